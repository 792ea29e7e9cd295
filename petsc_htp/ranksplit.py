"""How a parallel operator's rows are split over the ranks: the share of its couplings that join rows of two ranks,
shown by ``-ksp_view`` with advice where the split cuts too many.

HTPPC's leaves, like PETSc's block Jacobi blocks, hold rows of one rank: a split that cuts many couplings (rows
numbered at random, a mesh generator's order, MatLoad's contiguous blocks of such an order) leaves each rank's rows
loosely coupled to each other, and the method takes more iterations than on one rank (GAMG's smoother does not care):
on 2 ranks the foreign study's P1 triangles and tetrahedra, nodes numbered at random, cut 49.9 % of the couplings and
take 39 and 57 CG iterations against 34 and 40 on one rank; the DMDA-style matrix, split in strips, 0.2 % and 33
either way (results/ranksplit-20261126). A whole-matrix factor (small matrices, gathered on every rank) has no leaves
and no such line.
"""
from __future__ import annotations

import numpy as np

CUT_SHARE = 0.5     # a row whose couplings to other ranks weigh this share of its diagonal or more, and more than this
# share of all its couplings, is a leaf of its own (PETSc's ksp ex3, a Q1 stencil with positive corner couplings: every
# row's couplings weigh twice its diagonal, and under the first test alone the rows beside the cut were 1 202 leaves
# of one row on 2 ranks at 361 201 rows, whose coarse LU in the leaves' METIS order then filled 5x: 3.3 s)
CUT_ROWS = 0.05     # ... where at most this share of a rank's rows are such (a split that cuts many couplings, rows
# numbered at random: 82 % of the foreign study's P1 tetrahedra on 2 ranks, a coarse operator of 52 864 rows)
CUT_ADVICE = 0.2    # share of cut couplings above which -ksp_view advises a better split (a 3-D block of 25^3 rows
# per rank, a good split of 16 000 rows per rank, cuts about 4 %; rows at random over p ranks cut 1 - 1/p)


def crossing(mat, rows, coll, nonzero):
    """None on one rank, else (ranks, share over all ranks, the largest share of one rank) of the nonzero
    off-diagonal entries of ``mat`` whose column belongs to another rank; ``rows``: this rank's rows (CSR, global
    columns), ``nonzero`` which of their entries are nonzero, ``coll`` a :class:`~petsc_htp.collective.Collective`
    on ``mat``'s communicator (collective)."""
    from .petscmat import diagonal_block
    from .twolevel.csr import row_entries

    if coll.size < 2:
        return None
    start, end = mat.getOwnershipRange()
    with diagonal_block(mat, rows) as block:                # only rows with entries outside it are read (a
        where = row_entries(rows.indptr, outside_rows(rows, block))[0]           # strip's border)
        diagonal = int(np.count_nonzero(block.diagonal()))
    col = rows.indices[where]
    cut = int(np.count_nonzero(nonzero[where] & ((col < start) | (col >= end))))
    off = int(np.count_nonzero(nonzero)) - diagonal
    worst = coll.max_array(np.array([cut / off if off else 0.0]))[0]
    total = coll.sum(off)
    return coll.size, (coll.sum(cut) / total if total else 0.0), float(worst)


def describe(cut) -> list:
    """``-ksp_view``'s partition line for :func:`crossing`'s ``cut`` (none on one rank)."""
    if cut is None:
        return []
    ranks, share, worst = cut
    line = (f"ranks: {ranks}; {100 * share:.1f}% of the off-diagonal couplings join rows of two ranks (at most "
            f"{100 * worst:.1f}% of one rank's)")
    if share > CUT_ADVICE:
        line += ("; WARNING: leaves hold one rank's rows, so a split that cuts this many couplings costs iterations; "
                 "number the rows so that each rank holds rows coupled to each other (a graph partitioner's order)")
    return [line]


def cut_rows(rows, block) -> np.ndarray:
    """Boolean (n,): this rank's ``rows`` (CSR, global columns) whose couplings to other ranks' rows (those not in
    the diagonal ``block``) weigh at least :data:`CUT_SHARE` of their |diagonal| and more than that share of all their
    couplings, where they are at most
    :data:`CUT_ROWS` of the rows (else none). Such a row holds a strong coupling the rank's leaves cannot keep (a
    random field of contrast 1e4 at 16 384 rows: CG took 21 iterations on one rank, 85 on two, 101 on three; now 29
    and 22, ``results/sweep-20261127b``): as a leaf of its own its coarse column keeps the coupled pair's common mode."""
    from .twolevel.csr import abs_diagonal_of, row_entries

    n = rows.shape[0]
    cut = np.zeros(n, dtype=bool)
    if n == 0 or rows.shape[1] == n:
        return cut
    extra = outside_rows(rows, block)                                      # alone read (a strip's border), not
    where, owner = row_entries(rows.indptr, extra)                         # every row's sums
    total = np.bincount(owner, np.abs(rows.data[where]), minlength=extra.size)
    diag, (where, owner) = abs_diagonal_of(block, extra)
    cross = total - np.bincount(owner, np.abs(block.data[where]), minlength=extra.size)
    cut[extra[(cross >= CUT_SHARE * diag) & (cross > CUT_SHARE * (total - diag))]] = True
    return cut if np.count_nonzero(cut) <= CUT_ROWS * n else np.zeros(n, dtype=bool)


def outside_rows(rows, block) -> np.ndarray:
    """This rank's ``rows`` (CSR, global columns) that hold entries outside its diagonal ``block`` (CSR): the only rows
    whose couplings reach another rank."""
    return np.flatnonzero(np.diff(rows.indptr) > np.diff(block.indptr))
