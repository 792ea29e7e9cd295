"""Tests for the multiphase Poisson benchmark generator."""

import numpy as np
import pytest
import scipy.sparse as sp

from petsc_htp.scenes.dataset import dataset_seeds, load_dataset
from petsc_htp.scenes.plot import plot_frame
from petsc_htp.scenes.generator import (
    DISTRIBUTIONS,
    GENERATOR_VERSION,
    assemble_operator,
    barrier_mask,
    buoyancy_rhs,
    frame_summary,
    grid_dims,
    make_frame,
    morton_cells,
    sample_params,
)


def brute_force_morton(ix, iy, bits=16):
    """Morton code by explicit bit interleaving, one cell at a time."""
    code = 0
    for k in range(bits):
        code |= ((ix >> k) & 1) << (2 * k)
        code |= ((iy >> k) & 1) << (2 * k + 1)
    return code


def frame_arrays(frame):
    """All arrays of a frame, for exact comparisons."""
    return [frame.A.indptr, frame.A.indices, frame.A.data, frame.b, frame.rho,
            frame.coords, frame.perm]


def assert_frames_identical(f, g):
    for a, b in zip(frame_arrays(f), frame_arrays(g)):
        assert a.dtype == b.dtype
        np.testing.assert_array_equal(a, b)
    assert f.grid_shape == g.grid_shape
    assert f.params == g.params


# ----------------------------------------------------------------------- grid

@pytest.mark.parametrize("n, dims", [
    (1, (1, 1)), (2, (2, 1)), (3, (2, 2)), (5, (3, 2)), (7, (3, 3)),
    (1000, (32, 32)), (1024, (32, 32)), (2048, (46, 45)),
])
def test_frame_sizes(n, dims):
    frame = make_frame(n, seed=1)
    assert grid_dims(n) == dims
    assert frame.grid_shape == dims
    assert frame.n == n and frame.A.shape == (n, n)
    assert frame.b.shape == frame.rho.shape == frame.perm.shape == (n,)
    assert frame.coords.shape == (n, 2)
    assert frame.perm.dtype == np.int64
    assert len(np.unique(frame.perm)) == n and frame.perm.max() < dims[0] * dims[1]


@pytest.mark.parametrize("n", [4, 16, 5, 7, 10, 23])
def test_morton_order_matches_brute_force(n):
    w, h = grid_dims(n)
    cells = sorted(((x, y) for x in range(w) for y in range(h)),
                   key=lambda c: brute_force_morton(*c))[:n]
    ix, iy = morton_cells(n)
    assert list(zip(ix.tolist(), iy.tolist())) == cells
    frame = make_frame(n)
    np.testing.assert_array_equal(frame.perm, iy * w + ix)
    np.testing.assert_allclose(frame.coords[:, 0], (ix + 0.5) / w)
    np.testing.assert_allclose(frame.coords[:, 1], (iy + 0.5) / h)


def test_morton_order_small_grids_by_hand():
    assert list(zip(*morton_cells(4))) == [(0, 0), (1, 0), (0, 1), (1, 1)]
    # 3 x 2 grid: (2, 1) has the largest code (6) and is dropped for N = 5.
    assert list(zip(*morton_cells(5))) == [(0, 0), (1, 0), (0, 1), (1, 1), (2, 0)]


# ------------------------------------------------------------------- operator

@pytest.mark.parametrize("n, rhs", [(7, "random"), (1000, "random"), (2048, "buoyancy")])
def test_operator_properties(n, rhs):
    A = make_frame(n, seed=4, rhs=rhs).A
    assert A.format == "csr" and A.dtype == np.float64
    assert A.has_sorted_indices
    assert np.all(A.data != 0)
    assert abs(A - A.T).max() == 0
    diag = A.diagonal()
    assert np.all(diag > 0)
    assert np.abs(A @ np.ones(n)).max() <= 1e-10 * diag.max()
    off = A - sp.diags(diag, format="csr")
    assert off.max() <= 0
    # 5-point stencil: at most 4 neighbours per row.
    assert np.diff(A.indptr).max() <= 5


# Hand-chosen densities on a 3 x 3 grid, indexed [iy][ix].
RHO_3X3 = [[1.0, 2.0, 4.0],
           [1.0, 3.0, 1.0],
           [6.0, 1.0, 2.0]]
# Harmonic face weights 2ab/(a+b), computed by hand, keyed by cell pairs (ix, iy).
FACES_3X3 = {
    ((0, 0), (1, 0)): 4 / 3, ((1, 0), (2, 0)): 8 / 3,
    ((0, 1), (1, 1)): 3 / 2, ((1, 1), (2, 1)): 3 / 2,
    ((0, 2), (1, 2)): 12 / 7, ((1, 2), (2, 2)): 4 / 3,
    ((0, 0), (0, 1)): 1.0, ((0, 1), (0, 2)): 12 / 7,
    ((1, 0), (1, 1)): 12 / 5, ((1, 1), (1, 2)): 3 / 2,
    ((2, 0), (2, 1)): 8 / 5, ((2, 1), (2, 2)): 4 / 3,
}


@pytest.mark.parametrize("order", ["morton", "shuffled"])
def test_harmonic_weights_on_3x3_grid(order):
    ix, iy = morton_cells(9)
    if order == "shuffled":
        shuffle = np.random.default_rng(0).permutation(9)
        ix, iy = ix[shuffle], iy[shuffle]
    rho = np.array([RHO_3X3[y][x] for x, y in zip(ix, iy)])
    A = assemble_operator(rho, ix, iy).toarray()
    pos = {(x, y): k for k, (x, y) in enumerate(zip(ix.tolist(), iy.tolist()))}
    expected = np.zeros((9, 9))
    for (c, d), weight in FACES_3X3.items():
        i, j = pos[c], pos[d]
        expected[i, j] = expected[j, i] = -weight
        expected[i, i] += weight
        expected[j, j] += weight
    np.testing.assert_allclose(A, expected, rtol=1e-14, atol=0)
    centre = pos[(1, 1)]
    assert A[centre, centre] == pytest.approx(12 / 5 + 3 / 2 + 3 / 2 + 3 / 2)


def test_operator_without_neighbours_is_zero():
    A = assemble_operator([2.0], [0], [0])
    assert A.shape == (1, 1) and A.nnz == 0


def test_assemble_operator_rejects_bad_input():
    with pytest.raises(ValueError, match="duplicate"):
        assemble_operator([1.0, 1.0], [0, 0], [0, 0])
    with pytest.raises(ValueError, match="rho"):
        assemble_operator([1.0, -1.0], [0, 1], [0, 0])
    with pytest.raises(ValueError, match="non-negative"):
        assemble_operator([1.0, 1.0], [0, -1], [0, 0])


# -------------------------------------------------------------- density, rhs

@pytest.mark.parametrize("orientation, gap, light, heavy", [
    ("vertical", "top", [(0.5, 0.9), (0.7, 0.1)], [(0.5, 0.1), (0.5, 0.7)]),
    ("vertical", "bottom", [(0.5, 0.1)], [(0.5, 0.9), (0.54, 0.5)]),
    ("vertical", "middle_hole", [(0.5, 0.5), (0.5, 0.6)], [(0.5, 0.3), (0.5, 0.9)]),
    ("vertical", "closed", [(0.6, 0.5)], [(0.5, 0.0), (0.5, 0.5), (0.5, 1.0)]),
    ("horizontal", "top", [(0.9, 0.5), (0.1, 0.3)], [(0.1, 0.5), (0.7, 0.5)]),
    ("horizontal", "bottom", [(0.1, 0.5)], [(0.9, 0.5)]),
    ("horizontal", "middle_hole", [(0.5, 0.5)], [(0.2, 0.5), (0.8, 0.5)]),
    ("horizontal", "closed", [(0.5, 0.6)], [(0.0, 0.5), (1.0, 0.5)]),
])
def test_barrier_regions(orientation, gap, light, heavy):
    barrier = {"orientation": orientation, "center": 0.5, "thickness": 0.1, "gap": gap}
    assert not barrier_mask(barrier, np.array(light), gap_width=0.25).any()
    assert barrier_mask(barrier, np.array(heavy), gap_width=0.25).all()


def test_gap_width_is_configurable():
    barrier = {"orientation": "vertical", "center": 0.5, "thickness": 0.1, "gap": "top"}
    point = np.array([[0.5, 0.6]])
    assert barrier_mask(barrier, point, gap_width=0.25).all()
    assert not barrier_mask(barrier, point, gap_width=0.5).any()


def test_density_is_heavy_inside_barriers_with_small_noise():
    frame = make_frame(4096, seed=7)
    p = frame.params
    heavy = np.zeros(frame.n, dtype=bool)
    for barrier in p["barriers"]:
        heavy |= barrier_mask(barrier, frame.coords, p["gap_width"])
    assert heavy.any() and not heavy.all()
    base = np.where(heavy, p["rho_heavy"], 1.0)
    noise = frame.rho / base - 1.0
    assert abs(noise.std() - 0.05) < 0.005 and abs(noise.mean()) < 0.005


def test_buoyancy_rhs_by_hand_2x2():
    ix, iy = morton_cells(4)  # (0,0), (1,0), (0,1), (1,1)
    rho = np.array([1.0, 2.0, 5.0, 3.0])
    # One-sided d(rho)/dy is 4 in column 0 and 1 in column 1; -slope minus its mean.
    np.testing.assert_allclose(buoyancy_rhs(rho, ix, iy), [-1.5, 1.5, -1.5, 1.5])


def test_buoyancy_rhs_by_hand_3x3():
    ix, iy = morton_cells(9)
    rho = 1.0 + iy**2 + ix
    # d(rho)/dy: one-sided 1 at iy=0, central (4-0)/2 = 2 at iy=1, one-sided 3 at iy=2.
    np.testing.assert_allclose(buoyancy_rhs(rho, ix, iy), 2.0 - np.array([1, 2, 3])[iy],
                               atol=1e-15)


def test_buoyancy_rhs_without_vertical_neighbours_is_zero():
    np.testing.assert_array_equal(make_frame(2, rhs="buoyancy").b, [0.0, 0.0])


@pytest.mark.parametrize("rhs", ["random", "buoyancy"])
def test_rhs_has_mean_zero(rhs):
    frame = make_frame(1000, seed=3, rhs=rhs)
    assert abs(frame.b.mean()) < 1e-14 * max(1.0, np.abs(frame.b).max())
    assert np.abs(frame.b).max() > 0
    if rhs == "buoyancy":
        ix, iy = frame.perm % frame.grid_shape[0], frame.perm // frame.grid_shape[0]
        np.testing.assert_array_equal(frame.b, buoyancy_rhs(frame.rho, ix, iy))


# -------------------------------------------------------- seeds, distributions

def test_same_seed_is_bit_identical_and_seeds_differ():
    f = make_frame(300, seed=11, distribution="no_closed", rhs="buoyancy")
    assert_frames_identical(f, make_frame(300, seed=11, distribution="no_closed",
                                          rhs="buoyancy"))
    g = make_frame(300, seed=12, distribution="no_closed", rhs="buoyancy")
    assert not np.array_equal(f.rho, g.rho)
    assert not np.array_equal(f.A.data, g.A.data)
    assert f.params != g.params


def test_params_reproduce_frame():
    f = make_frame(64, seed=3, contrast=(2.0, 8.0), rhs="buoyancy", gap_width=0.3)
    keys = ("n", "seed", "distribution", "contrast", "rhs", "gap_width")
    assert_frames_identical(f, make_frame(**{k: f.params[k] for k in keys}))
    assert 2.0 <= f.params["rho_heavy"] <= 8.0


def test_train_and_test_seeds_are_disjoint():
    train, test = dataset_seeds("train", 1000), dataset_seeds("test", 1000)
    np.testing.assert_array_equal(train, np.arange(1000))
    np.testing.assert_array_equal(test, 1_000_000 + np.arange(1000))
    assert not set(train.tolist()) & set(test.tolist())
    assert dataset_seeds("train", 1_000_000).max() < dataset_seeds("test", 1).min()
    with pytest.raises(ValueError, match="split"):
        dataset_seeds("validation", 3)
    with pytest.raises(ValueError, match="count"):
        dataset_seeds("train", 0)


@pytest.mark.parametrize("name", sorted(DISTRIBUTIONS))
def test_distribution_ranges_and_topologies(name):
    dist = DISTRIBUTIONS[name]
    lo, hi = dist.contrast
    rng = np.random.default_rng(2024)
    draws = [sample_params(rng, name) for _ in range(300)]
    rho = np.array([d["rho_heavy"] for d in draws])
    barriers = [b for d in draws for b in d["barriers"]]
    assert np.all(rho <= hi)
    assert np.all(rho > lo) if dist.open_low else np.all(rho >= lo)
    # loguniform: the median of log(rho) is near the middle of the log range
    assert abs(np.median(np.log(rho)) - 0.5 * np.log(lo * hi)) < 0.2 * np.log(hi / lo)
    assert {b["gap"] for b in barriers} == set(dist.topologies)
    assert {len(d["barriers"]) for d in draws} == {1, 2, 3}
    assert {b["orientation"] for b in barriers} == {"vertical", "horizontal"}
    assert all(0.2 <= b["center"] <= 0.8 for b in barriers)
    assert all(0.05 <= b["thickness"] <= 0.20 for b in barriers)


def test_named_distributions_match_the_supplement():
    all_four = {"top", "bottom", "middle_hole", "closed"}
    expected = {
        "full": ((5, 100), all_four, False),
        "no_closed": ((5, 100), all_four - {"closed"}, False),
        "closed_only": ((5, 100), {"closed"}, False),
        "low_contrast": ((5, 25), all_four, False),
        "high_contrast": ((25, 100), all_four, True),
        "no_closed_low_contrast": ((5, 25), all_four - {"closed"}, False),
    }
    got = {k: (d.contrast, set(d.topologies), d.open_low) for k, d in DISTRIBUTIONS.items()}
    assert got == expected


class LowEndGenerator:
    """Stand-in Generator whose first uniform draw is the lower bound."""

    def __init__(self):
        self.uniform_calls = 0

    def uniform(self, low, high):
        self.uniform_calls += 1
        return low if self.uniform_calls == 1 else 0.5 * (low + high)

    def integers(self, low, high=None):
        return 0 if high is None else low


@pytest.mark.parametrize("name, expected", [("full", 5.0), ("high_contrast", 50.0)])
def test_low_contrast_endpoint_is_open_only_for_high_contrast(name, expected):
    rho_heavy = sample_params(LowEndGenerator(), name)["rho_heavy"]
    assert rho_heavy == pytest.approx(expected, rel=1e-12)
    assert rho_heavy >= 5.0 if name == "full" else rho_heavy > 25.0


def test_contrast_override():
    rng = np.random.default_rng(0)
    rho = [sample_params(rng, "high_contrast", (1.0, 2.0))["rho_heavy"] for _ in range(200)]
    assert min(rho) >= 1.0 and max(rho) <= 2.0


# -------------------------------------------------------------------- dataset

def test_dataset_cache_round_trip(tmp_path):
    frames = load_dataset(64, "train", count=3, cache_dir=tmp_path)
    files = list(tmp_path.iterdir())
    assert len(files) == 1 and files[0].suffix == ".npz"
    for seed, frame in enumerate(frames):
        assert_frames_identical(frame, make_frame(64, seed=seed))
    stamp = files[0].stat().st_mtime_ns
    again = load_dataset(64, "train", count=3, cache_dir=tmp_path)
    assert files[0].stat().st_mtime_ns == stamp
    for f, g in zip(frames, again):
        assert_frames_identical(f, g)


def test_dataset_defaults_and_env_cache_dir(tmp_path, monkeypatch):
    monkeypatch.setenv("PETSC_HTP_CACHE", str(tmp_path / "env"))
    frames = load_dataset(16, "test", distribution="closed_only")
    assert len(frames) == 20
    assert [f.params["seed"] for f in frames] == list(range(1_000_000, 1_000_020))
    assert all(b["gap"] == "closed" for f in frames for b in f.params["barriers"])
    assert len(list((tmp_path / "env").glob("*.npz"))) == 1


def test_dataset_regenerates_corrupt_or_stale_file(tmp_path):
    frames = load_dataset(32, "test", count=2, cache_dir=tmp_path)
    (path,) = tmp_path.iterdir()
    path.write_bytes(b"not an npz file")
    for f, g in zip(frames, load_dataset(32, "test", count=2, cache_dir=tmp_path)):
        assert_frames_identical(f, g)
    with np.load(path) as stored:
        arrays = dict(stored)
    assert arrays["version"].item() == GENERATOR_VERSION
    arrays["version"] = np.array("stale")
    arrays["data"] = np.zeros_like(arrays["data"])
    np.savez(path, **arrays)
    for f, g in zip(frames, load_dataset(32, "test", count=2, cache_dir=tmp_path)):
        assert_frames_identical(f, g)
    assert [p.name for p in tmp_path.iterdir()] == [path.name]


def test_load_dataset_rejects_bad_split(tmp_path):
    with pytest.raises(ValueError, match="split"):
        load_dataset(16, "val", cache_dir=tmp_path)


# ---------------------------------------------------------------- validation

@pytest.mark.parametrize("kwargs, match", [
    ({"n": 0}, "n must be a positive integer"),
    ({"n": -5}, "n must be a positive integer"),
    ({"n": 2.5}, "n must be a positive integer"),
    ({"n": 16, "contrast": (50.0, 10.0)}, "contrast range"),
    ({"n": 16, "contrast": (10.0, 10.0)}, "contrast range"),
    ({"n": 16, "contrast": (0.5, 10.0)}, "contrast range"),
    ({"n": 16, "distribution": "medium"}, "unknown distribution 'medium'.*full"),
    ({"n": 16, "rhs": "gravity"}, "unknown rhs"),
    ({"n": 16, "seed": -1}, "seed"),
    ({"n": 16, "gap_width": 1.5}, "gap_width"),
])
def test_make_frame_rejects_bad_arguments(kwargs, match):
    with pytest.raises(ValueError, match=match):
        make_frame(**kwargs)


# ------------------------------------------------------------------- reports

def test_frame_summary_mentions_key_facts():
    frame = make_frame(100, seed=2)
    text = frame_summary(frame)
    assert "N=100" in text and "grid=10x10" in text
    assert f"nnz={frame.A.nnz}" in text
    assert f"barriers ({len(frame.params['barriers'])})" in text


@pytest.mark.parametrize("n, with_pressure", [(256, False), (256, True), (2, True)])
def test_plot_frame_writes_png(tmp_path, n, with_pressure):
    frame = make_frame(n, seed=1)
    pressure = frame.coords[:, 1].copy() if with_pressure else None
    path = tmp_path / "sub" / "frame.png"
    plot_frame(frame, path, pressure=pressure)
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert [p.name for p in path.parent.iterdir()] == ["frame.png"]


def test_to_image_places_cells_and_marks_missing():
    frame = make_frame(5)
    image = frame.to_image(np.arange(5.0))
    assert image.shape == (2, 3)
    np.testing.assert_array_equal(image[0], [0.0, 1.0, 4.0])
    np.testing.assert_array_equal(image[1, :2], [2.0, 3.0])
    assert np.isnan(image[1, 2])


# ------------------------------------------------------------------------ 3-D

@pytest.mark.parametrize("n, dims", [(1, (1, 1, 1)), (8, (2, 2, 2)), (9, (3, 3, 1)), (1000, (10, 10, 10)),
                                     (3000, (15, 15, 14)), (32768, (32, 32, 32))])
def test_3d_frames_are_near_cubic_boxes_with_the_7_point_operator(n, dims):
    frame = make_frame(n, seed=2, dim=3)
    assert grid_dims(n, 3) == frame.grid_shape == dims and frame.dim == 3
    assert frame.coords.shape == (n, 3) and frame.n == n
    A = frame.A
    assert abs(A - A.T).max() == 0 and np.abs(A @ np.ones(n)).max() <= 1e-12 * A.diagonal().max()
    assert np.diff(A.indptr).max() <= 7 and np.all(A.diagonal() >= 0)
    if n == 32768:                                          # the interior rows have all 6 neighbours
        assert np.count_nonzero(np.diff(A.indptr) == 7) == 30 ** 3
    assert len(np.unique(frame.perm)) == n and frame.perm.max() < np.prod(dims)
    assert frame.to_image(frame.rho).shape == dims[::-1]
    assert abs(frame.b.mean()) < 1e-12


def test_3d_cells_come_in_octree_order():
    ix, iy, iz = morton_cells(512, dim=3)
    for block in np.arange(512).reshape(64, 8):             # each run of 8 cells is a 2 x 2 x 2 octant
        assert all(np.ptp(axis[block]) == 1 for axis in (ix, iy, iz))
    for block in np.arange(512).reshape(8, 64):             # each run of 64 a 4 x 4 x 4 one
        assert all(np.ptp(axis[block]) == 3 for axis in (ix, iy, iz))


@pytest.mark.parametrize("normal, gap", [("x", "top"), ("y", "bottom"), ("z", "middle_hole"), ("x", "closed")])
def test_3d_slabs_leave_the_same_open_fraction_as_2d_gaps(normal, gap):
    side = 40
    iz, iy, ix = np.unravel_index(np.arange(side ** 3), (side,) * 3)
    coords = (np.column_stack([ix, iy, iz]) + 0.5) / side
    slab = {"orientation": normal, "center": 0.5, "thickness": 0.2, "gap": gap}
    mask = barrier_mask(slab, coords, gap_width=0.25)
    axis = "xyz".index(normal)
    band = np.abs(coords[:, axis] - 0.5) <= 0.1
    assert not mask[~band].any()
    open_fraction = 1 - mask[band].mean()
    assert open_fraction == pytest.approx(0.0 if gap == "closed" else 0.25, abs=0.03)
    if gap == "top":                                        # the gap is at the top (z), along the whole slab
        assert not mask[band & (coords[:, 2] > 0.8)].any() and mask[band & (coords[:, 2] < 0.7)].all()


def test_3d_buoyancy_rhs_is_minus_d_rho_dz():
    rho = np.array([1.0, 1.0, 1.0, 1.0, 3.0, 3.0, 3.0, 3.0])            # heavy top layer of a 2 x 2 x 2 box
    ix, iy, iz = np.array([0, 1, 0, 1, 0, 1, 0, 1]), np.array([0, 0, 1, 1, 0, 0, 1, 1]), np.repeat([0, 1], 4)
    np.testing.assert_allclose(buoyancy_rhs(rho, ix, iy, iz), np.zeros(8))   # -2 everywhere, mean removed
    rho[4] = 5.0
    b = buoyancy_rhs(rho, ix, iy, iz)
    assert b[0] < b[1] and b[4] < b[5] and abs(b.sum()) < 1e-12


def test_3d_samples_slabs_and_keeps_2d_frames(tmp_path):
    scene = sample_params(np.random.default_rng(0), dim=3)
    assert all(b["orientation"] in ("x", "y", "z") for b in scene["barriers"])
    frames = load_dataset(1000, "test", count=2, cache_dir=tmp_path, dim=3)
    assert [f.params["dim"] for f in frames] == [3, 3] and frames[0].grid_shape == (10, 10, 10)
    assert_frames_identical(load_dataset(1000, "test", count=2, cache_dir=tmp_path, dim=3)[1], frames[1])
    flat = load_dataset(1000, "test", count=2, cache_dir=tmp_path)
    assert flat[0].grid_shape == (32, 32) and "dim" not in flat[0].params
    assert sorted(p.name for p in tmp_path.iterdir()) == ["multiphase3d_n1000_test_full_c2.npz",
                                                          "multiphase_n1000_test_full_c2.npz"]
    with pytest.raises(ValueError, match="dim must be 2 or 3"):
        make_frame(100, dim=4)


def test_3d_picture_shows_slices_and_a_projection(tmp_path):
    frame = make_frame(4096, seed=1, dim=3)
    plot_frame(frame, tmp_path / "f.png", pressure=frame.b)
    assert (tmp_path / "f.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert "grid=16x16x16" in frame_summary(frame)


@pytest.mark.slow
def test_scene_cli_dim_3(tmp_path):
    import subprocess
    import sys

    out = subprocess.run([sys.executable, "-m", "petsc_htp.cli", "scene", "-n", "1000", "--dim", "3", "--out",
                          str(tmp_path / "s")], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert "grid=10x10x10" in out.stdout and (tmp_path / "s.png").exists() and (tmp_path / "s.npz").exists()
