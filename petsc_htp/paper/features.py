"""Network inputs computed from the (ordered) operator, optional geometry and density.

Everything is normalised by s_A = mean(diag(A)), so the network sees the same
input whatever the units of A.
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np
import scipy.sparse as sp
import torch

from .partition import Partition

NODE_FEATURES = 12
GLOBAL_FEATURES = 12
PAIR_FEATURES = 4


@dataclass
class ModelInput:
    """Tensors the network consumes for one ordered operator."""

    node: torch.Tensor        # (N_pad, NODE_FEATURES)
    glob: torch.Tensor        # (GLOBAL_FEATURES,)
    message: torch.Tensor     # sparse (N_pad, N_pad): D^-1 |A_offdiag|
    leaf_xy: torch.Tensor     # (N_pad, 2) position relative to the leaf's centroid (0 without geometry)
    diag_pair: torch.Tensor   # (K, L, L, PAIR_FEATURES)
    tile_pair: torch.Tensor   # (M_H, L_s, L_s, PAIR_FEATURES)
    mask: torch.Tensor        # (N_pad,) bool, real indices
    tile_mask: torch.Tensor   # (M_H, 2, L_s) bool, row/column tokens with real indices
    inv_diag: torch.Tensor    # (N_pad,) 1/diag(A) in A's units (0 on padding)
    scale: float              # s_A

    def to(self, device) -> "ModelInput":
        """Copy to a device."""
        kw = {k: (v.to(device) if torch.is_tensor(v) else v) for k, v in self.__dict__.items()}
        return ModelInput(**kw)


@lru_cache(maxsize=32)
def tile_lookup(part: Partition) -> np.ndarray:
    """(K, K) table: tile index covering leaf pair (row leaf < column leaf), else -1."""
    K = part.n_leaves
    table = np.full((K, K), -1, dtype=np.int64)
    for m, (r0, r1, c0, c1) in enumerate(part.tiles):
        table[r0:r1, c0:c1] = m
    return table


def strip_tokens(part: Partition) -> np.ndarray:
    """(M_H, 2, L_s, 2) padded node ranges [start, stop) of every row/column sub-strip token."""
    Ls, L = part.coarse, part.leaf
    t = part.tiles * L                                   # node units, padded
    out = np.zeros((part.n_tiles, 2, Ls, 2), dtype=np.int64)
    j = np.arange(Ls)
    for side in (0, 1):
        a, b = t[:, 2 * side], t[:, 2 * side + 1]
        sub = (b - a) // Ls
        out[:, side, :, 0] = a[:, None] + j[None] * sub[:, None]
        out[:, side, :, 1] = out[:, side, :, 0] + sub[:, None]
    return out


def _check_values(A: sp.csr_matrix, n: int) -> np.ndarray:
    """Diagonal of ``A``, or ValueError when ``A`` cannot be an SPD operator of size ``n``."""
    if A.shape != (n, n):
        raise ValueError(f"operator has shape {A.shape}, expected square ({n}, {n})")
    if A.nnz == 0:
        raise ValueError("operator is empty (no nonzeros)")
    if not np.all(np.isfinite(A.data)):
        raise ValueError("operator contains NaN or Inf entries")
    d = A.diagonal()
    if np.any(d <= 0):
        raise ValueError(f"operator has {int(np.sum(d <= 0))} non-positive diagonal entries; HTP needs an SPD matrix")
    return d


@dataclass
class InputStructure:
    """The part of the network input fixed by the nonzero pattern, the partition and the geometry.

    Computed once per pattern by :func:`input_structure`; :func:`input_values` adds the values.
    """

    part: Partition
    rows: np.ndarray          # COO row of every stored entry (sorted CSR order)
    cols: np.ndarray
    off: np.ndarray           # bool, off-diagonal entries
    node: np.ndarray          # (N, NODE_FEATURES) with the pattern and geometry columns filled
    glob: np.ndarray          # (GLOBAL_FEATURES,) likewise
    leaf_xy: torch.Tensor
    diag_pair: np.ndarray     # (K, L, L, PAIR_FEATURES) geometry and structure channels
    tile_pair: np.ndarray     # (M_H, L_s, L_s, PAIR_FEATURES) likewise
    same: np.ndarray          # bool, entries inside a leaf
    tile_index: tuple         # (m, ti, tj, norm) of the strictly upper entries between leaves
    up: np.ndarray            # bool, those entries
    mask: torch.Tensor
    tile_mask: torch.Tensor


def input_structure(A, part: Partition, coords=None) -> InputStructure:
    """Pattern and geometry features of an operator already in the chosen ordering.

    Parameters
    ----------
    A : scipy.sparse matrix, (N, N)
        Only its sorted sparsity pattern is read.
    part : Partition
        Partition for N.
    coords : ndarray (N, 2), optional
        Cell coordinates (any units; normalised here).
    """
    n, L, Ls, K, Np = part.n, part.leaf, part.coarse, part.n_leaves, part.n_pad
    A = sp.csr_matrix(A)
    if A.shape != (n, n):
        raise ValueError(f"operator has shape {A.shape}, expected square ({n}, {n})")
    A.sort_indices()
    coo = A.tocoo()
    i, j = coo.row, coo.col
    off = i != j
    deg = np.bincount(i[off], minlength=n)
    boundary = deg < deg.max() if deg.size else deg.astype(bool)
    has_xy = coords is not None
    if has_xy:
        xy = np.asarray(coords, dtype=np.float64).reshape(n, 2)
        lo, hi = xy.min(0), xy.max(0)
        xy = (xy - lo) / np.where(hi > lo, hi - lo, 1.0)
    else:
        xy = np.zeros((n, 2))
    node = np.zeros((n, NODE_FEATURES))
    node[:, 4] = deg / max(deg.max(), 1)
    node[:, 5] = boundary
    node[:, 6:8] = xy
    node[:, 8] = float(has_xy)
    glob = np.zeros(GLOBAL_FEATURES)
    glob[[0, 6, 7]] = np.log(n) / 10, boundary.mean(), float(has_xy)

    # Within-leaf pair descriptors (dx, dy, A_ij normalised, structural nonzero).
    scale_leaf = np.sqrt(n / L)
    xy_p = np.zeros((Np, 2))
    xy_p[:n] = xy
    X = xy_p.reshape(K, L, 2)
    mask = np.zeros(Np, dtype=bool)
    mask[:n] = True
    centroid = X.sum(1, keepdims=True) / mask.reshape(K, L, 1).sum(1, keepdims=True)
    leaf_xy = ((X - centroid) * scale_leaf).reshape(Np, 2) * mask[:, None]
    diag_pair = np.zeros((K, L, L, PAIR_FEATURES), dtype=np.float32)
    diag_pair[..., :2] = (X[:, :, None, :] - X[:, None, :, :]) * scale_leaf
    same = (i // L) == (j // L)
    diag_pair[i[same] // L, i[same] % L, j[same] % L, 3] = 1.0

    # Tile pair descriptors: centroid offsets and coupling between sub-strips.
    ranges = strip_tokens(part)
    csum = np.concatenate([[0], np.cumsum(mask)])
    cxy = np.concatenate([np.zeros((1, 2)), np.cumsum(xy_p * mask[:, None], axis=0)])
    cnt = csum[ranges[..., 1]] - csum[ranges[..., 0]]           # (M, 2, Ls)
    cen = (cxy[ranges[..., 1]] - cxy[ranges[..., 0]]) / np.maximum(cnt, 1)[..., None]
    M = part.n_tiles
    tile_pair = np.zeros((M, Ls, Ls, PAIR_FEATURES), dtype=np.float32)
    up = (i < j) & ~same
    tile_index = (np.zeros(0, np.int64),) * 3 + (np.zeros(0),)
    if M:
        strip_len = (ranges[:, :, -1, 1] - ranges[:, :, 0, 0]).sum(1) / 2.0
        tile_scale = np.sqrt(n / strip_len)[:, None, None, None]
        tile_pair[..., :2] = (cen[:, 0, :, None, :] - cen[:, 1, None, :, :]) * tile_scale
        ki, kj = i[up] // L, j[up] // L
        m = tile_lookup(part)[ki, kj]
        sub = (ranges[m, 0, 0, 1] - ranges[m, 0, 0, 0])
        ti = (i[up] - ranges[m, 0, 0, 0]) // sub
        subc = (ranges[m, 1, 0, 1] - ranges[m, 1, 0, 0])
        tj = (j[up] - ranges[m, 1, 0, 0]) // subc
        norm = np.sqrt(np.maximum(cnt[m, 0, ti] * cnt[m, 1, tj], 1))
        np.add.at(tile_pair[..., 3], (m, ti, tj), 1.0 / norm)
        tile_index = (m, ti, tj, norm)
    return InputStructure(part=part, rows=i, cols=j, off=off, node=node, glob=glob,
                          leaf_xy=torch.as_tensor(leaf_xy, dtype=torch.float32), diag_pair=diag_pair,
                          tile_pair=tile_pair, same=same, tile_index=tile_index, up=up,
                          mask=torch.from_numpy(mask), tile_mask=torch.from_numpy(cnt > 0))


def input_values(st: InputStructure, A, density=None) -> ModelInput:
    """Complete ``st`` with the values of ``A`` (same sorted pattern) and the density.

    Parameters
    ----------
    st : InputStructure
        From :func:`input_structure` on this pattern.
    A : scipy.sparse matrix, (N, N)
        SPD (or SPD up to the constant null space) operator in the same ordering.
    density : ndarray (N,), optional
        Per-node density.
    """
    part = st.part
    n, L, Np = part.n, part.leaf, part.n_pad
    A = sp.csr_matrix(A, dtype=np.float64)
    A.sort_indices()
    d = _check_values(A, n)
    if A.nnz != st.rows.size:
        raise ValueError(f"operator has {A.nnz} stored entries but its analysed pattern has {st.rows.size} "
                         "(the nonzero pattern changed: analyse it again)")
    i, j, a, off = st.rows, st.cols, A.data, st.off
    s = float(d.mean())
    an = a / np.sqrt(d[i] * d[j])                         # normalised entries
    absoff = np.bincount(i[off], weights=np.abs(a[off]), minlength=n)
    rowsum = np.bincount(i, weights=a, minlength=n)
    mn = np.zeros(n)
    mx = np.full(n, -np.inf)
    np.minimum.at(mn, i[off], an[off])
    np.maximum.at(mx, i[off], an[off])
    mx[~np.isfinite(mx)] = 0.0
    has_rho = density is not None
    if has_rho:
        rho = np.asarray(density, dtype=np.float64).reshape(n)
        if np.any(rho <= 0) or not np.all(np.isfinite(rho)):
            raise ValueError("density must be finite and positive")
        lrho = np.log(rho / np.median(rho))
    else:
        lrho = np.zeros(n)
    logd = np.log(d / s)
    node = st.node.copy()
    node[:, [0, 1, 2, 3, 9, 10, 11]] = np.stack([logd, absoff / d, mn, mx, lrho, np.full(n, float(has_rho)),
                                                 rowsum / d], axis=1)
    w = -an[off]
    lw = np.log(np.clip(w, 1e-12, None)) if w.size else np.zeros(1)
    glob = st.glob.copy()
    glob[[1, 2, 3, 4, 5, 8, 9, 10, 11]] = (np.log(d.max() / d.min()), logd.mean(), logd.std(), lw.mean(), lw.std(),
                                          float(has_rho), lw.max() - lw.min(), np.abs(rowsum / d).mean(), np.ptp(lrho))
    node_p = np.zeros((Np, NODE_FEATURES))
    node_p[:n] = node

    # Message matrix D^-1 |A_off| (row-normalised coupling).
    message = torch.sparse_coo_tensor(np.stack([i[off], j[off]]), np.abs(a[off]) / d[i[off]],
                                      size=(Np, Np), dtype=torch.float32,
                                      check_invariants=False).coalesce()
    diag_pair = st.diag_pair.copy()
    same = st.same
    diag_pair[i[same] // L, i[same] % L, j[same] % L, 2] = an[same]
    tile_pair = st.tile_pair.copy()
    m, ti, tj, norm = st.tile_index
    if m.size:
        np.add.at(tile_pair[..., 2], (m, ti, tj), an[st.up] / norm)
    inv_diag = np.zeros(Np)
    inv_diag[:n] = 1.0 / d
    f32 = dict(dtype=torch.float32)
    return ModelInput(node=torch.as_tensor(node_p, **f32), glob=torch.as_tensor(glob, **f32), message=message,
                      leaf_xy=st.leaf_xy, diag_pair=torch.from_numpy(diag_pair),
                      tile_pair=torch.from_numpy(tile_pair), mask=st.mask, tile_mask=st.tile_mask,
                      inv_diag=torch.as_tensor(inv_diag, **f32), scale=s)


def build_input(A, part: Partition, coords=None, density=None) -> ModelInput:
    """Assemble the network input for an operator already in the chosen ordering.

    Parameters
    ----------
    A : scipy.sparse matrix, (N, N)
        SPD (or SPD up to the constant null space) operator.
    part : Partition
        Partition for N.
    coords : ndarray (N, 2), optional
        Cell coordinates (any units; normalised here).
    density : ndarray (N,), optional
        Per-node density.
    """
    A = sp.csr_matrix(A, dtype=np.float64)
    _check_values(A, part.n)
    return input_values(input_structure(A, part, coords), A, density)
