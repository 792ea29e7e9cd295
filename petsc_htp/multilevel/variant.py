"""``-htp_variant multilevel``: the two-level variant's choice (a small matrix factored whole), else the V-cycles of
:mod:`petsc_htp.multilevel`."""
from __future__ import annotations

from ..variants import TwoLevel
from .choice import dimension, unscalar
from .setup import MultilevelPC


class Multilevel(TwoLevel):
    """:class:`~petsc_htp.variants.TwoLevel` with :class:`~.setup.MultilevelPC` for the matrices it does not factor
    whole."""

    title = MultilevelPC.title

    def composed(self, mat, A, coords):
        """The hierarchy's setup (coordinates are not used; the graph's dimension picks the smoother); a Mat with a
        block size or a near null space takes the two-level method, whose coarse space holds them (the levels' coarse
        vectors are constants), as does a dense row (:func:`.choice.unscalar`)."""
        why = unscalar(mat, A, self.opts.block_size)
        self.title = TwoLevel.title if why else MultilevelPC.title          # what -ksp_view's title names
        if why:
            self.note = (f"multilevel takes scalar problems (constants as coarse vectors): {why} takes the two-level "
                         "method")
            return super().composed(mat, A, coords)
        return MultilevelPC(mat, A, self.prefix + "htp_", dimension(mat, A, lambda: self.choice.block_shape(mat, A)))
