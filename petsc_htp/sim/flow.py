"""Two-phase incompressible flow on a MAC grid: a heavy blob falls past a ledge into a pool.

The physics behind ``examples/multiphase_flow.py`` (numpy and scipy only). Each frame:
:meth:`Flow.advance` (semi-Lagrangian advection of velocity and level set, then
gravity), :meth:`Flow.system` (the pressure-Poisson system), a solve, and
:meth:`Flow.project`. The matrix is the benchmark's multiphase operator
(:func:`petsc_htp.scenes.assemble_operator` with coefficient ``1/rho``, face weight
``2/(rho_i + rho_j)``) over the fluid cells in Morton order: its nonzero pattern
never changes, only its values do.

The phase is a level set ``phi`` (negative in the heavy fluid); the density is
``rho = 1 + (R - 1) H(-phi)`` with a smoothed Heaviside ``H`` 1.5 cells wide on
each side. After advection ``phi`` is redistanced (a few Sussman steps) and
shifted by one global constant (Brent's method) so that the heavy volume
``sum H(-phi) dx^2`` keeps its initial value. The two phase masses, which split
``sum rho dx^2``, are therefore conserved up to round-off (tested: relative
change below 1e-10 over a run).
"""
import math
import numbers

import numpy as np
from scipy import ndimage, optimize

from ..morton import morton_code
from ..scenes.generator import assemble_operator

GRAVITY = 9.81
FRAME_DT = 1.0 / 60.0
SMOOTHING = 1.5          # half-width of the smoothed Heaviside, in cells
REDISTANCE_STEPS = 4     # Sussman pseudo-time steps per frame
MIN_CELLS = 8


def _heaviside(x, eps):
    """Smoothed Heaviside: 0 below ``-eps``, 1 above ``eps``."""
    t = np.clip(x / eps, -1.0, 1.0)
    return 0.5 * (1.0 + t + np.sin(np.pi * t) / np.pi)


def _sample(field, x, y, ox, oy, h):
    """Bilinear interpolation of ``field[j, i]``, stored at ``((i + ox) h, (j + oy) h)``, at points."""
    fx = np.clip(x / h - ox, 0.0, field.shape[1] - 1)
    fy = np.clip(y / h - oy, 0.0, field.shape[0] - 1)
    i = np.minimum(fx.astype(np.int64), field.shape[1] - 2)
    j = np.minimum(fy.astype(np.int64), field.shape[0] - 2)
    tx, ty = fx - i, fy - j
    return ((1 - ty) * ((1 - tx) * field[j, i] + tx * field[j, i + 1])
            + ty * ((1 - tx) * field[j + 1, i] + tx * field[j + 1, i + 1]))


def _redistance(phi, h, steps):
    """``steps`` pseudo-time steps of ``phi_t = S(phi0) (1 - |grad phi|)``, Godunov upwind."""
    sign = phi / np.sqrt(phi ** 2 + h ** 2)
    for _ in range(steps):
        p = np.pad(phi, 1, mode="edge")
        grad2 = 0.0
        for back, fwd in ((phi - p[1:-1, :-2], p[1:-1, 2:] - phi),
                          (phi - p[:-2, 1:-1], p[2:, 1:-1] - phi)):
            outward = np.maximum(np.maximum(back, 0) ** 2, np.minimum(fwd, 0) ** 2)
            inward = np.maximum(np.minimum(back, 0) ** 2, np.maximum(fwd, 0) ** 2)
            grad2 = grad2 + np.where(sign > 0, outward, inward)
        phi = phi - 0.5 * h * sign * (np.sqrt(grad2) / h - 1.0)
    return phi


def scene(nx, ny, seed=0):
    """Solid mask and initial level set of the splash scene.

    A pool fills the bottom quarter, a ledge floats at mid height on the left,
    and a round blob (centre and radius jittered by ``seed``) hangs above the
    ledge's right end. The box is 1 wide and ``ny/nx`` high.

    Returns
    -------
    solid : numpy.ndarray of bool, shape (ny, nx)
    phi : numpy.ndarray, shape (ny, nx)
        Signed distance, negative in the heavy fluid.
    """
    rng = np.random.default_rng(seed)
    top = ny / nx
    x, y = np.meshgrid((np.arange(nx) + 0.5) / nx, (np.arange(ny) + 0.5) / nx)
    solid = (np.abs(x - 0.32) < 0.17) & (np.abs(y - 0.45 * top) < max(0.035, 0.6 / nx))
    cx, radius = 0.5 + rng.uniform(-0.05, 0.05), 0.12 * rng.uniform(0.9, 1.1)
    phi = np.minimum(y - 0.25 * top, np.hypot(x - cx, y - 0.75 * top) - radius)
    return solid, phi


class Flow:
    """Heavy and light incompressible fluid in a closed box with a solid obstacle.

    Parameters
    ----------
    nx, ny : int
        Cells across and up (at least 8 each); the cell size is ``1/nx``.
    density_ratio : float
        Heavy over light density (light is 1), at least 1.
    seed : int
        Jitters the blob (see :func:`scene`).
    solid : numpy.ndarray of bool, shape (ny, nx), optional
        Replaces the scene's obstacle; walls splitting the box make several fluid regions.
    dt : float
        Frame time step.
    cfl : float
        Advection substeps per frame: ``ceil(max|u| dt / (cfl dx))``.

    Attributes
    ----------
    ix, iy : numpy.ndarray of int64, shape (N,)
        Grid indices of the unknowns (fluid cells) in Morton order.
    coords : numpy.ndarray, shape (N, 2)
        Cell centres normalised to ``[0, 1]`` per axis, in Morton order.
    regions : numpy.ndarray of int64, shape (N,)
        Connected fluid region (0 .. n_regions-1) of each unknown.
    substeps : int
        Advection substeps of the last :meth:`advance`.
    """

    def __init__(self, nx, ny, density_ratio=1000.0, seed=0, solid=None, dt=FRAME_DT, cfl=1.0):
        for name, value in (("nx", nx), ("ny", ny)):
            if isinstance(value, bool) or not isinstance(value, numbers.Integral) or value < MIN_CELLS:
                raise ValueError(f"{name} must be an integer >= {MIN_CELLS}, got {value!r}")
        if not (math.isfinite(density_ratio) and density_ratio >= 1.0):
            raise ValueError(f"density_ratio must be finite and >= 1, got {density_ratio!r}")
        if not (math.isfinite(dt) and dt > 0 and math.isfinite(cfl) and cfl > 0):
            raise ValueError(f"dt and cfl must be positive, got dt={dt!r}, cfl={cfl!r}")
        self.nx, self.ny, self.ratio, self.dt, self.cfl = int(nx), int(ny), float(density_ratio), dt, cfl
        self.h = 1.0 / nx
        self.eps = SMOOTHING * self.h
        scene_solid, phi = scene(self.nx, self.ny, seed)
        solid = scene_solid if solid is None else np.asarray(solid, dtype=bool)
        if solid.shape != (ny, nx) or solid.all():
            raise ValueError(f"solid must be a ({ny}, {nx}) mask with at least one fluid cell")
        self.fluid = ~solid
        iy, ix = np.nonzero(self.fluid)
        order = np.argsort(morton_code(ix, iy), kind="stable")
        self.ix, self.iy = ix[order], iy[order]
        self.coords = np.column_stack(((self.ix + 0.5) / nx, (self.iy + 0.5) / ny))
        labels, self.n_regions = ndimage.label(self.fluid)
        self.regions = labels[self.iy, self.ix] - 1
        self.u_open = np.zeros((ny, nx + 1), dtype=bool)
        self.u_open[:, 1:-1] = self.fluid[:, :-1] & self.fluid[:, 1:]
        self.v_open = np.zeros((ny + 1, nx), dtype=bool)
        self.v_open[1:-1] = self.fluid[:-1] & self.fluid[1:]
        self.u = np.zeros((ny, nx + 1))
        self.v = np.zeros((ny + 1, nx))
        self._nearest = tuple(ndimage.distance_transform_edt(solid, return_indices=True)[1])
        self.phi = phi[self._nearest]
        self.heavy_volume = self._heavy_volume(self.phi[self.fluid])
        self.substeps = 0

    @property
    def n(self):
        """Number of unknowns (fluid cells)."""
        return self.ix.size

    # ------------------------------------------------------------- phase

    def _heavy_volume(self, phi_fluid):
        """Heavy volume in cells: ``sum H(-phi)`` over the fluid."""
        return float(_heaviside(-phi_fluid, self.eps).sum())

    def _conserve_volume(self, phi):
        """``phi`` plus the constant that restores the initial heavy volume."""
        fluid_phi = phi[self.fluid]
        lo, hi = -fluid_phi.max() - self.eps, -fluid_phi.min() + self.eps
        shift = optimize.brentq(lambda c: self._heavy_volume(fluid_phi + c) - self.heavy_volume,
                                lo, hi, xtol=1e-15 * self.h)
        return phi + shift

    def _theta(self):
        """Heavy fraction ``H(-phi)`` of every cell, shape (ny, nx)."""
        return _heaviside(-self.phi, self.eps)

    def density(self):
        """Cell densities of the unknowns, Morton order."""
        return 1.0 + (self.ratio - 1.0) * self._theta()[self.iy, self.ix]

    def phase_mass(self):
        """(heavy, light) mass: ``sum rho dx^2`` split by phase."""
        theta = self._theta()[self.fluid]
        area = self.h ** 2
        return self.ratio * theta.sum() * area, (1.0 - theta).sum() * area

    # ---------------------------------------------------------- advection

    def _velocity(self, x, y):
        """Velocity ``(u, v)`` interpolated at points."""
        return _sample(self.u, x, y, 0.0, 0.5, self.h), _sample(self.v, x, y, 0.5, 0.0, self.h)

    def _departure(self, x, y, substeps):
        """Departure points of a backward trace over ``dt`` in ``substeps`` RK2 steps."""
        step = self.dt / substeps
        width, height = self.nx * self.h, self.ny * self.h
        for _ in range(substeps):
            u, v = self._velocity(x, y)
            u, v = self._velocity(x - 0.5 * step * u, y - 0.5 * step * v)
            x = np.clip(x - step * u, 0.0, width)
            y = np.clip(y - step * v, 0.0, height)
        return x, y

    def advance(self):
        """Advect velocity and level set by one frame, then add gravity.

        The trace through the current (divergence-free) velocity takes
        ``substeps`` RK2 steps so that each moves at most ``cfl`` cells; every
        field is interpolated once, at the departure points.
        """
        speed = max(np.abs(self.u).max(), np.abs(self.v).max())
        self.substeps = max(1, math.ceil(speed * self.dt / (self.cfl * self.h)))
        uj, ui = np.nonzero(self.u_open)
        vj, vi = np.nonzero(self.v_open)
        cj, ci = np.nonzero(self.fluid)
        h = self.h
        u_from = self._departure(ui * h, (uj + 0.5) * h, self.substeps)
        v_from = self._departure((vi + 0.5) * h, vj * h, self.substeps)
        c_from = self._departure((ci + 0.5) * h, (cj + 0.5) * h, self.substeps)
        u, v, phi = self.u.copy(), self.v.copy(), self.phi.copy()
        u[uj, ui] = _sample(self.u, *u_from, 0.0, 0.5, h)
        v[vj, vi] = _sample(self.v, *v_from, 0.5, 0.0, h) - GRAVITY * self.dt
        phi[cj, ci] = _sample(self.phi, *c_from, 0.5, 0.5, h)
        phi = _redistance(phi[self._nearest], h, REDISTANCE_STEPS)
        self.u, self.v = u, v
        self.phi = self._conserve_volume(phi[self._nearest])

    # --------------------------------------------------------- projection

    def _divergence(self):
        """Cell divergence of the face velocity, shape (ny, nx)."""
        return (np.diff(self.u, axis=1) + np.diff(self.v, axis=0)) / self.h

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
        coords : numpy.ndarray, shape (N, 2)
        density : numpy.ndarray, shape (N,)
        """
        rho = self.density()
        A = assemble_operator(1.0 / rho, self.ix, self.iy)
        b = -(self.h ** 2 / self.dt) * self._divergence()[self.iy, self.ix]
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
        pressure, rho = self.pressure_image(p), 1.0 + (self.ratio - 1.0) * self._theta()
        scale = self.dt / self.h
        du = scale * 2.0 / (rho[:, :-1] + rho[:, 1:]) * np.diff(pressure, axis=1)
        dv = scale * 2.0 / (rho[:-1] + rho[1:]) * np.diff(pressure, axis=0)
        self.u[:, 1:-1] -= np.where(self.u_open[:, 1:-1], du, 0.0)
        self.v[1:-1] -= np.where(self.v_open[1:-1], dv, 0.0)
        return self.max_divergence()

    # ------------------------------------------------------------- images

    def _image(self, values):
        """(ny, nx) image of Morton-ordered values, NaN in solid cells."""
        values = np.asarray(values, dtype=np.float64)
        if values.shape != (self.n,):
            raise ValueError(f"values must have shape ({self.n},), got {values.shape}")
        image = np.full((self.ny, self.nx), np.nan)
        image[self.iy, self.ix] = values
        return image

    def density_image(self):
        """(ny, nx) density, NaN in solid cells (row 0 at the bottom)."""
        return self._image(self.density())

    def pressure_image(self, p):
        """(ny, nx) image of a Morton-ordered pressure, NaN in solid cells."""
        return self._image(p)
