"""``-htp_variant multilevel``: the two-level variant's choice (a small matrix factored whole), else the V-cycles of
:mod:`petsc_htp.multilevel`."""
from __future__ import annotations

from ..twolevel import nearnull
from ..variants import TwoLevel
from .setup import MultilevelPC


class Multilevel(TwoLevel):
    """:class:`~petsc_htp.variants.TwoLevel` with :class:`~.setup.MultilevelPC` for the matrices it does not factor
    whole."""

    title = MultilevelPC.title

    def composed(self, mat, A, coords):
        """The hierarchy's setup (coordinates are not used); a Mat with a block size or a near null space of its own
        takes the two-level method, whose coarse space holds them (the levels' coarse vectors are constants)."""
        if nearnull.attached(mat) or mat.getBlockSize() > 1:
            self.note = ("multilevel takes scalar problems (constants as coarse vectors): the Mat's "
                         + ("near null space" if nearnull.attached(mat) else f"block size {mat.getBlockSize()}")
                         + " takes the two-level method")
            return super().composed(mat, A, coords)
        return MultilevelPC(mat, A, self.prefix + "htp_")
