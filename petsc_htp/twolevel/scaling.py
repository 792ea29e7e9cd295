"""Row-scaled operators: piece vectors |diag(A)|^-1/2 in place of the piece constants where they are smoother.

A program that hands over D A D, A a Poisson-type matrix and D a diagonal scaling far from constant (unknowns in
mixed units, a symmetric scaling of its own), has D^-1 1 as its near null space, not the constant: the piece
constants then make a coarse space no better than none (2-D Poisson at 40 000 rows, D in 1e-2 .. 1e2 per row:
465 CG iterations, 26 unscaled). Where A's own diagonal is about constant, |diag(D A D)|^-1/2 is proportional to
D^-1 and restores them. Which vector is the smoother one the operator tells: z replaces the constant when its
Rayleigh quotient z^T A z / z^T |diag| z is below :data:`RATIO` times the constant's (a coefficient jump makes z
rough across it, and the constant stays; a singular Neumann matrix keeps its constant, whose quotient is zero).
Couplings to other ranks' rows are left out of both quotients alike, and so are decoupled rows (no nonzero
off-diagonal entry: a DMDA's Dirichlet rows) and rows their own diagonal decides (:data:`.dominance.SOLVED`: a
penalty's Dirichlet rows, whose a_ii would make the constant's whole quotient and which would weigh one for z whatever
the scaling: P1 triangles of 40 000 rows with a penalty of 1e10 beside a coefficient of 1e4 took 255 CG iterations on
z). PETSc-free.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from .aggregation import decoupled_rows
from .csr import abs_diagonal_of, drawn

RATIO = 0.25        # z's quotient must be below this share of the constant's
SPREAD = 0.15       # the sampled couplings' median |log10(a_ii / a_jj)| from which the quotients are worth computing
SPREAD_ROWS = 1024  # ... in about this many rows


def inverse_root(diag) -> np.ndarray:
    """|a_ii|^-1/2 of the diagonal ``diag`` (1 where a_ii is 0): the smoother vector z of a row-scaled operator."""
    return 1.0 / np.sqrt(np.where(diag != 0, np.abs(diag), 1.0))


def quotients(rows, start, coll, block=None, solved=None) -> tuple:
    """(the constant's quotient, z's quotient, z) with z = |diag|^-1/2 on this rank's ``rows`` (CSR, global columns,
    local rows ``start`` ...; couplings to other ranks' rows, decoupled rows and the ``solved`` local rows left out:
    the module docstring); the quotients are sums over all ranks (collective). ``block``: the rows' diagonal
    block (this rank's columns), where it is at hand (:func:`petsc_htp.petscmat.diagonal_block`); else it is cut
    from ``rows``."""
    n = rows.shape[0]
    diag = np.abs(rows.diagonal(k=start))
    z = inverse_root(diag)
    coupled = ~decoupled_rows(rows, start)
    if solved is not None:
        coupled[solved] = False
    local = rows if block is None else block
    if local.shape[1] != n:                                     # this rank's columns only, by compiled products
        col = rows.indices - start
        inside = (col >= 0) & (col < n)
        local = sp.csr_matrix((np.where(inside, rows.data, 0.0), np.where(inside, col, 0), rows.indptr), shape=(n, n))
    sums = np.zeros(4)
    for i, v in enumerate((coupled.astype(np.float64), z * coupled)):
        sums[2 * i:2 * i + 2] = v @ (local @ v), v @ (diag * v)
    sums = coll.sum_array(sums)
    one, rough = (float(a / b) if b > 0 else 0.0 for a, b in (sums[:2], sums[2:]))
    return one, rough, z


def neighbours_spread(rows, start, coll) -> bool:
    """Whether the diagonal entries of coupled rows differ enough over all ranks (``coll``) to call for the quotients:
    the median |log10(|a_ii| / |a_jj|)| over the nonzero couplings of :data:`SPREAD_ROWS` rows drawn at random
    (:func:`.csr.drawn`: a stride of 1 024 rows sampled the 1M-row DMDA's boundary column alone) of this rank's
    ``rows`` (columns of this rank's) above :data:`SPREAD` on some rank, read from those rows and their neighbours'
    alone (one neighbour a row). D A D with D = 10^U(-0.5, 0.5) per row: about 0.6 (a_ii scales as d_i^2); the
    foreign study's matrices at 65 536 rows: 0 (a coefficient jump changes the rows along it only; a
    log-normal field of 4 096 rows passes, and the quotients then keep its constants). Its cost and the quotients':
    ``results/robust-20261128/gate.txt``. Collective."""
    n = rows.shape[0]
    picked = drawn(n, SPREAD_ROWS)
    mine, (where, owner) = abs_diagonal_of(rows, picked, start)
    col = rows.indices[where] - start
    pair = np.flatnonzero((rows.data[where] != 0) & (col != picked[owner]) & (col >= 0) & (col < n))
    first = pair[np.concatenate(([True], owner[pair][1:] != owner[pair][:-1]))] if pair.size else pair
    mine, theirs = mine[owner[first]], abs_diagonal_of(rows, col[first], start)[0]  # one neighbour a sampled row
    both = (mine > 0) & (theirs > 0)
    spread = np.abs(np.log10(mine[both] / theirs[both]))
    return coll.any(bool(spread.size) and float(np.median(spread)) > SPREAD)


def attached(mat, coll):
    """The one vector of ``mat``'s attached null space where it is no constant and nonzero on every row of every
    rank (D^-1 1 of a singular D A D: the pieces then take it in place of their constants; a Neumann square's
    Laplacian of 22 500 rows, D = 10^U(-1, 1): 32 CG iterations against 423, 31 against 419 on two ranks:
    ``tests/bad_input_cases.py``'s ``null_vector_attached``), else None. Collective."""
    nsp = mat.getNullSpace()
    vecs = nsp.getVecs() if nsp.handle and not nsp.hasConstant() else []
    z = vecs[0].getArray(readonly=True).copy() if len(vecs) == 1 else np.zeros(0)
    return z if coll.min_array(np.array([len(vecs) == 1 and np.all(z != 0)], dtype=np.int64))[0] else None


def weights(rows, start, coll, block=None, solved=None, null=None):
    """(z, (the constant's quotient, z's)) where z = |diag(A)|^-1/2 is the smoother vector on this rank's rows (see
    the module docstring), else (None, the quotients); ``block`` as :func:`quotients` takes it. Where A has null
    components (``null``: the Mat): (its attached null vector, None) as :func:`attached` finds it, else (None, None):
    a null constant stays. Collective."""
    if null is not None:
        return attached(null, coll), None
    one, rough, z = quotients(rows, start, coll, block, solved)
    return (z if rough < RATIO * one else None), (one, rough)


def note(weighted, quotients) -> str:
    """``-ksp_view``'s words on the pieces' vectors where they are ``weighted`` (:func:`weights`'s z, with its
    ``quotients``, or the attached null vector where those are None), else empty."""
    if not weighted:
        return ""
    if quotients is None:
        return "; pieces take the attached null vector in place of their constants"
    return (f"; pieces take |diag|^-1/2 in place of their constants (a row-scaled operator: Rayleigh quotient "
            f"{quotients[1]:.2g} against the constant's {quotients[0]:.2g})")
