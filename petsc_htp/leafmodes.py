"""Low eigenvectors of every leaf's local Neumann matrix at once, through one sparse Cholesky factor.

The leaves' Neumann matrices (each leaf block of A with its off-leaf couplings added to the
diagonal) form one block-diagonal sparse matrix S. Its shifted Cholesky factor, computed once
by PETSc, serves every leaf: block inverse iteration from smooth seeds on a (rows, q) matrix
whose columns are local to each leaf, per-leaf QR and a per-leaf Rayleigh-Ritz step in the
padded (K, Lmax, q) layout of :mod:`petsc_htp.twolevel`. Same method as ``twolevel``'s dense
'eig' basis, at sparse cost: one factor, a few multi-vector solves, no dense leaf blocks.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp
import torch
from petsc4py import PETSc

from .twolevel import EIG_OVERSAMPLE, EIG_STEPS, _eigh_modes, _seeds

# Shift of the Neumann matrices, times each leaf's mean |diagonal|. Larger than twolevel's EIG_SHIFT:
# a leaf with several components (a sealed region's edge) gets each component's constant from the
# step, to 1e-4 here; twolevel deflates such near-null coarse directions itself, PETSc's coarse
# Cholesky does not, and with them accurate to 1e-8 W^T A W has eigenvalues at rounding level
# (some negative: an indefinite M on the stability map's 'regions' frames).
SHIFT = 1e-4


def neumann_matrix(inside: sp.csr_matrix, rowsum: np.ndarray, leaf_of: np.ndarray) -> sp.csr_matrix:
    """S: the leaf blocks ``inside`` with each row's off-leaf couplings on the diagonal, shifted.

    ``rowsum`` holds A's full row sums, so the off-leaf part of row i is
    ``rowsum[i] - inside[i].sum()``; the shift is SHIFT times the leaf's mean |diagonal|.
    """
    off = rowsum - np.asarray(inside.sum(axis=1)).ravel()
    mean = np.bincount(leaf_of, np.abs(inside.diagonal() + off)) / np.bincount(leaf_of)
    return (inside + sp.diags(off + SHIFT * mean[leaf_of])).tocsr()


def _factor(S: sp.csr_matrix, ordering: str) -> PETSc.PC:
    """PETSc Cholesky of S on this rank (zero pivots shifted, so it never stops)."""
    mat = PETSc.Mat().createAIJ(size=S.shape, csr=(S.indptr.astype(PETSc.IntType), S.indices.astype(PETSc.IntType),
                                                   S.data), comm=PETSc.COMM_SELF)
    pc = PETSc.PC().create(PETSc.COMM_SELF)
    pc.setOperators(mat, mat)
    pc.setType("cholesky")
    pc.setFactorOrdering(ordering)
    pc.setFactorShift(PETSc.Mat.FactorShiftType.NONZERO)
    pc.setUp()
    mat.destroy()
    return pc


def _solve(factor: PETSc.Mat, X: np.ndarray) -> np.ndarray:
    """S^-1 X for a (rows, q) array, by one multi-vector triangular solve."""
    rhs = PETSc.Mat().createDense(X.shape, array=np.asfortranarray(X), comm=PETSc.COMM_SELF)
    out = PETSc.Mat().createDense(X.shape, comm=PETSc.COMM_SELF)
    out.setUp()
    factor.matSolve(rhs, out)
    Y = out.getDenseArray().copy()
    rhs.destroy()
    out.destroy()
    return Y


def modes(S: sp.csr_matrix, pos: np.ndarray, mask: torch.Tensor, r: int, ordering: str = "natural",
          seeds: torch.Tensor | None = None, extra: int = 0) -> tuple:
    """Approximate r lowest eigenvectors of each leaf block of S, (K, Lmax, r) float64, zero on the padding,
    and their Ritz values (K, r), ascending per leaf (inf for the missing vectors of a leaf under r rows).

    EIG_STEPS block inverse-iteration steps from the seeds, per-leaf QR, then Rayleigh-Ritz
    with S; leaves with at most q rows get a dense eigh instead. With ``extra``, that many further
    cosines go through the same step, orthogonal to the first vectors, and come after them
    (Rayleigh-Ritz within themselves): r + extra columns, the first r unchanged.

    Parameters
    ----------
    S : scipy.sparse.csr_matrix
        Block-diagonal SPD matrix (:func:`neumann_matrix`) in the caller's row order.
    pos : numpy.ndarray (rows,)
        Padded position ``k * Lmax + i`` of each caller row.
    mask : Tensor (K, Lmax)
        1.0 on real rows.
    r : int
    ordering : str
        PETSc ordering for the factor (natural when the leaves are contiguous rows).
    seeds : Tensor (K, Lmax, q), optional
        Start vectors (default: the ``r + EIG_OVERSAMPLE`` smoothest cosines of each leaf).
    """
    K, L = mask.shape
    X = _seeds(mask, r + EIG_OVERSAMPLE) if seeds is None else seeds
    q0 = X.shape[2]
    if extra:
        X = torch.cat([X, _seeds(mask, q0 + extra)[:, :, q0:]], dim=2)
    q = X.shape[2]
    pad = lambda X: torch.zeros(K * L, X.shape[1], dtype=torch.float64).index_copy_(  # noqa: E731
        0, torch.as_tensor(pos), torch.as_tensor(X)).view(K, L, -1)
    rows = lambda X: X.reshape(K * L, -1)[pos].numpy()                                   # noqa: E731
    pc = _factor(S, ordering)
    for _ in range(EIG_STEPS):
        X = torch.linalg.qr(pad(_solve(pc.getFactorMatrix(), rows(X))))[0] * mask[:, :, None]
    pc.destroy()
    SX = pad(S @ rows(X))
    theta, ritz = torch.linalg.eigh(X[:, :, :q0].mT @ SX[:, :, :q0])
    P, theta = X[:, :, :q0] @ ritz[:, :, :r], theta[:, :r]
    if extra:                                           # QR kept the first q0 columns' span: the rest is its complement
        theta_x, ritz_x = torch.linalg.eigh(X[:, :, q0:].mT @ SX[:, :, q0:])
        P, theta = torch.cat([P, X[:, :, q0:] @ ritz_x], dim=2), torch.cat([theta, theta_x], dim=1)
    small = (mask.sum(1) <= q).nonzero().flatten()
    if small.numel():                                   # too few rows for the iteration: dense eigh
        dense = torch.zeros(small.numel(), L, L, dtype=torch.float64)
        for j, k in enumerate(small.tolist()):
            idx = np.flatnonzero(pos // L == k)
            slot = torch.as_tensor(pos[idx] % L)
            dense[j, slot[:, None], slot[None, :]] = torch.as_tensor(S[idx][:, idx].toarray())
        P[small] = _eigh_modes(dense, mask[small], r + extra)
        theta[small] = torch.einsum("klr,klm,kmr->kr", P[small], dense, P[small])
        theta[small] = torch.where(P[small].abs().sum(1) > 0, theta[small], torch.inf)
    return P, theta
