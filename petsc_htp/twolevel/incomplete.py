"""Where ICC(0) of the whole matrix beats a coarse space: shifted, wide, grid-aligned or strongly anisotropic rows
that a short trial confirms.

Grid-aligned anisotropy: a 5- or 7-point stencil whose strong direction follows the grid (eps 0.001) holds weak
couplings across its strong lines, half of its couplings (the foreign study's 5- and 7-point matrices 0-4 %), and
ICC(0) in the grid's order nearly solves along the lines: at 64 000-65 536 rows 40 and 61 ms alone (42 and 64
iterations) against the two-level method's 107 and 143 (``results/rotated-20261127/aligned.txt``). Rows of at most
:data:`SPARSE_ROW` entries of which :data:`WEAK_SHARE` or more are weak (below :data:`.aggregation.THETA`), none
strongly positive, take the trial on the whole matrix up to :data:`WEAK_MAX` rows (eps 0.01 fails it, where ICC(0)
takes 119 iterations; at 131 044 rows the trial's graph ball, a diamond that cuts the strong lines short, failed
eps 0.001 too: ``aligned131k.txt``).

Shifted rows: one implicit step of the heat equation, M + dt K, holds a mass matrix's positive couplings beside
the stiffness's negative ones, so it is not diagonally dominant (:mod:`.dominance`) though its rows sum to the mass,
and ICC(0) of the whole matrix converges in a number of iterations bounded by the time step. Where the median
sampled row sums to :data:`SHIFT` of its diagonal or more (a Laplacian's rows sum to 0; P1 tetrahedra at dt = 10 h^2
0.013, at 1000 h^2 0.00013), ICC(0) of each rank's whole block is tried, without PETSc's shift, up to
:data:`WHOLE_NNZ` stored entries: at 262 144 rows of tetrahedra (dt = 10 h^2) one pivot that is not positive called
for the shift, under which ICC(0) took 299 iterations (the two-level method 42, ICC(0) at 64 000 rows 39), and no
graph ball of 8 192 or 65 536 rows held that pivot. At 64 000 rows HTPPC then took 166 and 277 ms (15 and 39
iterations) at dt = h^2 and 10 h^2 against its two-level method's 451 and 491 (``results/shifted-20261127``).

Wide rows: a 27-point stencil's or Q1 hexahedra's rows hold 27 stored entries, each coupling weak (1/32 to 1/16 of
the diagonal) and none positive; ICC(0) of the whole matrix keeps most of such a matrix (``results/wide-20261127``:
at 64 000 rows 84-121 ms alone, 31-36 iterations, against the two-level method's 210-441; at 262 144 rows 570-633
(46-52) against 910-2 150; at 1M rows, out1m.txt and out1m-rule.txt, 4.7 s with the rule against the two-level
method's 4.8-4.9: no longer a gain, at 71 iterations against 15-19). Rows of at least :data:`WIDE_ROW`
entries whose positive couplings weigh less than :data:`WEIGHT` (elasticity's weigh 0.97) and whose diagonal spans at
most :data:`CONTRAST` take the trial on a graph ball, up to :data:`WIDE_MAX` rows: conductivity balls of contrast 1e4
took ICC(0) 74 and 116 iterations at 64 000 and 262 144 rows (the two-level method 20 and 21), and before this cut
the ball of the larger matrix passed the trial (commit 27ba923).

Diffusion whose strong direction is turned against the grid (PyAMG's ``diffusion_stencil_2d`` with eps <= 0.01: FD
at about 22-68 degrees, FE within about 32 degrees of the axes) holds positive off-diagonal couplings that weigh
0.15 or more of the median row's diagonal (FE at 30 degrees 0.186-0.198, where the two-level method took 94-274
iterations and ICC(0) 26-125). Leaves of 10-30 rows cannot follow such couplings, and the two-level
method took 40-153 CG iterations at 65 536 rows, at 1M rows 41 (eps 0.01, 30 degrees, 4.5 s) and 2000 without
converging (eps 0.001, 45 degrees); ICC(0) of the whole matrix, whose 9-point pattern holds the strong couplings,
takes 14-37 at 65 536 rows and 70-100 at 1M (``results/rotated-20261127``). The same weight also marks rows where
ICC(0) loses as N grows (eps 0.1: 70-95 ICC iterations at 65 536 rows against the two-level method's 24-25), and a
random numbering takes ICC(0) to 600 iterations: a trial tells them apart (on one rank; on several, rows split at
random leave each rank a sparser block on which the trial passes, so none is made there: :func:`_kept`).
:data:`TRIAL_ITS` CG iterations with ICC(0) from zero on a fixed random right-hand side, on a graph ball of at most
:data:`TRIAL_ROWS` rows of each rank's block in the matrix's own numbering, must bring the residual below
:data:`TRIAL_DROP` (0.02-0.06 on the strongly
anisotropic rows at 65 536 rows, 0.13 with penalty rows, 0.16 for FE eps 0.01 at 15 degrees at 1M rows, where ICC(0)
took 3.3 s against the two-level method's 7.9; 0.95-7 on the others at 65 536 and 1M rows). Only rows of at most
:data:`STENCIL` stored entries whose positive couplings weigh :data:`WEIGHT` pay for the trial (none of the foreign
study's other matrices), and a singular matrix never takes it: the ball is not singular, and ICC(0) of the whole
Neumann matrix stalled (500 iterations at 70 225 rows, the two-level method 95).
"""
from __future__ import annotations

from functools import partial

import numpy as np
import scipy.sparse as sp
from petsc4py import PETSc

from .aggregation import SAMPLE_ROWS, THETA, sampled_shares
from .csr import row_entries
from .nullspace import vanishing
from ..petscmat import diagonal_block
from ..ranksplit import crossing
from .sizing import SPLIT_PAIRED

WEIGHT = 0.15           # the median sampled row's positive off-diagonal sum over its diagonal from which to try ICC(0)
STENCIL = 10.0          # ... in rows of at most this many stored entries (9-point stencils; not 2-D elasticity's 18)
SHIFT = 0.0025          # the median sampled row's sum over its diagonal from which to try ICC(0) (dominance's margin)
DRIFT = 2.0             # ... and new values whose share fell below the trial's over this make the trial again: a
# time step grown from 1e-5 (share 0.17) on a 2-D Laplacian of 65 536 rows took ICC(0) from 44 to 143 CG iterations
# a step, where a fresh trial fails and the two-level method takes 25 (ICC(0)'s iterations grow as the share's -1/2)
WHOLE_NNZ = 1 << 21     # ... where a rank's block holds at most this many stored entries (the trial takes it whole)
WIDE_ROW = 20.0         # rows of at least this many stored entries (27-point stencils, Q1 hexahedra) try ICC(0) ...
WIDE_MAX = 1 << 18      # ... in matrices of at most this many rows (ICC(0)'s iterations grow with N: 71 at 1M rows)
CONTRAST = 1e3          # ... whose diagonal entries span at most this factor (coefficient jumps: their low modes)
SPARSE_ROW = 7.0        # rows of at most this many stored entries (5- and 7-point stencils) ...
WEAK_SHARE = 0.3        # ... of whose sampled couplings this share or more is weak (below THETA) try ICC(0) ...
WEAK_MAX = 1 << 16      # ... in matrices of at most this many rows (at 131 044 the trial on a ball failed: 0.24)
TRIAL_ITS = 10          # CG iterations of the trial
TRIAL_ROWS = 65536      # ... on at most this many rows (anisotropic rows: a graph ball)
TRIAL_DROP = 0.2        # ... whose residual must fall below this times the first
HALFWAY = 2.0           # ... and be below this times the first halfway


def why_icc(mat, A, per_row, coll, bare=True):
    """Why ICC(0) of the whole matrix (of each rank's block on several ranks) serves ``mat`` (this rank's rows
    ``A``, scipy CSR; ``per_row`` stored entries a row on average; ``coll`` its ranks), the test that new values
    still call for it (:func:`holds`, :func:`wide`, :func:`aligned` or :func:`shifted`), whether the ranks' blocks
    are to be grown (anisotropy) and the trial's set-up PC where it took the whole matrix on one rank (the factor to
    apply, else None), or (None, None, False, None); never with a null space attached. Strongly anisotropic rows
    first (``bare`` matrices, no coordinates): rows hold at most :data:`STENCIL` entries, their positive couplings
    weigh at least :data:`WEIGHT` of the diagonal on every rank, not every row sum vanishes, the ranks' blocks keep
    the couplings (:func:`_kept`) and every rank's trial on its :func:`window` brings its residual below
    :data:`TRIAL_DROP`. Then wide rows (``bare``, at most :data:`WIDE_MAX` rows): at least :data:`WIDE_ROW` entries
    a row, positive couplings below :data:`WEIGHT` on every rank, a diagonal that spans at most :data:`CONTRAST`
    (:func:`_spread`), and the same tests and trial (:func:`wide`). Then grid-aligned anisotropy (``bare``, at most
    :data:`WEAK_MAX` rows): at most :data:`SPARSE_ROW` entries a row, :data:`WEAK_SHARE` or more of the sampled
    couplings weak on every rank, positive ones and the diagonal as for wide rows, and the same tests and trial
    (:func:`aligned`); the gates in :func:`_candidates`. Else shifted rows (any matrix): the median sampled row sums
    to at least :data:`SHIFT` of its diagonal on every rank, and every rank's trial on its whole block, unshifted,
    where it holds at most :data:`WHOLE_NNZ` entries, brings the residual below :data:`TRIAL_DROP`. Collective."""
    if mat.getNullSpace().handle:
        return None, None, False, None
    start = mat.getOwnershipRange()[0]
    for what, test, grown in _candidates(A, start, mat.getSize()[0], per_row, coll) if bare else ():
        if coll.any(not _null_rows(A, start)) and _kept(mat, A, coll):
            drop, factor = _trial(mat, A, coll, TRIAL_ROWS)
            if drop <= TRIAL_DROP:
                return _why(what, drop), test, grown, factor
    share = coll.min_array(np.array([row_sum_share(A, start)]))[0]
    if share >= SHIFT:
        drop, factor = _trial(mat, A, coll, None)
        if drop <= TRIAL_DROP:
            return _why(f"shifted rows (row sums {share:.2g} of the diagonal", drop), partial(shifted, chosen=share), \
                False, factor
    return None, None, False, None


def _candidates(A, start, n, per_row, coll):
    """The rules of a bare matrix's rows (a rank's ``A``, ``n`` rows in all, ``per_row`` stored entries a row) whose
    gates they pass, in order, for a trial on a graph ball: (what -ksp_view says, the test new values must pass, whether
    the ranks' blocks are to be grown). Collective."""
    if STENCIL < per_row < WIDE_ROW:                      # no rule's rows (SPARSE_ROW is below STENCIL)
        return
    local = positive_weight(A, start)                     # this rank's; the least and the largest over the ranks
    if per_row <= STENCIL:
        weight = coll.min_array(np.array([local]))[0]
        if weight >= WEIGHT:
            yield f"strongly anisotropic rows (positive couplings {weight:.2f} of the diagonal", holds, True
    if per_row >= WIDE_ROW and n <= WIDE_MAX and _spread(A, start, coll) <= CONTRAST:
        weight = coll.max_array(np.array([local]))[0]
        if weight < WEIGHT:
            yield f"wide rows ({per_row:.0f} stored entries a row, positive couplings {weight:.2f} of the diagonal", \
                wide, False
    if per_row <= SPARSE_ROW and n <= WEAK_MAX and _spread(A, start, coll) <= CONTRAST:
        weight = coll.max_array(np.array([local]))[0]
        weak = coll.min_array(np.array([weak_share(A, start)]))[0] if weight < WEIGHT else 0.0
        if weak >= WEAK_SHARE:
            yield f"grid-aligned anisotropy ({100 * weak:.0f}% of the couplings weak", aligned, False


def _spread(A, start, coll=None) -> float:
    """The largest |a_ii| of a rank's rows ``A`` (their diagonal in column ``start`` + row) over their least nonzero
    one, over all ranks of ``coll`` (collective; None: this rank's), inf where all are zero."""
    diag = np.abs(A.diagonal(k=start))
    diag = diag[diag > 0]
    top, least = diag.max(initial=0.0), diag.min(initial=np.inf)
    if coll is not None:
        top, least = coll.max_array(np.array([top]))[0], coll.min_array(np.array([least]))[0]
    return top / least if least < np.inf else np.inf


def _kept(mat, A, coll) -> bool:
    """Whether the ranks' blocks keep the couplings (less than :data:`.sizing.SPLIT_PAIRED` of them join two ranks),
    so that a trial on each block speaks for the whole matrix: the 45-degree anisotropy numbered at random passed it
    on 2 ranks at 65 536 rows (each block a sparser graph) and took 618 ICC(0) iterations, 1.6 s
    (``results/rotated-20261127/split-before.txt``), where the two-level method on paired leaves takes 269, 0.8 s
    (``split.txt``). Collective."""
    cut = crossing(mat, A, coll, A.data != 0)
    return cut is None or cut[1] < SPLIT_PAIRED


def _why(what, drop) -> str:
    """-ksp_view's reason for ICC(0): ``what`` the rows are, then the trial's ``drop``."""
    return f"{what}; ICC(0) took a trial residual to {drop:.1e} in {TRIAL_ITS} CG iterations): a coarse space " \
           "does not pay"


def _trial(mat, A, coll, size):
    """The largest over the ranks of :func:`trial_drop`: on a :func:`window` of ``size`` rows of each rank's block,
    PETSc's shift keeping the pivots positive, or (``size`` None) on the whole block, unshifted, where it holds at most
    :data:`WHOLE_NNZ` entries; inf where a rank's window is less than half its size or its block larger. With it the
    trial's ICC(0), set up, where one rank's trial passed on the whole matrix (the factor to apply), else None."""
    kept = []
    with diagonal_block(mat, A) as block:
        if size is None:
            rows, skip = np.arange(block.shape[0]), block.nnz > WHOLE_NNZ
        else:
            rows = window(block, size)
            skip = rows.size < min(size, block.shape[0]) // 2
    drop = coll.max_array(np.array([np.inf if skip else trial_drop(mat.getDiagonalBlock(), rows, size is not None,
                                                                   kept)]))[0]
    if kept and (coll.size > 1 or not drop <= TRIAL_DROP):
        kept.pop().destroy()
    return drop, kept[0] if kept else None


def holds(rows, start) -> bool:
    """Whether new values ``rows`` (a rank's, their diagonal in column ``start`` + row) keep the positive couplings'
    weight (:data:`WEIGHT`) that chose ICC(0)."""
    return positive_weight(rows, start) >= WEIGHT


def wide(rows, start) -> bool:
    """Whether new values ``rows`` (as for :func:`holds`) keep what chose ICC(0) for wide rows: positive couplings
    below :data:`WEIGHT` and a diagonal that spans at most :data:`CONTRAST` on this rank (jumps that move in call for
    a new analysis)."""
    return positive_weight(rows, start) < WEIGHT and _spread(rows, start) <= CONTRAST


def aligned(rows, start) -> bool:
    """Whether new values ``rows`` (as for :func:`holds`) keep what chose ICC(0) for grid-aligned anisotropy: a share
    of weak couplings of at least :data:`WEAK_SHARE`, and what :func:`wide` tests."""
    return weak_share(rows, start) >= WEAK_SHARE and wide(rows, start)


def weak_share(rows, start=0) -> float:
    """The share of a rank's sampled couplings (:func:`.aggregation.sampled_shares` of its diagonal block, ``rows``'
    columns ``start`` to ``start`` + rows) below :data:`.aggregation.THETA`: about half in a 5-point stencil whose
    strong direction follows the grid, 0-0.04 in the foreign study's 5- and 7-point matrices; 1 (no say in the least
    over the ranks) where a rank's block holds no coupling."""
    n = rows.shape[0]
    block = rows[:, start:start + n] if rows.shape[1] != n or start else rows
    share = sampled_shares(sp.csr_matrix(block))[0]
    return float(np.mean(share < THETA)) if share.size else 1.0


def shifted(rows, start, chosen=SHIFT) -> bool:
    """Whether new values ``rows`` (as for :func:`holds`) keep the row sums' share that chose ICC(0): at least
    :data:`SHIFT`, and at least the share ``chosen`` at the trial over :data:`DRIFT` (else a new analysis makes the
    trial again; between, ICC(0)'s shift keeps its pivots positive)."""
    return row_sum_share(rows, start) >= max(SHIFT, chosen / DRIFT)


def positive_weight(A, start=0, rows=SAMPLE_ROWS) -> float:
    """The median over ``rows`` sampled rows (:func:`_sampled`) of a rank's CSR rows ``A`` (their diagonal in column
    ``start`` + row) of their positive off-diagonal entries' sum over |a_ii| (0 where the diagonal is 0)."""
    return _sampled(A, start, rows, positive=True)


def row_sum_share(A, start=0, rows=SAMPLE_ROWS) -> float:
    """The median over ``rows`` sampled rows of a rank's CSR rows ``A`` (as for :func:`positive_weight`) of their sum
    over |a_ii| (0 where the diagonal is 0): about 0 for a Laplacian (a Dirichlet boundary's rows are few), the mass
    matrix's share for a time step's M + dt K."""
    return _sampled(A, start, rows, positive=False)


def _sampled(A, start, rows, positive) -> float:
    """The median over ``rows`` rows of ``A`` drawn at random (a fixed draw; a stride that a grid's side divides
    would sample one column), all where it has fewer, of their ``positive`` off-diagonal entries' sum (else all their
    entries') over |a_ii|; inf where a rank has no rows (no say in the least over the ranks)."""
    n = A.shape[0]
    if n == 0:
        return np.inf
    picked = np.arange(n) if n <= rows else np.sort(np.random.default_rng(0).choice(n, rows, replace=False))
    where, owner = row_entries(A.indptr, picked)
    values = A.data[where]
    on = A.indices[where] == picked[owner] + start                   # the sampled rows' diagonal entries
    taken = (values > 0) & ~on if positive else np.ones(values.size, bool)
    total = np.bincount(owner[taken], values[taken], minlength=picked.size).astype(float)   # int where none is
    diag = np.abs(np.bincount(owner[on], values[on], minlength=picked.size).astype(float))
    return float(np.median(np.divide(total, diag, out=np.zeros_like(total), where=diag > 0)))


def _null_rows(A, start) -> bool:
    """Whether every one of a rank's rows ``A`` has a vanishing sum (:func:`.nullspace.vanishing`): a Neumann
    matrix."""
    return bool(np.all(vanishing(np.asarray(A.sum(axis=1)).ravel(), A.diagonal(k=start))))


def window(A, size=TRIAL_ROWS) -> np.ndarray:
    """The rows of a graph ball of at most ``size`` rows about the first coupled row from the middle of a square CSR
    ``A``, sorted: a patch of the domain in the matrix's own numbering (fewer rows where that row's component is
    smaller; :func:`why_icc` then takes no trial). The leading rows would not do: in a 1024^2 grid they are a strip
    64 rows high, on which ICC(0) converged fast whatever the anisotropy. Grown level by level, so its cost is the
    ball's, not the matrix's (a search of the whole graph took 8 ms at 64 000 rows of tetrahedra)."""
    n = A.shape[0]
    if n <= size:
        return np.arange(n)
    coupled = np.flatnonzero(np.diff(A.indptr)[n // 2:] > 1)
    seen, stamp = np.zeros(n, dtype=bool), np.empty(n, dtype=np.int64)
    level = np.array([n // 2 + int(coupled[0]) if coupled.size else n // 2])
    levels, count = [], 0
    seen[level] = True
    while level.size and count < size:
        levels.append(level)
        count += level.size
        where, _ = row_entries(A.indptr, level)
        level = A.indices[where]
        level = level[~seen[level]]
        seen[level] = True                                   # each row once (no sort: a stamp per row)
        stamp[level] = np.arange(level.size)
        level = level[stamp[level] == np.arange(level.size)]
    levels[-1] = np.sort(levels[-1])                        # the rows it cuts: the last level's highest
    return np.sort(np.concatenate(levels)[:size])


def trial_drop(mat, rows, shift=True, kept=None) -> float:
    """The residual after :data:`TRIAL_ITS` CG iterations with ICC(0) from zero on a fixed random right-hand side in
    [0, 1) (its mean is the smooth part that ICC(0) leaves), over the first, on the ``rows`` (:func:`window`) of a
    sequential ``mat`` (a rank's diagonal block): iterations whose cost does not grow with N (at 1M rows the whole
    matrix's trial took 0.3-0.7 s, and its residual grew on every kind of row); inf where PETSc's factor failed, CG
    broke down or a residual is not finite. ``shift``: ICC(0)'s pivots kept positive by PETSc's shift, else not, and
    a factor with a pivot that is not positive (its inertia) fails at once, with no iteration: such a pivot calls for
    the shift, under which a heat step on P1 tetrahedra at 262 144 rows took 299 iterations, and the shift's tries
    repeat the factor. ``kept``: a list that takes the trial's PC, set up, where the trial took the whole ``mat`` and
    ended with a finite drop."""
    n = rows.size
    index = PETSc.IS().createGeneral(rows.astype(PETSc.IntType), comm=PETSc.COMM_SELF) if n < mat.getSize()[0] else None
    part = mat if index is None else mat.createSubMatrix(index, index)
    ksp = PETSc.KSP().create(PETSc.COMM_SELF)
    b, x = part.createVecLeft(), part.createVecRight()
    try:
        ksp.setOptionsPrefix("htp_trial_")                     # never set from options: a fixed trial
        ksp.setOperators(part, part)
        ksp.setType("cg")
        pc = ksp.getPC()
        pc.setType("icc")
        pc.setFactorOrdering("natural")
        pc.setFactorShift(shift_type=PETSc.Mat.FactorShiftType.POSITIVE_DEFINITE if shift else
                          PETSc.Mat.FactorShiftType.NONE)
        ksp.setNormType(PETSc.KSP.NormType.UNPRECONDITIONED)
        ksp.setTolerances(rtol=0.0, atol=0.0, max_it=TRIAL_ITS)
        ksp.setConvergenceHistory(length=TRIAL_ITS + 1)
        ksp.setConvergenceTest(_halfway)
        if not shift:
            ksp.setUp()
            if pc.getFailedReason() != PETSc.PC.FailedReason.NOERROR or pc.getFactorMatrix().getInertia()[0]:
                return np.inf
        b.setArray(np.random.default_rng(0).random(n))
        x.set(0.0)
        ksp.solve(b, x)
        history = ksp.getConvergenceHistory()
        if ksp.getConvergedReason() < 0:
            return np.inf
        if history.size < 2 or not np.all(np.isfinite(history)) or not history[0] > 0:
            return np.inf
        if kept is not None and index is None:
            kept.append(pc)
        return float(history[-1] / history[0])
    finally:
        for obj in (ksp, b, x) + (() if index is None else (index, part)):
            obj.destroy()


def _halfway(ksp, its, rnorm):
    """The trial's end: after :data:`TRIAL_ITS` iterations, or halfway where the residual is :data:`HALFWAY` times the
    first or more (the rejected rows at 65 536 rows: 3.9-5.1 there, half their trial's cost; FE eps 0.01 at 15 degrees
    at 1M rows, 1.03 halfway, ends at 0.16)."""
    first = ksp.getConvergenceHistory()[0]
    if its >= TRIAL_ITS or (its == TRIAL_ITS // 2 and rnorm >= HALFWAY * first):
        return PETSc.KSP.ConvergedReason.CONVERGED_ITS
    return PETSc.KSP.ConvergedReason.ITERATING
