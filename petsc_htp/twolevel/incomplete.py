"""Where ICC(0) of the whole matrix beats a coarse space: strongly anisotropic rows that a short trial confirms.

Diffusion whose strong direction is turned against the grid (PyAMG's ``diffusion_stencil_2d`` with eps <= 0.01,
FD or FE, any angle but the grid's own for FD) holds positive off-diagonal couplings that weigh a fifth or more
of the median row's diagonal. Leaves of 10-30 rows cannot follow such couplings and the two-level method takes
40-155 CG iterations (5.9 s and 16 s at 1M rows), where ICC(0) of the whole matrix, whose pattern holds the
stencil's diagonal couplings, takes 31-37 at 65 536 rows and 60-103 at 1M (44-57 ms against 167-323, 1.8-3.6 s
against 5.9-16 s; ``results/rotated-20261127``). The same weight also marks matrices where ICC(0) loses as N
grows (2-D elasticity, eps = 0.1, a Laplacian squared: 95-267 ICC iterations): a trial tells them apart.
:data:`TRIAL_ITS` CG iterations with ICC(0) from zero on a fixed random right-hand side, the matrix's own
numbering (a random one takes ICC(0) to 600 iterations, and the trial sees it), must bring the residual below
:data:`TRIAL_DROP`: 0.02-0.03 on the strongly anisotropic rows, 1.1-7 on the others. Only rows of that weight pay
for the trial (none of the foreign study's other matrices).
"""
from __future__ import annotations

import numpy as np
from petsc4py import PETSc
from scipy.sparse.csgraph import breadth_first_order

from .aggregation import SAMPLE_ROWS
from .csr import row_entries
from .graphshape import graph_shape
from ..petscmat import diagonal_block

WEIGHT = 0.2            # the median sampled row's positive off-diagonal sum over its diagonal from which to try ICC(0)
STENCIL = 10.0          # ... where rows hold at most this many stored entries (9-point stencils; not 2-D elasticity's 18)
TRIAL_ITS = 10          # CG iterations of the trial
TRIAL_ROWS = 65536      # ... on at most this many rows
TRIAL_DROP = 0.1        # ... whose residual must fall below this times the first


def why_icc(mat, A, per_row, coll):
    """Why ICC(0) of the whole matrix (of each rank's diagonal block on several ranks) serves ``mat`` (this rank's
    rows ``A``, scipy CSR; ``per_row`` stored entries a row on average; ``coll`` its ranks), or None: rows hold at most
    :data:`STENCIL` entries, their positive couplings weigh at least :data:`WEIGHT` of the diagonal on every rank
    (:func:`positive_weight`), every rank's graph is 2-D (P1 tets, whose obtuse elements' positive couplings weigh as
    much, paid 77 ms for a failed trial at 64 000 rows) and every rank's trial brings its residual below
    :data:`TRIAL_DROP` (:func:`trial_drop` on its block). Collective."""
    if per_row > STENCIL:
        return None
    with diagonal_block(mat, A) as block:
        weight = coll.min_array(np.array([positive_weight(block)]))[0]
        if not weight >= WEIGHT:
            return None
        dim = coll.max_array(np.array([graph_shape(block, want_weak=False, samples=8).dim]))[0]
        if dim != 2:
            return None
        rows = window(block)
    drop = coll.max_array(np.array([trial_drop(mat.getDiagonalBlock(), rows)]))[0]
    if not drop <= TRIAL_DROP:
        return None
    return (f"strongly anisotropic rows (positive couplings {weight:.2f} of the diagonal; ICC(0) took a trial residual "
            f"to {drop:.1e} in {TRIAL_ITS} CG iterations): a coarse space does not pay")


def positive_weight(A, rows=SAMPLE_ROWS) -> float:
    """The median over about ``rows`` evenly spaced rows of a square CSR ``A`` of their positive off-diagonal entries'
    sum over |a_ii| (0 where the diagonal is 0)."""
    n = A.shape[0]
    if n == 0:
        return 0.0
    picked = np.arange(0, n, max(1, n // rows))
    where, owner = row_entries(A.indptr, picked)
    values = A.data[where]
    lift = (values > 0) & (A.indices[where] != picked[owner])
    total = np.bincount(owner[lift], values[lift], minlength=picked.size).astype(float)   # int where none lift
    diag = np.abs(A.diagonal()[picked])
    return float(np.median(np.divide(total, diag, out=np.zeros_like(total), where=diag > 0)))


def window(A, size=TRIAL_ROWS) -> np.ndarray:
    """The rows of a graph ball of at most ``size`` rows about the middle row of a square CSR ``A``, sorted: a patch
    of the domain in the matrix's own numbering. The leading rows would not do: in a 1024^2
    grid they are a strip 64 rows high, on which ICC(0) converged fast whatever the anisotropy."""
    n = A.shape[0]
    if n <= size:
        return np.arange(n)
    order = breadth_first_order(A, n // 2, directed=True, return_predecessors=False)
    return np.sort(order[:size])


def trial_drop(mat, rows) -> float:
    """The residual after :data:`TRIAL_ITS` CG iterations with ICC(0) from zero on a fixed random right-hand side in
    [0, 1) (its mean is the smooth part that ICC(0) leaves), over the first, on the ``rows`` (:func:`window`) of a
    sequential ``mat`` (a rank's diagonal block): a cost that does not grow with N (at 1M rows the whole matrix's
    trial took 0.3-0.7 s, and its residual grew on every kind of row); inf where PETSc's factor failed."""
    n = rows.size
    index = PETSc.IS().createGeneral(rows.astype(PETSc.IntType), comm=PETSc.COMM_SELF)
    part = mat.createSubMatrix(index, index) if n < mat.getSize()[0] else mat
    ksp = PETSc.KSP().create(PETSc.COMM_SELF)
    b, x = part.createVecLeft(), part.createVecRight()
    try:
        ksp.setOptionsPrefix("htp_trial_")                     # never set from options: a fixed trial
        ksp.setOperators(part, part)
        ksp.setType("cg")
        pc = ksp.getPC()
        pc.setType("icc")
        pc.setFactorOrdering("natural")
        pc.setFactorShift(shift_type=PETSc.Mat.FactorShiftType.POSITIVE_DEFINITE)
        ksp.setNormType(PETSc.KSP.NormType.UNPRECONDITIONED)
        ksp.setTolerances(rtol=0.0, atol=0.0, max_it=TRIAL_ITS)
        ksp.setConvergenceHistory(length=TRIAL_ITS + 1)
        ksp.setConvergenceTest(_halfway)
        b.setArray(np.random.default_rng(0).random(n))
        x.set(0.0)
        ksp.solve(b, x)
        history = ksp.getConvergenceHistory()
        if ksp.getConvergedReason() < 0:
            return np.inf
        if history.size < 2 or not np.all(np.isfinite(history)) or not history[0] > 0:
            return np.inf
        return float(history[-1] / history[0])
    finally:
        for obj in (ksp, b, x, index) + ((part,) if part is not mat else ()):
            obj.destroy()


def _halfway(ksp, its, rnorm):
    """The trial's end: after :data:`TRIAL_ITS` iterations, or halfway where the residual has not fallen below the
    first (every matrix that failed the trial: half its cost)."""
    first = ksp.getConvergenceHistory()[0]
    if its >= TRIAL_ITS or (its == TRIAL_ITS // 2 and rnorm >= first):
        return PETSc.KSP.ConvergedReason.CONVERGED_ITS
    return PETSc.KSP.ConvergedReason.ITERATING
