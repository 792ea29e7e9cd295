"""Two-phase incompressible flow on a MAC grid, in 2-D or 3-D: a heavy blob falls past a ledge into a pool.

The physics behind ``examples/multiphase_flow.py`` (numpy and scipy only). Each frame:
:meth:`Flow.advance` (semi-Lagrangian advection of velocity and level set, then
gravity), :meth:`Flow.system` (the pressure-Poisson system), a solve, and
:meth:`Flow.project`. The matrix is the benchmark's multiphase operator
(:func:`petsc_htp.scenes.generator.assemble_operator` with coefficient ``1/rho``, face weight
``2/(rho_i + rho_j)``; 5-point in 2-D, 7-point in 3-D) over the fluid cells in Morton order: its
nonzero pattern never changes, only its values do.

The phase is a level set ``phi`` (negative in the heavy fluid); the density is
``rho = 1 + (R - 1) H(-phi)`` with a smoothed Heaviside ``H`` 1.5 cells wide on
each side. After advection ``phi`` is redistanced (a few Sussman steps) and
shifted by one global constant (Brent's method) so that the heavy volume
``sum H(-phi) dx^d`` keeps its initial value. The two phase masses, which split
``sum rho dx^d``, are therefore conserved up to round-off (tested: relative
change below 1e-10 over a run).

Arrays are indexed ``[iy, ix]`` (2-D) or ``[iz, iy, ix]`` (3-D); physical axis ``a`` (x, y, z) is array
axis ``d - 1 - a``, and the last physical axis is up.
"""
import math
import numbers

import numpy as np
from scipy import ndimage, optimize

from ..morton import morton_code
from ..scenes.generator import assemble_operator
from .advection import departure, face_offset, sample

GRAVITY = 9.81
FRAME_DT = 1.0 / 60.0
SMOOTHING = 1.5          # half-width of the smoothed Heaviside, in cells
REDISTANCE_STEPS = 4     # Sussman pseudo-time steps per frame
MIN_CELLS = 8


def _heaviside(x, eps):
    """Smoothed Heaviside: 0 below ``-eps``, 1 above ``eps``."""
    t = np.clip(x / eps, -1.0, 1.0)
    return 0.5 * (1.0 + t + np.sin(np.pi * t) / np.pi)


def _shifted(p, axis, step):
    """The interior of the edge-padded ``p`` moved by ``step`` (-1 or 1) along ``axis``."""
    return p[tuple(slice(1 + step, p.shape[ax] - 1 + step) if ax == axis else slice(1, -1) for ax in range(p.ndim))]


def _redistance(phi, h, steps):
    """``steps`` pseudo-time steps of ``phi_t = S(phi0) (1 - |grad phi|)``, Godunov upwind."""
    sign = phi / np.sqrt(phi ** 2 + h ** 2)
    for _ in range(steps):
        p = np.pad(phi, 1, mode="edge")
        grad2 = 0.0
        for axis in reversed(range(phi.ndim)):                  # x first
            back, fwd = phi - _shifted(p, axis, -1), _shifted(p, axis, 1) - phi
            outward = np.maximum(np.maximum(back, 0) ** 2, np.minimum(fwd, 0) ** 2)
            inward = np.maximum(np.minimum(back, 0) ** 2, np.maximum(fwd, 0) ** 2)
            grad2 = grad2 + np.where(sign > 0, outward, inward)
        phi = phi - 0.5 * h * sign * (np.sqrt(grad2) / h - 1.0)
    return phi


def _heavy_volume(phi_fluid, eps):
    """Heavy volume in cells: ``sum H(-phi)`` over the fluid values ``phi_fluid``."""
    return float(_heaviside(-phi_fluid, eps).sum())


def _conserve_volume(phi, fluid, volume, eps, h):
    """``phi`` plus the constant that brings the heavy volume over the ``fluid`` cells back to ``volume``."""
    fluid_phi = phi[fluid]
    lo, hi = -fluid_phi.max() - eps, -fluid_phi.min() + eps
    shift = optimize.brentq(lambda c: _heavy_volume(fluid_phi + c, eps) - volume, lo, hi, xtol=1e-15 * h)
    return phi + shift


def scene(nx, ny, seed=0, nz=None):
    """Solid mask and initial level set of the splash scene.

    A pool fills the bottom quarter, a ledge floats at mid height on the left,
    and a round blob (centre and radius jittered by ``seed``) hangs above the
    ledge's right end. The box is 1 wide and ``ny/nx`` high; with ``nz`` it is
    3-D (``ny/nx`` deep, ``nz/nx`` high), the ledge a plate half the depth wide
    and the blob a sphere.

    Returns
    -------
    solid : numpy.ndarray of bool, shape (ny, nx) or (nz, ny, nx)
    phi : numpy.ndarray, same shape
        Signed distance, negative in the heavy fluid.
    """
    rng = np.random.default_rng(seed)
    if nz is None:
        top = ny / nx
        x, y = np.meshgrid((np.arange(nx) + 0.5) / nx, (np.arange(ny) + 0.5) / nx)
        solid = (np.abs(x - 0.32) < 0.17) & (np.abs(y - 0.45 * top) < max(0.035, 0.6 / nx))
        cx, radius = 0.5 + rng.uniform(-0.05, 0.05), 0.12 * rng.uniform(0.9, 1.1)
        phi = np.minimum(y - 0.25 * top, np.hypot(x - cx, y - 0.75 * top) - radius)
        return solid, phi
    top, depth = nz / nx, ny / nx
    z, y, x = np.meshgrid((np.arange(nz) + 0.5) / nx, (np.arange(ny) + 0.5) / nx, (np.arange(nx) + 0.5) / nx,
                          indexing="ij")
    solid = ((np.abs(x - 0.32) < 0.17) & (np.abs(y - 0.5 * depth) < 0.25 * depth)
             & (np.abs(z - 0.45 * top) < max(0.035, 0.6 / nx)))
    cx, radius = 0.5 + rng.uniform(-0.05, 0.05), 0.15 * rng.uniform(0.9, 1.1)
    blob = np.sqrt((x - cx) ** 2 + (y - 0.5 * depth) ** 2 + (z - 0.75 * top) ** 2) - radius
    return solid, np.minimum(z - 0.25 * top, blob)


def _interior(shape, axis):
    """Index of the faces strictly inside a face array of ``shape`` along ``axis``."""
    return tuple(slice(1, -1) if ax == axis else slice(None) for ax in range(len(shape)))


def _pair(fluid, axis):
    """Whether both cells of each interior face along ``axis`` are fluid."""
    lo = tuple(slice(None, -1) if ax == axis else slice(None) for ax in range(fluid.ndim))
    hi = tuple(slice(1, None) if ax == axis else slice(None) for ax in range(fluid.ndim))
    return fluid[lo] & fluid[hi]


class Flow:
    """Heavy and light incompressible fluid in a closed box with a solid obstacle.

    Parameters
    ----------
    nx, ny : int
        Cells across and up (2-D) or deep (3-D), at least 8 each; the cell size is ``1/nx``.
    density_ratio : float
        Heavy over light density (light is 1), at least 1.
    seed : int
        Jitters the blob (see :func:`scene`).
    solid : numpy.ndarray of bool, shape (ny, nx) or (nz, ny, nx), optional
        Replaces the scene's obstacle; walls splitting the box make several fluid regions.
    dt : float
        Frame time step.
    cfl : float
        Advection substeps per frame: ``ceil(max|u| dt / (cfl dx))``.
    nz : int, optional
        Cells up in 3-D (at least 8); None for 2-D.

    Attributes
    ----------
    idx : tuple of numpy.ndarray of int64, shape (N,)
        Grid indices (ix, iy[, iz]) of the unknowns (fluid cells) in Morton order; also ``ix``, ``iy``.
    coords : numpy.ndarray, shape (N, d)
        Cell centres normalised to ``[0, 1]`` per axis, in Morton order.
    regions : numpy.ndarray of int64, shape (N,)
        Connected fluid region (0 .. n_regions-1) of each unknown.
    substeps : int
        Advection substeps of the last :meth:`advance`.
    """

    def __init__(self, nx, ny, density_ratio=1000.0, seed=0, solid=None, dt=FRAME_DT, cfl=1.0, nz=None):
        for name, value in (("nx", nx), ("ny", ny)) + ((("nz", nz),) if nz is not None else ()):
            if isinstance(value, bool) or not isinstance(value, numbers.Integral) or value < MIN_CELLS:
                raise ValueError(f"{name} must be an integer >= {MIN_CELLS}, got {value!r}")
        if not (math.isfinite(density_ratio) and density_ratio >= 1.0):
            raise ValueError(f"density_ratio must be finite and >= 1, got {density_ratio!r}")
        if not (math.isfinite(dt) and dt > 0 and math.isfinite(cfl) and cfl > 0):
            raise ValueError(f"dt and cfl must be positive, got dt={dt!r}, cfl={cfl!r}")
        self.shape = (int(nx), int(ny)) + (() if nz is None else (int(nz),))
        self.dim = len(self.shape)
        self.ratio, self.dt, self.cfl = float(density_ratio), dt, cfl
        self.h = 1.0 / nx
        self.eps = SMOOTHING * self.h
        cells = self.shape[::-1]
        scene_solid, phi = scene(int(nx), int(ny), seed, nz)
        solid = scene_solid if solid is None else np.asarray(solid, dtype=bool)
        if solid.shape != cells or solid.all():
            raise ValueError(f"solid must be a {cells} mask with at least one fluid cell")
        self.fluid = ~solid
        idx = np.nonzero(self.fluid)[::-1]                         # (ix, iy[, iz])
        order = np.argsort(morton_code(*idx), kind="stable")
        self.idx = tuple(i[order] for i in idx)
        self.at = self.idx[::-1]                                   # array index of the unknowns
        self.coords = np.column_stack([(i + 0.5) / s for i, s in zip(self.idx, self.shape)])
        labels, self.n_regions = ndimage.label(self.fluid)
        self.regions = labels[self.at] - 1
        self.open, self.vel = [], []
        for a in range(self.dim):
            axis = self.dim - 1 - a
            faces = tuple(c + (ax == axis) for ax, c in enumerate(cells))
            opened = np.zeros(faces, dtype=bool)
            opened[_interior(faces, axis)] = _pair(self.fluid, axis)
            self.open.append(opened)
            self.vel.append(np.zeros(faces))
        self._nearest = tuple(ndimage.distance_transform_edt(solid, return_indices=True)[1])
        self.phi = phi[self._nearest]
        self.heavy_volume = _heavy_volume(self.phi[self.fluid], self.eps)
        self.substeps = 0

    @property
    def n(self):
        """Number of unknowns (fluid cells)."""
        return self.idx[0].size

    @property
    def ix(self):
        """x grid index of the unknowns."""
        return self.idx[0]

    @property
    def iy(self):
        """y grid index of the unknowns."""
        return self.idx[1]

    # ------------------------------------------------------------- phase

    def theta(self):
        """Heavy fraction ``H(-phi)`` of every cell (array shape)."""
        return _heaviside(-self.phi, self.eps)

    def density(self):
        """Cell densities of the unknowns, Morton order."""
        return 1.0 + (self.ratio - 1.0) * self.theta()[self.at]

    def phase_mass(self):
        """(heavy, light) mass: ``sum rho dx^d`` split by phase."""
        theta = self.theta()[self.fluid]
        volume = self.h ** self.dim
        return self.ratio * theta.sum() * volume, (1.0 - theta).sum() * volume

    def advance(self):
        """Advect velocity and level set by one frame, then add gravity (along the last axis).

        The trace through the current (divergence-free) velocity takes
        ``substeps`` RK2 steps so that each moves at most ``cfl`` cells; every
        field is interpolated once, at the departure points.
        """
        speed = max(np.abs(v).max() for v in self.vel)
        self.substeps = max(1, math.ceil(speed * self.dt / (self.cfl * self.h)))
        h, d = self.h, self.dim
        moved = []
        size = [s * h for s in self.shape]
        for a in range(d):
            at = np.nonzero(self.open[a])
            pts = [(at[d - 1 - b] + (0.0 if b == a else 0.5)) * h for b in range(d)]
            moved.append((at, departure(self.vel, pts, self.dt, self.substeps, h, size)))
        cells = np.nonzero(self.fluid)
        c_from = departure(self.vel, [(cells[d - 1 - b] + 0.5) * h for b in range(d)], self.dt, self.substeps, h, size)
        vel, phi = [v.copy() for v in self.vel], self.phi.copy()
        for a, (at, pts) in enumerate(moved):
            vel[a][at] = sample(self.vel[a], pts, face_offset(a, d), h) - (GRAVITY * self.dt if a == d - 1 else 0.0)
        phi[cells] = sample(self.phi, c_from, [0.5] * d, h)
        phi = _redistance(phi[self._nearest], h, REDISTANCE_STEPS)
        self.vel = vel
        self.phi = _conserve_volume(phi[self._nearest], self.fluid, self.heavy_volume, self.eps, h)

    # --------------------------------------------------------- projection

    def _divergence(self):
        """Cell divergence of the face velocity (array shape)."""
        div = np.diff(self.vel[0], axis=self.dim - 1)
        for a in range(1, self.dim):
            div = div + np.diff(self.vel[a], axis=self.dim - 1 - a)
        return div / self.h

    def max_divergence(self):
        """max |div u| over the fluid cells."""
        return float(np.abs(self._divergence()[self.fluid]).max())

    def system(self):
        """The pressure system ``A p = b`` of the current velocity and density.

        ``A`` has face weights ``2/(rho_i + rho_j)`` and zero flux through walls
        and obstacle; ``b = -(dx^2/dt) div u``, made mean-zero in each fluid
        region. ``p`` is the physical pressure.

        Returns
        -------
        A : scipy.sparse.csr_matrix
            Symmetric positive semidefinite, same pattern every frame.
        b : numpy.ndarray, shape (N,)
        coords : numpy.ndarray, shape (N, d)
        density : numpy.ndarray, shape (N,)
        """
        rho = self.density()
        A = assemble_operator(1.0 / rho, *self.idx)
        b = -(self.h ** 2 / self.dt) * self._divergence()[self.at]
        b -= (np.bincount(self.regions, b) / np.bincount(self.regions))[self.regions]
        return A, b, self.coords, rho

    def project(self, p):
        """Subtract ``dt grad(p) / rho_face`` from the open faces.

        Parameters
        ----------
        p : array_like, shape (N,)
            Pressure in Morton order (a solution of :meth:`system`).

        Returns
        -------
        float
            max |div u| after the projection.
        """
        pressure, rho = image(self, p), 1.0 + (self.ratio - 1.0) * self.theta()
        scale = self.dt / self.h
        for a in range(self.dim):
            axis = self.dim - 1 - a
            lo = tuple(slice(None, -1) if ax == axis else slice(None) for ax in range(self.dim))
            hi = tuple(slice(1, None) if ax == axis else slice(None) for ax in range(self.dim))
            inner = _interior(self.vel[a].shape, axis)
            grad = scale * 2.0 / (rho[lo] + rho[hi]) * np.diff(pressure, axis=axis)
            self.vel[a][inner] -= np.where(self.open[a][inner], grad, 0.0)
        return self.max_divergence()


def image(flow, values):
    """Array-shaped image of a :class:`Flow`'s Morton-ordered ``values`` (density, pressure), NaN in solid cells
    (row 0 at the bottom; a (nz, ny, nx) volume in 3-D)."""
    values = np.asarray(values, dtype=np.float64)
    if values.shape != (flow.n,):
        raise ValueError(f"values must have shape ({flow.n},), got {values.shape}")
    out = np.full(flow.fluid.shape, np.nan)
    out[flow.at] = values
    return out
