"""Whether a right-hand side lies in the range of a singular matrix the V-cycles take (:mod:`..twolevel.consistency`):
their coarse factor is shifted or grounded, so a singular matrix without its null space and a b outside its range
would end in a CONVERGED_RTOL far from any solution (a true relative residual of 74 on a 65 536-row Neumann square)."""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

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

    def check(self, rows, hierarchy, perm=None) -> tuple:
        """(the :class:`~..twolevel.consistency.RangeCheck` of the connected components of the matrix whose row sums
        vanish, where no null space is attached and some do, else None | the coarsest operator's rows to ground,
        :func:`floating`'s) for this rank's ``rows`` (their values now) and the ``hierarchy`` built on the matrix (its
        rows in the order ``perm``, where given; collective). Where the hierarchy shows no component floating and can
        tell, none is null: no components are looked for (the 2-D DMDA's at 262 144 rows took 8.5 ms on one rank and 11 on two, at
        1M 43 and 34, against 0.9, 1.7, 5.0 and 3.1 through the hierarchy: results/renew-20261128/ranges.txt)."""
        mat = self.mat
        coll = Collective(mat.getComm())
        diag, rowsum = rows.diagonal(k=mat.getOwnershipRange()[0]), row_sums(rows.indptr, rows.data)
        top = coll.max_array(np.array([np.abs(diag).max(initial=0.0)]))[0]       # the null test's tolerance
        grounded = np.abs(rowsum) > nullspace.NULL_TOL * top
        if not coll.any(not grounded.all()):
            return None, np.zeros(0, dtype=np.int64)
        lifted, complete = floating(hierarchy, grounded if perm is None else grounded[perm], coll)
        if mat.getNullSpace().handle or (complete and lifted.size == 0):
            return None, lifted
        if self.components is None:
            self.components = components(mat, rows, coll)
        n_comp, comp = self.components
        null = nullspace.null_by_rowsums(rowsum, diag, comp, n_comp, coll.max_array if coll.size > 1 else None)
        return (RangeCheck(rows, comp, null, coll) if null.any() else None), lifted


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


def floating(hierarchy, grounded, coll) -> tuple:
    """(the last row, in its numbering, of each connected component of the :class:`~.hierarchy.Hierarchy`'s coarsest
    operator that holds no coarse row lifted from a grounded one, sorted | whether they are all that stand for null
    components) for ``grounded``, this rank's rows of the finest operator whose row sums do not vanish (each level's
    leaves lift them); (None, False) without levels. A null component of the finest operator makes such a component:
    its leaves make coarse rows that couple to no other (its smoothed coarse vectors stay in it), all ungrounded, down
    to the coarsest, whose factor they leave singular. Products that drop entries that cancel may split a component: a
    part without a grounded row is then among them. Some may be missing where an ungrounded row is left without a
    coarse column (a null component shrunk to a row that couples to nothing) or rows may share a leaf across components
    (:attr:`.level.Level.joined`): those found are still such components (collective: the coarsest gathered on every
    rank)."""
    from ..petscmat import gathered_rows, local_rows

    if not hierarchy.levels:
        return None, False
    complete = True
    for level in hierarchy.levels:
        lost = coll.any(np.any(~grounded & (level.column < 0)))
        complete = complete and not level.joined and not lost
        lifted = np.zeros(level.k, dtype=bool)
        lifted[level.column[grounded & (level.column >= 0)]] = True
        grounded = lifted
    with local_rows(hierarchy.coarsest) as mine:
        rows = mine if coll.size == 1 else gathered_rows(mine, coll.mpi)
        if coll.size > 1:
            grounded = np.concatenate(coll.mpi.allgather(grounded))
        count, label = nullspace.graph_components(sp.csr_matrix((rows.data, rows.indices, rows.indptr),
                                                                shape=(rows.shape[0],) * 2))
    last = np.full(count, -1, dtype=np.int64)
    np.maximum.at(last, label, np.arange(label.size))
    return np.sort(last[np.bincount(label[grounded], minlength=count) == 0]), complete
