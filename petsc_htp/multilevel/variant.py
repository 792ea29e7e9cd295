"""``-htp_variant multilevel``: the two-level variant's choice (a small matrix factored whole), else the V-cycles of
:mod:`petsc_htp.multilevel`."""
from __future__ import annotations

from ..variants import TwoLevel


class Multilevel(TwoLevel):
    """:class:`~petsc_htp.variants.TwoLevel` with :class:`~.setup.MultilevelPC` for the matrices it does not factor
    whole."""

    title = "multilevel preconditioner: leaf solves smoothing every level of an aggregation hierarchy (PCMG)"

    def composed(self, mat, A, coords):
        """The hierarchy's setup (coordinates are not used)."""
        from .setup import MultilevelPC

        return MultilevelPC(mat, A, self.prefix + "htp_")
