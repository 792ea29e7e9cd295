"""Whether a right-hand side lies in the range of a singular matrix the V-cycles take (:mod:`..twolevel.consistency`):
their coarse factor is shifted or grounded, so a singular matrix without its null space and a b outside its range
would end in a CONVERGED_RTOL far from any solution (a true relative residual of 74 on a 65 536-row Neumann square)."""
from __future__ import annotations

import numpy as np

from ..collective import Collective
from ..petscmat import diagonal_block, ghost_values
from ..twolevel import nullspace
from ..twolevel.consistency import RangeCheck
from ..twolevel.csr import row_sums


class Ranges:
    """The range checks of one pattern's values on ``mat``: its connected components found at the first
    :meth:`check` that needs them and kept (the pattern's nonzero entries, which an analysis keeps: 3 ms a frame at
    65 536 rows)."""

    def __init__(self, mat):
        self.mat, self.components = mat, None

    def check(self, rows):
        """The :class:`~..twolevel.consistency.RangeCheck` of the connected components of the matrix (this rank's
        ``rows``, its values now) whose row sums vanish, where no null space is attached and some do; else None
        (collective)."""
        mat = self.mat
        if mat.getNullSpace().handle:
            return None
        coll = Collective(mat.getComm())
        diag, rowsum = rows.diagonal(k=mat.getOwnershipRange()[0]), row_sums(rows.indptr, rows.data)
        if not coll.any(nullspace.vanishing(rowsum, diag).any()):
            return None
        if self.components is None:
            self.components = components(mat, rows, coll)
        n_comp, comp = self.components
        null = nullspace.null_by_rowsums(rowsum, diag, comp, n_comp, coll.max_array if coll.size > 1 else None)
        return RangeCheck(rows, comp, null, coll) if null.any() else None


def components(mat, rows, coll) -> tuple:
    """(number, label of each of this rank's rows) of the connected components of ``mat``'s nonzero entries over all
    ranks: each rank's own (its diagonal block), then the graph of those joined by the couplings between ranks,
    which alone travel (collective)."""
    if coll.size == 1:
        return nullspace.graph_components(rows)
    start, n = mat.getOwnershipRange()[0], rows.shape[0]
    with diagonal_block(mat, rows) as block:
        n_loc, loc = nullspace.graph_components(block) if n else (0, np.zeros(0, dtype=np.int64))
    offset, n_all = coll.exscan(n_loc), coll.sum(n_loc)
    row_comp = loc.astype(np.int64) + offset
    row = np.repeat(np.arange(n), np.diff(rows.indptr))
    far = ((rows.indices < start) | (rows.indices >= start + n)) & (rows.data != 0)
    other = ghost_values(mat, row_comp.astype(np.float64), rows.indices[far]).astype(np.int64)   # collective
    key = np.unique(row_comp[row[far]] * n_all + other)
    n_comp, comp = nullspace.components(n_all, coll.gather_rows(np.stack([key // n_all, key % n_all], 1)))
    return n_comp, comp[row_comp]
