"""Weak-admissibility (HODLR-type) H-matrix partition over ordered indices.

The N ordered indices are cut into K = ceil(N/L) contiguous leaves of L indices
(the last leaf padded to L and masked). A binary bisection of the leaf range
gives a tree with K leaves and K-1 internal nodes; internal node m owns the
off-diagonal tile m whose row strip is its left child's leaves and whose column
strip is its right child's leaves. Those K-1 tiles cover every off-diagonal
leaf pair of the strict upper triangle exactly once.

Everything here depends on (N, L, L_s) alone and is cached.
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np


@dataclass(frozen=True, eq=False)
class Partition:
    """Static partition of N ordered indices.

    Attributes
    ----------
    n, leaf, coarse : int
        Number of real indices N, leaf size L and coarse token count L_s.
    n_leaves : int
        K = ceil(N / L).
    tiles : ndarray, shape (K-1, 4)
        Per tile: row-leaf start, row-leaf stop, column-leaf start, column-leaf
        stop (leaf units, half-open).
    parent : ndarray, shape (2K-1,)
        Tree parent of every node (-1 for the root). Nodes 0..K-1 are the
        leaves, K..2K-2 the internal nodes; internal node K+m owns tile m.
    left, right : ndarray, shape (K-1,)
        Children of internal node K+m.
    levels : tuple of ndarray
        Non-root nodes grouped by depth, deepest first (for upward sweeps;
        reversed for downward sweeps).
    """

    n: int
    leaf: int
    coarse: int
    n_leaves: int
    tiles: np.ndarray
    parent: np.ndarray
    left: np.ndarray
    right: np.ndarray
    levels: tuple

    @property
    def n_pad(self) -> int:
        """Padded size K*L."""
        return self.n_leaves * self.leaf

    @property
    def n_tiles(self) -> int:
        """M_H = K - 1 unique off-diagonal tiles."""
        return self.n_leaves - 1

    @property
    def packed_width(self) -> int:
        """P = K L^2 + M_H L_s^2 + 2 N_pad L_s + N_pad (N_pad = K L)."""
        K, L, Ls = self.n_leaves, self.leaf, self.coarse
        return K * L * L + self.n_tiles * Ls * Ls + 2 * self.n_pad * Ls + self.n_pad

    def tile_node_ranges(self) -> np.ndarray:
        """Per tile, (row start, row stop, col start, col stop) in index units, clipped to N."""
        return np.minimum(self.tiles * self.leaf, self.n)

    def mask(self) -> np.ndarray:
        """Boolean (N_pad,) mask of real (unpadded) indices."""
        m = np.zeros(self.n_pad, dtype=bool)
        m[: self.n] = True
        return m


def _bisect(n_leaves: int):
    """Return the internal nodes of a balanced bisection of [0, K) in BFS order."""
    nodes = []  # (start, stop, parent_internal_index or -1, is_left)
    queue = [(0, n_leaves, -1, False)]
    while queue:
        start, stop, par, is_left = queue.pop(0)
        nodes.append((start, stop, par, is_left))
        if stop - start > 1:
            mid = (start + stop + 1) // 2
            me = len(nodes) - 1
            queue.append((start, mid, me, True))
            queue.append((mid, stop, me, False))
    return nodes


@lru_cache(maxsize=64)
def build_partition(n: int, leaf: int = 128, coarse: int = 32) -> Partition:
    """Build (and cache) the partition for N indices, leaf size L, L_s coarse tokens.

    Parameters
    ----------
    n : int
        Number of indices, N >= 1.
    leaf : int
        Leaf size L.
    coarse : int
        Coarse token count L_s; must divide L.
    """
    if int(n) != n or n < 1:
        raise ValueError(f"partition size N must be a positive integer, got {n!r}")
    if leaf < 1 or coarse < 1 or leaf % coarse:
        raise ValueError(f"leaf size L={leaf} must be a positive multiple of L_s={coarse}")
    K = -(-int(n) // leaf)
    raw = _bisect(K)
    # Number tree nodes: leaves 0..K-1 by leaf index, internal nodes K.. in BFS order.
    ids = np.empty(len(raw), dtype=np.int64)
    n_int = 0
    for i, (start, stop, _, _) in enumerate(raw):
        if stop - start == 1:
            ids[i] = start
        else:
            ids[i] = K + n_int
            n_int += 1
    parent = np.full(2 * K - 1, -1, dtype=np.int64)
    depth = np.zeros(2 * K - 1, dtype=np.int64)
    left = np.zeros(K - 1, dtype=np.int64)
    right = np.zeros(K - 1, dtype=np.int64)
    tiles = np.zeros((K - 1, 4), dtype=np.int64)
    span = {}
    for i, (start, stop, par, is_left) in enumerate(raw):
        node = ids[i]
        span[node] = (start, stop)
        if par >= 0:
            p = ids[par]
            parent[node] = p
            depth[node] = depth[p] + 1
            (left if is_left else right)[p - K] = node
    for m in range(K - 1):
        tiles[m, :2] = span[left[m]]
        tiles[m, 2:] = span[right[m]]
    non_root = np.flatnonzero(parent >= 0)
    levels = tuple(non_root[depth[non_root] == d] for d in range(int(depth.max()), 0, -1))
    return Partition(int(n), leaf, coarse, K, tiles, parent, left, right, levels)
