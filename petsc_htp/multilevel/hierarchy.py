"""The levels from the finest operator down to one small enough for one factor (:func:`.cycle.banded`)."""
from __future__ import annotations

from petsc4py import PETSc

from .level import JACOBI, Level

COARSE_MAX = {2: 5000, 3: 1000}     # rows of the coarsest operator, factored once, by the graph's dimension (2-D,
# one rank, CG to 1e-8, single solves, 5 000 against 1 000, 2026-11-28: 1M rows dmda2d 1 945 / 1 966 ms, lognormal
# 1 531 / 1 779 (18 / 25 iterations), neumann 2 037 / 2 167, free surface 1 419 / 1 449; 65 536 rows level but
# lognormal 81 / 99 (15 / 22); 20 000 slower at 65 536 rows; 3-D: the 64^3 DMDA's setup 1 959 against 937 ms)
MAX_LEVELS = 12         # levels at most, the coarsest included
STALL = 0.8             # a level that keeps more than this share of its rows as coarse vectors ends the hierarchy


def default_coarse_max(dim) -> int:
    """:data:`COARSE_MAX` for a graph of dimension ``dim`` (3-D beyond)."""
    return COARSE_MAX[2] if dim <= 2 else COARSE_MAX[3]


class Hierarchy:
    """:attr:`levels` (:class:`~.level.Level`, finest first) and :attr:`coarsest`, the operator under the last;
    ``leaf``, ``rows``: the finest level's leaves (:func:`.level.leaves`) and this rank's rows of ``A`` where already
    found; ``blocks``: each level's leaf-block matrix made (the leaf solves' smoother); ``weighted``: the finest
    level's leaf vectors weighted (:func:`.level.row_scaled`); ``least``: the mean rows a coarser level's leaves hold
    at least (:data:`.level.LEAST`)."""

    def __init__(self, A, coarse_max=COARSE_MAX[2], max_levels=MAX_LEVELS, jacobi=JACOBI, leaf=None, blocks=True,
                 rows=None, weighted=False, least=0.0):
        self.levels, self.coarsest, self.least = [], A, least
        self.sizes, self.jacobi, self.blocks, self.weighted = (coarse_max, max_levels), jacobi, blocks, weighted
        self._grow(leaf, rows)

    def _grow(self, leaf=None, rows=None):
        """Levels under :attr:`coarsest` until it is small enough (``leaf``, ``rows``: its leaves and this rank's
        rows where found)."""
        coarse_max, max_levels = self.sizes
        while self.coarsest.getSize()[0] > coarse_max and len(self.levels) + 1 < max_levels:
            first = not self.levels
            level = Level(self.coarsest, self.jacobi, leaf if first else None, self.blocks, rows if first else None,
                          self.weighted and first, 0.0 if first else self.least)
            n, k = level.W.getSize()
            if k == 0 or k > STALL * n:
                level.below.destroy()
                level.destroy()
                break
            self.levels.append(level)
            self.coarsest = level.below

    def refresh(self, rows=None):
        """New values of the finest operator (same pattern; ``rows``: this rank's rows of it, where read): the finest
        level's leaf blocks (where made), smoothed coarse vectors and Galerkin operator anew, its leaves kept; the
        coarser levels made anew from that operator (their leaves follow its new values: log-normal fields of a new
        seed each frame, 65 536 rows, took 29, 32 and 40 CG iterations with every level's leaves kept, 25, 20 and 23
        so)."""
        if not self.levels:
            return
        for A in self.operators()[1:]:                 # first: the old operators go before the new are made
            A.destroy()
        for level in self.levels[1:]:
            level.destroy()
        self.levels = self.levels[:1]
        self.levels[0].refresh(rows)
        self.coarsest = self.levels[0].below
        self._grow()

    def operators(self) -> list:
        """Each level's operator, then the coarsest."""
        return [level.A for level in self.levels] + [self.coarsest]

    def rows(self) -> list:
        """Global rows of :meth:`operators`."""
        return [A.getSize()[0] for A in self.operators()]

    def complexity(self) -> float:
        """Stored entries of all operators over the finest's (the operator complexity)."""
        nnz = [A.getInfo(PETSc.Mat.InfoType.GLOBAL_SUM)["nz_used"] for A in self.operators()]
        return sum(nnz) / nnz[0]

    def destroy(self):
        """Free every level's matrices and the coarse operators (not the finest)."""
        for A in self.operators()[1:]:
            A.destroy()
        for level in self.levels:
            level.destroy()
        self.levels, self.coarsest = [], None
