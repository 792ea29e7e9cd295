"""Matrix-free application of the HTP preconditioner M from its packed factors.

    M r = blockdiag(F_k F_k^T) r                       (diagonal stage)
        + sum_m [U~_R B_m V~_C^T + (U~_R B_m V~_C^T)^T] r  (off-diagonal chain)
        + g * r,            g = (lambda + shift) / diag(A)  (Jacobi gate)

The off-diagonal chain is restriction (batched GEMM), strip aggregation (an
upward sweep of the partition tree), coarse coupling (batched GEMM with B_m and
B_m^T), redistribution (a downward sweep) and prolongation (batched GEMM). M is
symmetric by construction and never assembled (except by :func:`assemble`, for
tests on small N).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from .partition import Partition


@dataclass
class Factors:
    """Views into one packed factor tensor of width P."""

    F: torch.Tensor  # (K, L, L)
    B: torch.Tensor  # (M_H, L_s, L_s)
    U: torch.Tensor  # (K, L, L_s)
    V: torch.Tensor  # (K, L, L_s)
    g: torch.Tensor  # (N_pad,)

    @classmethod
    def unpack(cls, packed: torch.Tensor, part: Partition) -> "Factors":
        """Split a packed (P,) tensor into factor views (no copy)."""
        if packed.ndim != 1 or packed.numel() != part.packed_width:
            raise ValueError(
                f"packed factors have shape {tuple(packed.shape)}, expected ({part.packed_width},) "
                f"for N={part.n}, L={part.leaf}, L_s={part.coarse}")
        K, L, Ls, M, Np = part.n_leaves, part.leaf, part.coarse, part.n_tiles, part.n_pad
        sizes = [K * L * L, M * Ls * Ls, Np * Ls, Np * Ls, Np]
        F, B, U, V, g = torch.split(packed, sizes)
        return cls(F.view(K, L, L), B.view(M, Ls, Ls), U.view(K, L, Ls), V.view(K, L, Ls), g)

    def pack(self) -> torch.Tensor:
        """Concatenate the factors into one (P,) tensor."""
        return torch.cat([t.reshape(-1) for t in (self.F, self.B, self.U, self.V, self.g)])


class TreeIndex:
    """Partition index tensors on a device: tile children and sweep levels."""

    def __init__(self, part: Partition, device="cpu"):
        dev = torch.device(device)
        self.part = part
        self.n_nodes = 2 * part.n_leaves - 1
        self.left = torch.as_tensor(part.left, device=dev)
        self.right = torch.as_tensor(part.right, device=dev)
        self.levels = [(torch.as_tensor(lv, device=dev), torch.as_tensor(part.parent[lv], device=dev))
                       for lv in part.levels]


def _up(sub: torch.Tensor, tree: TreeIndex) -> torch.Tensor:
    """Subtree sums: leaves hold their values, each parent accumulates its children."""
    for nodes, parents in tree.levels:
        sub = sub.index_add(0, parents, sub[nodes]) if sub.requires_grad else sub.index_add_(0, parents, sub[nodes])
    return sub


def _down(acc: torch.Tensor, tree: TreeIndex) -> torch.Tensor:
    """Push every node's accumulated value down to all of its descendants."""
    for nodes, parents in reversed(tree.levels):
        if acc.requires_grad:
            acc = acc.index_add(0, nodes, acc[parents])
        else:
            acc[nodes] += acc[parents]
    return acc


def htp_apply(f: Factors, tree: TreeIndex, r: torch.Tensor) -> torch.Tensor:
    """Return M r for a block of vectors ``r`` of shape (N_pad, nrhs).

    Differentiable in the factors; padded entries of ``r`` must be zero.
    """
    K, L, Ls = f.F.shape[0], f.F.shape[1], f.U.shape[2]
    nrhs = r.shape[1]
    R = r.reshape(K, L, nrhs)
    y = torch.bmm(f.F, torch.bmm(f.F.transpose(1, 2), R))
    if K > 1:
        zeros = r.new_zeros((tree.n_nodes - K, Ls, nrhs))
        su = _up(torch.cat([torch.bmm(f.U.transpose(1, 2), R), zeros]), tree)
        sv = _up(torch.cat([torch.bmm(f.V.transpose(1, 2), R), zeros]), tree)
        tr = torch.bmm(f.B, sv[tree.right])                    # to the row strips
        tc = torch.bmm(f.B.transpose(1, 2), su[tree.left])     # to the column strips
        acc_r = torch.zeros_like(su).index_add(0, tree.left, tr)
        acc_c = torch.zeros_like(sv).index_add(0, tree.right, tc)
        acc_r, acc_c = _down(acc_r, tree), _down(acc_c, tree)
        y = y + torch.bmm(f.U, acc_r[:K]) + torch.bmm(f.V, acc_c[:K])
    return y.reshape(-1, nrhs) + f.g[:, None] * r


class HTPOperator:
    """M bound to fixed factors, applied to one vector on preallocated buffers (inference hot path).

    Vectors are kept as rows, shape (K, 1, L), and every product is ``row @ matrix`` against a
    contiguous copy of the factor or its transpose made once here: on CPU a batched
    row-times-matrix product is several times faster than the matrix-times-column form.

    Parameters
    ----------
    packed : torch.Tensor
        Packed (P,) float32 factors.
    part : Partition
        The partition they were produced for.
    """

    def __init__(self, packed: torch.Tensor, part: Partition):
        self.part = part
        self.packed = packed.detach()
        self.f = Factors.unpack(self.packed, part)
        f = self.f
        self.Ft = f.F.transpose(1, 2).contiguous()
        self.Ut = f.U.transpose(1, 2).contiguous()
        self.Vt = f.V.transpose(1, 2).contiguous()
        self.Bt = f.B.transpose(1, 2).contiguous()
        self.tree = TreeIndex(part, self.packed.device)
        K, L, Ls, dev = part.n_leaves, part.leaf, part.coarse, self.packed.device
        kw = dict(dtype=self.packed.dtype, device=dev)
        self.r = torch.zeros(part.n_pad, 1, **kw)
        self.y = torch.zeros(part.n_pad, 1, **kw)
        self.t = torch.zeros(K, 1, L, **kw)
        self.su = torch.zeros(2 * K - 1, 1, Ls, **kw)
        self.sv = torch.zeros_like(self.su)
        self.acc_r = torch.zeros_like(self.su)
        self.acc_c = torch.zeros_like(self.su)
        self.tiles = torch.zeros(max(K - 1, 0), 1, Ls, **kw)
        self.leaf_out = torch.zeros(K, 1, L, **kw)

    @torch.no_grad()
    def load_(self, packed: torch.Tensor) -> None:
        """Copy new factors (same partition) into this operator's buffers in place."""
        self.packed.copy_(packed)
        f = self.f
        for dst, src in ((self.Ft, f.F), (self.Ut, f.U), (self.Vt, f.V), (self.Bt, f.B)):
            dst.copy_(src.transpose(1, 2))

    @property
    def nbytes(self) -> int:
        """Bytes held by the factors (the packed tensor and its transposed copies)."""
        return sum(t.numel() * t.element_size() for t in (self.packed, self.Ft, self.Ut, self.Vt, self.Bt))

    def buffer_numel(self) -> int:
        """Number of elements in the preallocated work buffers."""
        return sum(t.numel() for t in (self.r, self.y, self.t, self.su, self.sv, self.acc_r,
                                       self.acc_c, self.tiles, self.leaf_out))

    @torch.no_grad()
    def apply_(self) -> torch.Tensor:
        """Compute ``self.y = M self.r`` in place on the buffers; returns ``self.y``."""
        f, tree, K = self.f, self.tree, self.part.n_leaves
        L = self.part.leaf
        R = self.r.view(K, 1, L)
        Y = self.y.view(K, 1, L)
        torch.bmm(R, f.F, out=self.t)                        # (F^T r)^T
        torch.bmm(self.t, self.Ft, out=Y)                     # (F F^T r)^T
        if K > 1:
            torch.bmm(R, f.U, out=self.su[:K])                # restriction
            torch.bmm(R, f.V, out=self.sv[:K])
            self.su[K:].zero_()
            self.sv[K:].zero_()
            _up(self.su, tree)
            _up(self.sv, tree)
            self.acc_r.zero_()
            self.acc_c.zero_()
            torch.bmm(self.sv[tree.right], self.Bt, out=self.tiles)     # (B s_c)^T to the row strips
            self.acc_r.index_add_(0, tree.left, self.tiles)
            torch.bmm(self.su[tree.left], f.B, out=self.tiles)          # (B^T s_r)^T to the column strips
            self.acc_c.index_add_(0, tree.right, self.tiles)
            _down(self.acc_r, tree)
            _down(self.acc_c, tree)
            Y.add_(torch.bmm(self.acc_r[:K], self.Ut, out=self.leaf_out))   # prolongation
            Y.add_(torch.bmm(self.acc_c[:K], self.Vt, out=self.leaf_out))
        self.y.addcmul_(f.g[:, None], self.r)
        return self.y

    def apply(self, r: np.ndarray) -> np.ndarray:
        """Return M r for a float64 vector of length N (float32 inside)."""
        n = self.part.n
        self.r[:n, 0].copy_(torch.from_numpy(np.asarray(r)))
        return self.apply_()[:n, 0].double().cpu().numpy()


def assemble(f: Factors, part: Partition) -> np.ndarray:
    """Dense float64 M (N x N) from its factors; for tests on small N."""
    F, B, U, V = (t.detach().double().cpu().numpy() for t in (f.F, f.B, f.U, f.V))
    L, n = part.leaf, part.n
    M = np.zeros((part.n_pad, part.n_pad))
    for k in range(part.n_leaves):
        M[k * L:(k + 1) * L, k * L:(k + 1) * L] = F[k] @ F[k].T
    Uf, Vf = U.reshape(-1, U.shape[2]), V.reshape(-1, V.shape[2])
    for m, (r0, r1, c0, c1) in enumerate(part.tiles * L):
        blk = Uf[r0:r1] @ B[m] @ Vf[c0:c1].T
        M[r0:r1, c0:c1] += blk
        M[c0:c1, r0:r1] += blk.T
    M += np.diag(f.g.detach().double().cpu().numpy())
    return M[:n, :n]


def apply_flops(part: Partition, nrhs: int = 1) -> int:
    """Floating-point operations of one apply to ``nrhs`` vectors (multiply-add = 2)."""
    K, L, Ls, Np, M = part.n_leaves, part.leaf, part.coarse, part.n_pad, part.n_tiles
    diag = 2 * 2 * K * L * L
    bridges = 4 * 2 * Np * Ls             # two restrictions, two prolongations
    coupling = 2 * 2 * M * Ls * Ls
    sweeps = 4 * 2 * M * Ls                # up and down sweeps, row and column (one add per child)
    return nrhs * (diag + bridges + coupling + sweeps + 2 * Np)
