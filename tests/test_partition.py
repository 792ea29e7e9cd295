import numpy as np
import pytest

from petsc_htp.paper.partition import build_partition


@pytest.mark.parametrize("n,leaf", [(1, 8), (8, 8), (9, 8), (40, 8), (64, 8), (100, 8), (1000, 128), (16384, 128)])
def test_tiles_cover_upper_triangle_once(n, leaf):
    p = build_partition(n, leaf, leaf // 4)
    K = p.n_leaves
    assert K == -(-n // leaf) and p.n_tiles == K - 1
    cover = np.zeros((K, K), dtype=int)
    for r0, r1, c0, c1 in p.tiles:
        assert r0 < r1 <= c0 < c1 <= K            # strictly above the diagonal, contiguous strips
        cover[r0:r1, c0:c1] += 1
    np.testing.assert_array_equal(cover, np.triu(np.ones((K, K), dtype=int), 1))


def test_packed_width_formula():
    p = build_partition(1000, 128, 32)
    K, L, Ls = 8, 128, 32
    assert p.packed_width == K * L * L + (K - 1) * Ls * Ls + 2 * K * L * Ls + K * L
    q = build_partition(8192, 128, 32)
    assert round(q.packed_width / 1e6, 2) == 1.65  # the supplement table: P = 1.65 M at N = 8192


def test_tree_levels_reach_every_node_once():
    p = build_partition(13 * 16, 16, 4)
    seen = np.concatenate(p.levels)
    assert sorted(seen.tolist()) == [v for v in range(2 * p.n_leaves - 1) if p.parent[v] >= 0]


def test_cached_and_validated():
    assert build_partition(512, 128, 32) is build_partition(512, 128, 32)
    with pytest.raises(ValueError, match="positive integer"):
        build_partition(0)
    with pytest.raises(ValueError, match="multiple"):
        build_partition(100, 128, 48)
