"""Multiphase Poisson benchmark generator.

Implements the scene generator of the paper supplement ("Multiphase Poisson
Benchmark Generation"): cell-centred grids in Morton order, light fluid with
heavy barriers, a harmonic-mean 5-point Laplacian with zero-flux boundaries.
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

def _check_positive_int(value, name):
    """Return ``value`` as an int, or raise ValueError naming ``name``."""
    if isinstance(value, bool) or not isinstance(value, numbers.Integral) or value <= 0:
        raise ValueError(f"{name} must be a positive integer, got {value!r}")
    return int(value)


def _check_seed(seed):
    """Return ``seed`` as a non-negative int, or raise ValueError."""
    if isinstance(seed, bool) or not isinstance(seed, numbers.Integral) or seed < 0:
        raise ValueError(f"seed must be a non-negative integer, got {seed!r}")
    return int(seed)


def _check_distribution(name):
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
    dist = _check_distribution(distribution)
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

def grid_dims(n):
    """Closest-to-square grid ``(W, H)`` with ``W * H >= n``.

    ``W = ceil(sqrt(n))`` and ``H = ceil(n / W)``.
    """
    n = _check_positive_int(n, "n")
    w = math.isqrt(n)
    if w * w < n:
        w += 1
    return w, -(-n // w)


def morton_cells(n):
    """Grid indices of the first ``n`` cells of the ``W x H`` grid in Morton order.

    Returns
    -------
    ix, iy : numpy.ndarray of int64, shape (n,)
    """
    w, h = grid_dims(n)
    iy, ix = np.divmod(np.arange(w * h, dtype=np.int64), w)
    order = np.argsort(morton_code(ix, iy), kind="stable")[:n]
    return ix[order], iy[order]


def _cell_lookup(ix, iy):
    """Validated cell indices plus a row-major ``(W, H)`` index -> position map."""
    ix = np.asarray(ix, dtype=np.int64)
    iy = np.asarray(iy, dtype=np.int64)
    if ix.ndim != 1 or ix.shape != iy.shape or ix.size == 0:
        raise ValueError("ix and iy must be non-empty 1-D arrays of equal length")
    if ix.min() < 0 or iy.min() < 0:
        raise ValueError("cell indices ix, iy must be non-negative")
    w, h = int(ix.max()) + 1, int(iy.max()) + 1
    lookup = np.full(w * h, -1, dtype=np.int64)
    lookup[iy * w + ix] = np.arange(ix.size)
    if np.count_nonzero(lookup >= 0) != ix.size:
        raise ValueError("cell indices (ix, iy) contain duplicate cells")
    return ix, iy, lookup, (w, h)


def _neighbour(ix, iy, lookup, dims, dx, dy):
    """Position of each cell's ``(dx, dy)`` neighbour, -1 where absent."""
    w, h = dims
    jx, jy = ix + dx, iy + dy
    inside = (jx >= 0) & (jx < w) & (jy >= 0) & (jy < h)
    return np.where(inside, lookup[np.where(inside, jy * w + jx, 0)], -1)


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


def _sample_barrier(rng, topologies):
    """Draw one barrier: orientation, centre, thickness and gap topology."""
    return {
        "orientation": ORIENTATIONS[rng.integers(2)],
        "center": float(rng.uniform(0.2, 0.8)),
        "thickness": float(rng.uniform(0.05, 0.20)),
        "gap": topologies[rng.integers(len(topologies))],
    }


def sample_params(rng, distribution="full", contrast=None):
    """Draw the heavy density and 1-3 barriers of one scene.

    Parameters
    ----------
    rng : numpy.random.Generator
    distribution : str
        Name in :data:`DISTRIBUTIONS`.
    contrast : (float, float), optional
        Overrides the distribution's contrast range.

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
    barriers = [_sample_barrier(rng, topologies) for _ in range(count)]
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


def barrier_mask(barrier, coords, gap_width=0.25):
    """Boolean mask of the cells inside a barrier's heavy region.

    Parameters
    ----------
    barrier : dict
        ``orientation``, ``center``, ``thickness`` and ``gap``.
    coords : numpy.ndarray, shape (N, 2)
        Normalised cell centres.
    gap_width : float
        Gap width ``g``.
    """
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

def assemble_operator(rho, ix, iy):
    """Variable-coefficient 5-point Laplacian with zero-flux boundaries.

    Parameters
    ----------
    rho : array_like, shape (N,)
        Positive cell densities.
    ix, iy : array_like of int, shape (N,)
        Distinct grid indices of the cells; rows follow this order.

    Returns
    -------
    scipy.sparse.csr_matrix
        ``A_ij = -w_ij`` for 4-neighbours with ``w_ij = 2 rho_i rho_j /
        (rho_i + rho_j)``, ``A_ii = sum_j w_ij``; sorted indices, no
        explicit zeros.
    """
    ix, iy, lookup, dims = _cell_lookup(ix, iy)
    n = ix.size
    rho = _check_density(rho, n)
    rows, cols = [], []
    for dx, dy in ((1, 0), (0, 1)):
        nbr = _neighbour(ix, iy, lookup, dims, dx, dy)
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


def buoyancy_rhs(rho, ix, iy):
    """Right-hand side ``-d(rho)/dy`` projected to mean zero.

    Central differences in grid-index units, one-sided where a vertical
    neighbour is absent, zero where both are.
    """
    ix, iy, lookup, dims = _cell_lookup(ix, iy)
    rho = _check_density(rho, ix.size)
    up = _neighbour(ix, iy, lookup, dims, 0, 1)
    down = _neighbour(ix, iy, lookup, dims, 0, -1)
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
    coords : numpy.ndarray, shape (N, 2)
        Normalised cell centres.
    grid_shape : tuple
        ``(W, H)``.
    perm : numpy.ndarray of int64
        Row-major cell index ``iy * W + ix`` of each row.
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

    def to_image(self, values):
        """Map Morton-ordered ``values`` to an ``(H, W)`` image, NaN where absent."""
        values = np.asarray(values, dtype=np.float64)
        if values.shape != (self.n,):
            raise ValueError(f"values must have shape ({self.n},), got {values.shape}")
        w, h = self.grid_shape
        image = np.full(w * h, np.nan)
        image[self.perm] = values
        return image.reshape(h, w)


def _make_rhs(kind, rng, rho, ix, iy):
    """Right-hand side of the requested kind."""
    if kind == "random":
        return _mean_zero(rng.standard_normal(rho.size))
    return buoyancy_rhs(rho, ix, iy)


def make_frame(n, seed=0, distribution="full", contrast=None, rhs="random",
               gap_width=0.25):
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
        Barrier gap width in ``[0, 1]``.

    Returns
    -------
    Frame
    """
    n = _check_positive_int(n, "n")
    seed = _check_seed(seed)
    if rhs not in RHS_KINDS:
        raise ValueError(f"unknown rhs {rhs!r}; expected one of {', '.join(RHS_KINDS)}")
    if not 0.0 <= gap_width <= 1.0:
        raise ValueError(f"gap_width must lie in [0, 1], got {gap_width!r}")
    rng = np.random.default_rng(np.random.SeedSequence(seed))
    scene = sample_params(rng, distribution, contrast)
    w, h = grid_dims(n)
    ix, iy = morton_cells(n)
    coords = np.column_stack(((ix + 0.5) / w, (iy + 0.5) / h))
    rho = barrier_density(coords, scene["rho_heavy"], scene["barriers"], gap_width)
    rho *= 1.0 + rng.normal(0.0, DENSITY_NOISE, n)
    params = {
        "n": n, "seed": seed, "distribution": distribution,
        "contrast": None if contrast is None else [float(c) for c in contrast],
        "rho_heavy": scene["rho_heavy"], "gap_width": float(gap_width),
        "rhs": rhs, "barriers": scene["barriers"],
    }
    return Frame(
        A=assemble_operator(rho, ix, iy),
        b=_make_rhs(rhs, rng, rho, ix, iy),
        rho=rho,
        coords=coords,
        grid_shape=(w, h),
        perm=iy * w + ix,
        params=params,
    )


# ------------------------------------------------------------------- reports

def frame_summary(frame):
    """A few human-readable lines describing a frame."""
    p = frame.params
    w, h = frame.grid_shape
    diag = frame.A.diagonal()
    barriers = "; ".join(
        f"{b['orientation']} c={b['center']:.3f} t={b['thickness']:.3f} gap={b['gap']}"
        for b in p["barriers"]
    )
    return "\n".join([
        f"N={frame.n} grid={w}x{h} distribution={p['distribution']} "
        f"seed={p['seed']} rhs={p['rhs']}",
        f"rho_heavy={p['rho_heavy']:.4g} rho range=[{frame.rho.min():.4g}, "
        f"{frame.rho.max():.4g}]",
        f"barriers ({len(p['barriers'])}): {barriers}",
        f"nnz={frame.A.nnz} diag range=[{diag.min():.4g}, {diag.max():.4g}]",
    ])
