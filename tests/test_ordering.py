"""Tests for Morton codes and row orderings."""
import numpy as np
import pytest
import scipy.sparse as sp

from petsc_htp.morton import morton_code, morton_permutation, quantized_morton_codes
from petsc_htp.ordering import (
    choose_ordering,
    is_morton_sorted,
    rcm_permutation,
)

SIDE = 16  # a square power-of-two grid, where quantised codes keep the cell order


def grid_laplacian(side):
    """Row-major 5-point Laplacian (Neumann) on a ``side x side`` grid."""
    path = sp.diags([-np.ones(side - 1), -np.ones(side - 1)], [-1, 1])
    path = path - sp.diags(np.asarray(path.sum(axis=1)).ravel())
    eye = sp.identity(side)
    return sp.csr_matrix(sp.kron(eye, path) + sp.kron(path, eye))


def grid_cells(side):
    """Row-major cell indices and normalised cell centres."""
    iy, ix = np.divmod(np.arange(side * side), side)
    return ix, iy, np.column_stack(((ix + 0.5) / side, (iy + 0.5) / side))


def bandwidth(A):
    coo = sp.coo_matrix(A)
    return int(np.abs(coo.row - coo.col).max())


def shuffled_problem(seed=0):
    """Grid Laplacian and coordinates under a random relabelling."""
    ix, iy, coords = grid_cells(SIDE)
    shuffle = np.random.default_rng(seed).permutation(SIDE * SIDE)
    A = grid_laplacian(SIDE)[shuffle][:, shuffle]
    return A, coords[shuffle], ix[shuffle], iy[shuffle]


# --------------------------------------------------------------------- morton

def test_morton_code_by_hand():
    np.testing.assert_array_equal(
        morton_code([0, 1, 0, 1, 2, 3], [0, 0, 1, 1, 0, 3]), [0, 1, 2, 3, 4, 15])
    assert morton_code(2**32 - 1, 2**32 - 1) == np.uint64(2**64 - 1)
    assert morton_code(0, 2**31) == np.uint64(2**63)
    assert morton_code([5], [9]).dtype == np.uint64


@pytest.mark.parametrize("ix, iy, match", [
    ([-1], [0], "ix"),
    ([0], [2**32], "iy"),
    ([0.5], [0], "ix must be an integer"),
])
def test_morton_code_rejects_bad_input(ix, iy, match):
    with pytest.raises(ValueError, match=match):
        morton_code(ix, iy)


def test_morton_code_3d_by_hand_and_octree_blocks():
    np.testing.assert_array_equal(morton_code([1, 0, 0, 1, 3], [0, 1, 0, 1, 3], [0, 0, 1, 1, 3]), [1, 2, 4, 7, 63])
    assert morton_code(2**21 - 1, 2**21 - 1, 2**21 - 1) == np.uint64(2**63 - 1)
    with pytest.raises(ValueError, match="iz"):
        morton_code([0], [0], [2**21])
    iz, iy, ix = np.unravel_index(np.arange(64), (4, 4, 4))
    order = morton_permutation(np.column_stack([ix, iy, iz]) + 0.5)
    for block in order.reshape(8, 8):                   # each run of 8 is one 2 x 2 x 2 octant
        assert all(np.ptp(axis[block]) == 1 for axis in (ix, iy, iz))


def test_morton_permutation_recovers_morton_order_of_shuffled_grid():
    _, coords, ix, iy = shuffled_problem()
    perm = morton_permutation(coords)
    assert perm.dtype == np.int64
    codes = morton_code(ix[perm], iy[perm])
    assert np.all(np.diff(codes.astype(np.int64)) == 1)  # 0, 1, 2, ... on a full grid


def test_morton_permutation_is_stable_and_validates():
    coords = np.array([[1.0, 1.0], [0.0, 0.0], [1.0, 1.0], [0.0, 0.0]])
    np.testing.assert_array_equal(morton_permutation(coords), [1, 3, 0, 2])
    np.testing.assert_array_equal(quantized_morton_codes(np.zeros((3, 2))), [0, 0, 0])
    with pytest.raises(ValueError, match="coords must have shape"):
        morton_permutation(np.zeros((4, 4)))
    with pytest.raises(ValueError, match="bits"):
        quantized_morton_codes(np.zeros((2, 3)), bits=22)       # 3 x 22 bits do not fit 64
    with pytest.raises(ValueError, match="finite"):
        morton_permutation([[0.0, np.nan]])
    with pytest.raises(ValueError, match="bits"):
        morton_permutation(coords, bits=40)


@pytest.mark.parametrize("n", [2048, 3000])
def test_non_square_scene_order_is_recovered_from_coordinates(n):
    """Cell centres of a W x H grid (W != H, truncated) give the scene's integer Morton order back."""
    from petsc_htp.scenes.generator import make_frame

    coords = make_frame(n, seed=1).coords
    assert is_morton_sorted(coords)
    shuffle = np.random.default_rng(0).permutation(n)
    np.testing.assert_array_equal(shuffle[morton_permutation(coords[shuffle])], np.arange(n))


def test_scattered_points_fall_back_to_bounding_box_quantisation():
    pts = np.random.default_rng(1).random((200, 2))
    codes = quantized_morton_codes(pts, bits=4)
    assert codes.max() < 2**8 and len(np.unique(codes)) > 50


def test_is_morton_sorted():
    _, coords, _, _ = shuffled_problem()
    assert not is_morton_sorted(coords)
    assert is_morton_sorted(coords[morton_permutation(coords)])


# ------------------------------------------------------------------------ rcm

def test_rcm_is_permutation_and_reduces_bandwidth():
    A, _, _, _ = shuffled_problem(seed=1)
    perm = rcm_permutation(A)
    assert perm.dtype == np.int64
    np.testing.assert_array_equal(np.sort(perm), np.arange(SIDE * SIDE))
    before, after = bandwidth(A), bandwidth(A[perm][:, perm])
    assert before > 10 * SIDE
    assert after <= 2 * SIDE


# ------------------------------------------------------------ choose_ordering

def test_choose_ordering_natural():
    A, coords, _, _ = shuffled_problem()
    perm, name = choose_ordering(A, coords, method="natural")
    assert name == "natural"
    np.testing.assert_array_equal(perm, np.arange(SIDE * SIDE))


def test_choose_ordering_rcm():
    A, coords, _, _ = shuffled_problem()
    perm, name = choose_ordering(A, coords, method="rcm")
    assert name == "rcm"
    np.testing.assert_array_equal(perm, rcm_permutation(A))


@pytest.mark.parametrize("method", ["morton", "auto"])
def test_choose_ordering_morton_reorders_matrix(method):
    A, coords, ix, iy = shuffled_problem()
    perm, name = choose_ordering(A, coords, method=method)
    assert name == "morton" and perm.dtype == np.int64
    # A[p][:, p] equals the grid Laplacian numbered along the Morton curve.
    ix0, iy0, _ = grid_cells(SIDE)
    order = np.argsort(morton_code(ix0, iy0))
    expected = grid_laplacian(SIDE)[order][:, order]
    assert abs(A[perm][:, perm] - expected).max() == 0
    np.testing.assert_array_equal(iy[perm] * SIDE + ix[perm], order)


def test_choose_ordering_auto_keeps_given_morton_order():
    A, coords, _, _ = shuffled_problem()
    p = morton_permutation(coords)
    perm, name = choose_ordering(A[p][:, p], coords[p])
    assert name == "morton (given)"
    np.testing.assert_array_equal(perm, np.arange(SIDE * SIDE))


def test_choose_ordering_auto_without_coords_is_rcm():
    A, _, _, _ = shuffled_problem()
    perm, name = choose_ordering(A)
    assert name == "rcm"
    np.testing.assert_array_equal(perm, rcm_permutation(A))


def test_choose_ordering_errors():
    A, coords, _, _ = shuffled_problem()
    with pytest.raises(ValueError, match="'morton' needs coordinates"):
        choose_ordering(A, method="morton")
    with pytest.raises(ValueError, match="unknown ordering method 'metis'"):
        choose_ordering(A, coords, method="metis")
    with pytest.raises(ValueError, match="coords must have shape"):
        choose_ordering(A, coords[:-1])
    with pytest.raises(ValueError, match="square"):
        choose_ordering(sp.csr_matrix(np.ones((3, 4))))
    with pytest.raises(ValueError, match="square"):
        rcm_permutation(np.eye(3))
