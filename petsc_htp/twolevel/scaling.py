"""Row-scaled operators: piece vectors |diag(A)|^-1/2 in place of the piece constants where they are smoother.

A program that hands over D A D, A a Poisson-type matrix and D a diagonal scaling far from constant (unknowns in
mixed units, a symmetric scaling of its own), has D^-1 1 as its near null space, not the constant: the piece
constants then make a coarse space no better than none (2-D Poisson at 40 000 rows, D in 1e-2 .. 1e2 per row:
465 CG iterations, 26 unscaled). Where A's own diagonal is about constant, |diag(D A D)|^-1/2 is proportional to
D^-1 and restores them. Which vector is the smoother one the operator tells: z replaces the constant when its
Rayleigh quotient z^T A z / z^T |diag| z is below :data:`RATIO` times the constant's (a coefficient jump makes z
rough across it, and the constant stays; a singular Neumann matrix keeps its constant, whose quotient is zero).
Couplings to other ranks' rows are left out of both quotients alike, and so are decoupled rows (no nonzero
off-diagonal entry: a DMDA's Dirichlet rows), which the leaf solves take exactly and which would weigh one for
z whatever the scaling. PETSc-free.
"""
from __future__ import annotations

import numpy as np

RATIO = 0.25        # z's quotient must be below this share of the constant's


def quotients(rows, start, coll) -> tuple:
    """(the constant's, z's) Rayleigh quotients over all ranks, from this rank's ``rows`` (CSR, global columns,
    local rows ``start`` ...; couplings to other ranks' rows left out) and its diagonal."""
    n = rows.shape[0]
    diag = np.abs(rows.diagonal(k=start))
    z = 1.0 / np.sqrt(np.where(diag > 0, diag, 1.0))
    stored = np.concatenate(([0], np.cumsum(rows.data != 0)))
    coupled = (stored[rows.indptr[1:]] - stored[rows.indptr[:-1]] - (diag != 0)) > 0
    sums = np.zeros(4)
    for i, v in enumerate((coupled.astype(np.float64), z * coupled)):
        full = np.zeros(rows.shape[1])
        full[start:start + n] = v
        sums[2 * i:2 * i + 2] = v @ (rows @ full), v @ (diag * v)
    sums = coll.sum_array(sums)
    return tuple(float(a / b) if b > 0 else 0.0 for a, b in (sums[:2], sums[2:]))


def weights(rows, start, coll):
    """z = |diag(A)|^-1/2 on this rank's rows where it is the smoother vector (see the module docstring), with the
    two quotients; else (None, quotients). Collective."""
    q = quotients(rows, start, coll)
    if q[1] >= RATIO * q[0]:
        return None, q
    diag = np.abs(rows.diagonal(k=start))
    return 1.0 / np.sqrt(np.where(diag > 0, diag, 1.0)), q
