"""Multiphase Poisson benchmark generator, in 2-D and 3-D.

Implements the scene generator of the paper supplement ("Multiphase Poisson
Benchmark Generation"): cell-centred grids in Morton order, light fluid with
heavy barriers, a harmonic-mean 5-point Laplacian with zero-flux boundaries.
``dim=3`` carries the design over: near-cubic boxes in octree (3-D Morton)
order, the 7-point Laplacian, and heavy slabs normal to x, y or z whose gaps
(top, bottom, a middle hole, closed) leave the same fraction of the slab open.
Cached datasets are in :mod:`petsc_htp.scenes.dataset`, pictures in
:mod:`petsc_htp.scenes.plot`, PETSc Mat/Vec copies in :mod:`petsc_htp.petscmat`.
"""
import math
import numbers
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
import scipy.sparse as sp

from ..morton import morton_code

GENERATOR_VERSION = "multiphase-poisson-1"
TOPOLOGIES = ("top", "bottom", "middle_hole", "closed")
ORIENTATIONS = ("vertical", "horizontal")
NORMALS = ("x", "y", "z")        # 3-D slabs: the axis a slab is normal to
DIMS = (2, 3)
RHS_KINDS = ("random", "buoyancy")
DENSITY_NOISE = 0.05


class Distribution(NamedTuple):
    """Scene distribution: contrast range, gap topologies, open low end."""

    contrast: tuple
    topologies: tuple
    open_low: bool


DISTRIBUTIONS = {
    "full": Distribution((5.0, 100.0), TOPOLOGIES, False),
    "no_closed": Distribution((5.0, 100.0), TOPOLOGIES[:3], False),
    "closed_only": Distribution((5.0, 100.0), ("closed",), False),
    "low_contrast": Distribution((5.0, 25.0), TOPOLOGIES, False),
    "high_contrast": Distribution((25.0, 100.0), TOPOLOGIES, True),
    "no_closed_low_contrast": Distribution((5.0, 25.0), TOPOLOGIES[:3], False),
}


# ----------------------------------------------------------------- validation

def check_positive_int(value, name):
    """Return ``value`` as an int, or raise ValueError naming ``name``."""
    if isinstance(value, bool) or not isinstance(value, numbers.Integral) or value <= 0:
        raise ValueError(f"{name} must be a positive integer, got {value!r}")
    return int(value)


def _check_seed(seed):
    """Return ``seed`` as a non-negative int, or raise ValueError."""
    if isinstance(seed, bool) or not isinstance(seed, numbers.Integral) or seed < 0:
        raise ValueError(f"seed must be a non-negative integer, got {seed!r}")
    return int(seed)


def check_distribution(name):
    """Return the :class:`Distribution` called ``name``, or raise ValueError."""
    if name not in DISTRIBUTIONS:
        known = ", ".join(DISTRIBUTIONS)
        raise ValueError(f"unknown distribution {name!r}; known distributions: {known}")
    return DISTRIBUTIONS[name]


def contrast_range(distribution="full", contrast=None):
    """Heavy-density sampling range of a distribution.

    Parameters
    ----------
    distribution : str
        Name in :data:`DISTRIBUTIONS`.
    contrast : (float, float), optional
        Closed range ``(lo, hi)`` with ``1 <= lo < hi`` overriding the
        distribution's range.

    Returns
    -------
    tuple
        ``(lo, hi, open_low)``.
    """
    dist = check_distribution(distribution)
    if contrast is None:
        return (*dist.contrast, dist.open_low)
    bounds = np.asarray(contrast, dtype=np.float64)
    if bounds.shape != (2,) or not np.all(np.isfinite(bounds)):
        raise ValueError(f"contrast range must be a finite pair (lo, hi), got {contrast!r}")
    lo, hi = float(bounds[0]), float(bounds[1])
    if lo < 1.0 or lo >= hi:
        raise ValueError(f"contrast range must satisfy 1 <= lo < hi, got ({lo}, {hi})")
    return lo, hi, False


# ----------------------------------------------------------------------- grid

def check_dim(dim):
    """Return ``dim`` (2 or 3), or raise ValueError."""
    if dim not in DIMS:
        raise ValueError(f"dim must be 2 or 3, got {dim!r}")
    return int(dim)


def grid_dims(n, dim=2):
    """Closest-to-square grid ``(W, H)`` with ``W * H >= n``, or closest-to-cubic ``(W, H, D)`` in 3-D.

    2-D: ``W = ceil(sqrt(n))``, ``H = ceil(n / W)``; 3-D: ``W = H = ceil(cbrt(n))``, ``D = ceil(n / W^2)``.
    """
    n = check_positive_int(n, "n")
    if check_dim(dim) == 2:
        w = math.isqrt(n)
        if w * w < n:
            w += 1
        return w, -(-n // w)
    w = round(n ** (1 / 3))
    while w ** 3 < n:
        w += 1
    while w > 1 and (w - 1) ** 3 >= n:
        w -= 1
    return w, w, -(-n // (w * w))


def row_major(idx, shape) -> np.ndarray:
    """Row-major position ``ix + W (iy + H iz)`` of cells with indices ``idx`` in a grid of ``shape``."""
    pos = np.zeros_like(idx[0])
    for axis in reversed(range(len(idx))):
        pos = pos * shape[axis] + idx[axis]
    return pos


def morton_cells(n, dim=2):
    """Grid indices of the first ``n`` cells of the :func:`grid_dims` grid in Morton (octree in 3-D) order.

    Returns
    -------
    ix, iy[, iz] : numpy.ndarray of int64, shape (n,)
    """
    shape = grid_dims(n, dim)
    idx = np.unravel_index(np.arange(math.prod(shape), dtype=np.int64), shape[::-1])[::-1]
    order = np.argsort(morton_code(*idx), kind="stable")[:n]
    return tuple(np.asarray(i[order], dtype=np.int64) for i in idx)


def _cell_lookup(*idx):
    """Validated cell indices plus a row-major grid index -> position map and the grid's shape."""
    idx = tuple(np.asarray(i, dtype=np.int64) for i in idx)
    names = ", ".join(("ix", "iy", "iz")[:len(idx)])
    if any(i.ndim != 1 or i.shape != idx[0].shape for i in idx) or idx[0].size == 0:
        raise ValueError(f"{names} must be non-empty 1-D arrays of equal length")
    if min(int(i.min()) for i in idx) < 0:
        raise ValueError(f"cell indices {names} must be non-negative")
    shape = tuple(int(i.max()) + 1 for i in idx)
    lookup = np.full(math.prod(shape), -1, dtype=np.int64)
    lookup[row_major(idx, shape)] = np.arange(idx[0].size)
    if np.count_nonzero(lookup >= 0) != idx[0].size:
        raise ValueError(f"cell indices ({names}) contain duplicate cells")
    return idx, lookup, shape


def _neighbour(idx, lookup, shape, axis, step):
    """Position of each cell's neighbour ``step`` cells along ``axis``, -1 where absent."""
    moved = list(idx)
    moved[axis] = idx[axis] + step
    inside = (moved[axis] >= 0) & (moved[axis] < shape[axis])
    moved[axis] = np.where(inside, moved[axis], 0)
    return np.where(inside, lookup[row_major(moved, shape)], -1)


def _check_density(rho, n):
    """Return ``rho`` as a positive float array of length ``n``."""
    rho = np.asarray(rho, dtype=np.float64)
    if rho.shape != (n,):
        raise ValueError(f"rho must have shape ({n},), got {rho.shape}")
    if not np.all(np.isfinite(rho) & (rho > 0)):
        raise ValueError("rho must be finite and positive")
    return rho


# -------------------------------------------------------------------- density

def _loguniform(rng, lo, hi, open_low):
    """Draw from loguniform[lo, hi], redrawing ``lo`` itself when ``open_low``."""
    while True:
        value = float(np.clip(np.exp(rng.uniform(np.log(lo), np.log(hi))), lo, hi))
        if value > lo or not open_low:
            return value


def _sample_barrier(rng, topologies, dim=2):
    """Draw one barrier: orientation (2-D) or normal axis (3-D), centre, thickness and gap topology."""
    return {
        "orientation": ORIENTATIONS[rng.integers(2)] if dim == 2 else NORMALS[rng.integers(3)],
        "center": float(rng.uniform(0.2, 0.8)),
        "thickness": float(rng.uniform(0.05, 0.20)),
        "gap": topologies[rng.integers(len(topologies))],
    }


def sample_params(rng, distribution="full", contrast=None, dim=2):
    """Draw the heavy density and 1-3 barriers of one scene.

    Parameters
    ----------
    rng : numpy.random.Generator
    distribution : str
        Name in :data:`DISTRIBUTIONS`.
    contrast : (float, float), optional
        Overrides the distribution's contrast range.
    dim : int
        2 (barriers 'vertical' or 'horizontal') or 3 (slabs normal to 'x', 'y' or 'z').

    Returns
    -------
    dict
        ``rho_heavy`` (float) and ``barriers`` (list of dicts with
        ``orientation``, ``center``, ``thickness``, ``gap``).
    """
    lo, hi, open_low = contrast_range(distribution, contrast)
    topologies = DISTRIBUTIONS[distribution].topologies
    rho_heavy = _loguniform(rng, lo, hi, open_low)
    count = int(rng.integers(1, 4))
    barriers = [_sample_barrier(rng, topologies, check_dim(dim)) for _ in range(count)]
    return {"rho_heavy": rho_heavy, "barriers": barriers}


def _gap_mask(gap, along, gap_width):
    """Cells of a barrier's along-axis coordinate that fall in its gap."""
    if gap == "top":
        return along >= 1.0 - gap_width
    if gap == "bottom":
        return along <= gap_width
    if gap == "middle_hole":
        return np.abs(along - 0.5) <= gap_width / 2
    if gap == "closed":
        return np.zeros(along.shape, dtype=bool)
    raise ValueError(f"unknown gap topology {gap!r}; known: {', '.join(TOPOLOGIES)}")


def _slab_gap(gap, u, v, gap_width):
    """A 3-D slab's gap over its in-plane coordinates ``u`` (up for top/bottom) and ``v``: the same open
    fraction ``g`` of the slab as a 2-D gap (a full-width strip, or a square hole of side sqrt(g))."""
    if gap == "middle_hole":
        half = math.sqrt(gap_width) / 2
        return (np.abs(u - 0.5) <= half) & (np.abs(v - 0.5) <= half)
    return _gap_mask(gap, u, gap_width)


def barrier_mask(barrier, coords, gap_width=0.25):
    """Boolean mask of the cells inside a barrier's heavy region.

    Parameters
    ----------
    barrier : dict
        ``orientation``, ``center``, ``thickness`` and ``gap``.
    coords : numpy.ndarray, shape (N, 2) or (N, 3)
        Normalised cell centres.
    gap_width : float
        Gap width ``g`` (3-D: the open fraction of the slab).
    """
    if coords.shape[1] == 3:
        if barrier["orientation"] not in NORMALS:
            raise ValueError(f"unknown slab normal {barrier['orientation']!r}; known: {', '.join(NORMALS)}")
        normal = NORMALS.index(barrier["orientation"])
        u_axis = 2 if normal != 2 else 0                       # 'up' is z unless the slab lies flat
        v_axis = 3 - normal - u_axis
        in_band = np.abs(coords[:, normal] - barrier["center"]) <= barrier["thickness"] / 2
        return in_band & ~_slab_gap(barrier["gap"], coords[:, u_axis], coords[:, v_axis], gap_width)
    if barrier["orientation"] not in ORIENTATIONS:
        raise ValueError(f"unknown barrier orientation {barrier['orientation']!r}")
    x, y = coords[:, 0], coords[:, 1]
    cross, along = (x, y) if barrier["orientation"] == "vertical" else (y, x)
    in_band = np.abs(cross - barrier["center"]) <= barrier["thickness"] / 2
    return in_band & ~_gap_mask(barrier["gap"], along, gap_width)


def barrier_density(coords, rho_heavy, barriers, gap_width=0.25):
    """Noise-free density: ``rho_heavy`` in any barrier, 1 elsewhere."""
    heavy = np.zeros(len(coords), dtype=bool)
    for barrier in barriers:
        heavy |= barrier_mask(barrier, coords, gap_width)
    return np.where(heavy, rho_heavy, 1.0)


# ------------------------------------------------------------------- operator

def assemble_operator(rho, *idx):
    """Variable-coefficient 5-point (2-D) or 7-point (3-D) Laplacian with zero-flux boundaries.

    Parameters
    ----------
    rho : array_like, shape (N,)
        Positive cell densities.
    ix, iy[, iz] : array_like of int, shape (N,)
        Distinct grid indices of the cells; rows follow this order.

    Returns
    -------
    scipy.sparse.csr_matrix
        ``A_ij = -w_ij`` for face neighbours with ``w_ij = 2 rho_i rho_j /
        (rho_i + rho_j)``, ``A_ii = sum_j w_ij``; sorted indices, no
        explicit zeros.
    """
    idx, lookup, shape = _cell_lookup(*idx)
    n = idx[0].size
    rho = _check_density(rho, n)
    rows, cols = [], []
    for axis in range(len(idx)):
        nbr = _neighbour(idx, lookup, shape, axis, 1)
        present = np.flatnonzero(nbr >= 0)
        rows.append(present)
        cols.append(nbr[present])
    i, j = np.concatenate(rows), np.concatenate(cols)
    weight = 2.0 * rho[i] * rho[j] / (rho[i] + rho[j])
    diag = np.bincount(i, weight, n) + np.bincount(j, weight, n)
    cells = np.arange(n)
    A = sp.coo_matrix(
        (np.concatenate([-weight, -weight, diag]),
         (np.concatenate([i, j, cells]), np.concatenate([j, i, cells]))),
        shape=(n, n),
    ).tocsr()
    A.eliminate_zeros()
    A.sort_indices()
    return A


def buoyancy_rhs(rho, *idx):
    """Right-hand side ``-d(rho)/dy`` (``-d(rho)/dz`` in 3-D: the last axis is up) projected to mean zero.

    Central differences in grid-index units, one-sided where a vertical
    neighbour is absent, zero where both are.
    """
    idx, lookup, shape = _cell_lookup(*idx)
    rho = _check_density(rho, idx[0].size)
    up = _neighbour(idx, lookup, shape, len(idx) - 1, 1)
    down = _neighbour(idx, lookup, shape, len(idx) - 1, -1)
    upper = np.where(up >= 0, rho[up], rho)
    lower = np.where(down >= 0, rho[down], rho)
    steps = (up >= 0).astype(np.float64) + (down >= 0)
    slope = np.divide(upper - lower, steps, out=np.zeros_like(rho), where=steps > 0)
    return _mean_zero(-slope)


def _mean_zero(b):
    """Project ``b`` onto the complement of the constant vector."""
    return b - b.mean()


# ---------------------------------------------------------------------- frame

@dataclass(eq=False)
class Frame:
    """One benchmark problem ``A p = b`` in Morton order.

    Attributes
    ----------
    A : scipy.sparse.csr_matrix
        Symmetric positive semidefinite operator with ``A @ 1 = 0``.
    b : numpy.ndarray
        Mean-zero right-hand side.
    rho : numpy.ndarray
        Cell densities.
    coords : numpy.ndarray, shape (N, 2) or (N, 3)
        Normalised cell centres.
    grid_shape : tuple
        ``(W, H)`` or ``(W, H, D)``.
    perm : numpy.ndarray of int64
        Row-major cell index ``iy * W + ix`` (3-D: ``(iz * H + iy) * W + ix``) of each row.
    params : dict
        Generator inputs and sampled scene parameters.
    """

    A: sp.csr_matrix
    b: np.ndarray
    rho: np.ndarray
    coords: np.ndarray
    grid_shape: tuple
    perm: np.ndarray
    params: dict

    @property
    def n(self):
        """Number of unknowns."""
        return self.A.shape[0]

    @property
    def dim(self):
        """2 or 3."""
        return len(self.grid_shape)

    def to_image(self, values):
        """Map Morton-ordered ``values`` to an ``(H, W)`` image (3-D: a ``(D, H, W)`` volume), NaN where absent."""
        values = np.asarray(values, dtype=np.float64)
        if values.shape != (self.n,):
            raise ValueError(f"values must have shape ({self.n},), got {values.shape}")
        image = np.full(math.prod(self.grid_shape), np.nan)
        image[self.perm] = values
        return image.reshape(self.grid_shape[::-1])


def _make_rhs(kind, rng, rho, idx):
    """Right-hand side of the requested kind."""
    if kind == "random":
        return _mean_zero(rng.standard_normal(rho.size))
    return buoyancy_rhs(rho, *idx)


def make_frame(n, seed=0, distribution="full", contrast=None, rhs="random",
               gap_width=0.25, dim=2):
    """Generate one multiphase Poisson problem.

    Parameters
    ----------
    n : int
        Number of cells (>= 1).
    seed : int
        Non-negative seed; the frame is a deterministic function of all
        arguments.
    distribution : str
        Name in :data:`DISTRIBUTIONS`.
    contrast : (float, float), optional
        Heavy-density range overriding the distribution's.
    rhs : {'random', 'buoyancy'}
        Right-hand-side kind.
    gap_width : float
        Barrier gap width in ``[0, 1]`` (3-D: the open fraction of a slab).
    dim : int
        2 (the paper's scenes) or 3 (near-cubic boxes, 7-point operator, slabs).

    Returns
    -------
    Frame
    """
    n = check_positive_int(n, "n")
    seed = _check_seed(seed)
    dim = check_dim(dim)
    if rhs not in RHS_KINDS:
        raise ValueError(f"unknown rhs {rhs!r}; expected one of {', '.join(RHS_KINDS)}")
    if not 0.0 <= gap_width <= 1.0:
        raise ValueError(f"gap_width must lie in [0, 1], got {gap_width!r}")
    rng = np.random.default_rng(np.random.SeedSequence(seed))
    scene = sample_params(rng, distribution, contrast, dim)
    shape = grid_dims(n, dim)
    idx = morton_cells(n, dim)
    coords = np.column_stack([(i + 0.5) / s for i, s in zip(idx, shape)])
    rho = barrier_density(coords, scene["rho_heavy"], scene["barriers"], gap_width)
    rho *= 1.0 + rng.normal(0.0, DENSITY_NOISE, n)
    params = {
        "n": n, "seed": seed, "distribution": distribution,
        "contrast": None if contrast is None else [float(c) for c in contrast],
        "rho_heavy": scene["rho_heavy"], "gap_width": float(gap_width),
        "rhs": rhs, "barriers": scene["barriers"],
    }
    if dim == 3:
        params["dim"] = 3
    return Frame(
        A=assemble_operator(rho, *idx),
        b=_make_rhs(rhs, rng, rho, idx),
        rho=rho,
        coords=coords,
        grid_shape=shape,
        perm=row_major(idx, shape),
        params=params,
    )


# ------------------------------------------------------------------- reports

def frame_summary(frame):
    """A few human-readable lines describing a frame."""
    p = frame.params
    diag = frame.A.diagonal()
    barriers = "; ".join(
        f"{b['orientation']} c={b['center']:.3f} t={b['thickness']:.3f} gap={b['gap']}"
        for b in p["barriers"]
    )
    return "\n".join([
        f"N={frame.n} grid={'x'.join(map(str, frame.grid_shape))} distribution={p['distribution']} "
        f"seed={p['seed']} rhs={p['rhs']}",
        f"rho_heavy={p['rho_heavy']:.4g} rho range=[{frame.rho.min():.4g}, "
        f"{frame.rho.max():.4g}]",
        f"barriers ({len(p['barriers'])}): {barriers}",
        f"nnz={frame.A.nnz} diag range=[{diag.min():.4g}, {diag.max():.4g}]",
    ])
