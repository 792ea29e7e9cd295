"""Grid coordinates found by breadth-first search in a bare matrix's graph."""
import numpy as np
import pytest
import scipy.sparse as sp
from scipy.sparse.csgraph import shortest_path

from petsc_htp.twolevel.embedding import bfs_levels, grid_coordinates
from petsc_htp.twolevel.leaves import choose_leaves
from petsc_htp.scenes.generator import make_frame

from conftest import grid_laplacian


def test_bfs_levels_are_graph_distances_from_the_nearest_source():
    A = make_frame(1024, seed=2).A
    for sources in ([7], [7, 500, 1000]):
        want = shortest_path(abs(A), indices=sources, unweighted=True).min(0)
        assert np.array_equal(bfs_levels(A, sources), want)
    two = sp.block_diag([grid_laplacian(4, 4), grid_laplacian(3, 3)]).tocsr()
    assert np.all(bfs_levels(two, [0])[16:] == -1) and np.all(bfs_levels(two, [0])[:16] >= 0)


@pytest.mark.parametrize("nx, ny", [(32, 32), (40, 24)])
def test_grid_coordinates_recover_the_axes_of_a_shuffled_grid(nx, ny):
    q = np.random.default_rng(nx).permutation(nx * ny)
    A = grid_laplacian(nx, ny)[q][:, q].tocsr()
    xy = grid_coordinates(A)
    ix, iy = (np.arange(nx * ny) % nx)[q], (np.arange(nx * ny) // nx)[q]
    # each found axis is one grid axis up to sign, scale and offset
    corr = np.abs(np.corrcoef(np.column_stack([xy, ix, iy]).T)[:2, 2:])
    assert np.allclose(np.sort(corr.max(1)), 1.0) and np.allclose(np.sort(corr.min(1)), 0.0, atol=1e-12)


def test_grid_coordinates_decline_3d_and_disconnected_graphs():
    t = sp.diags([-np.ones(11), 2 * np.ones(12), -np.ones(11)], [-1, 0, 1])
    eye = sp.eye(12)
    cube = (sp.kron(sp.kron(t, eye), eye) + sp.kron(sp.kron(eye, t), eye) + sp.kron(sp.kron(eye, eye), t)).tocsr()
    assert grid_coordinates(cube) is None
    assert grid_coordinates(sp.block_diag([grid_laplacian(8, 8), grid_laplacian(8, 8)]).tocsr()) is None


def test_graph_leaves_of_a_shuffled_grid_are_its_square_blocks():
    q = np.random.default_rng(0).permutation(64 * 64)
    A = grid_laplacian(64, 64)[q][:, q].tocsr()
    lv = choose_leaves(A, layout="graph", leaf=64)
    assert lv.kind == "graph" and np.all(lv.sizes == 64)
    ix, iy = (np.arange(4096) % 64)[q], (np.arange(4096) // 64)[q]
    for lo, hi in zip(lv.offsets[:-1], lv.offsets[1:]):
        rows = lv.perm[lo:hi]
        assert np.ptp(ix[rows]) == 7 and np.ptp(iy[rows]) == 7          # an 8 x 8 block


def test_grid_coordinates_leave_the_matrix_alone():
    q = np.random.default_rng(3).permutation(16 * 16)
    A = grid_laplacian(16, 16)[q][:, q].tocsr()
    before = (A.indptr.copy(), A.indices.copy(), A.data.copy())
    grid_coordinates(A)
    assert all(np.array_equal(x, y) for x, y in zip(before, (A.indptr, A.indices, A.data)))
