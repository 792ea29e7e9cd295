"""Semi-Lagrangian advection on the staggered grid of :class:`~petsc_htp.sim.flow.Flow`: multilinear sampling
and backward traces through the face velocities."""
from __future__ import annotations

import numpy as np


def sample(field, pts, offset, h):
    """Multilinear interpolation of ``field``, whose entry at physical index ``(i, j[, k])`` sits at
    ``((i + offset[0]) h, (j + offset[1]) h[, ...])``, at the points ``pts`` (x, y[, z] arrays).

    Interpolates along x innermost, then y, then z."""
    d = len(pts)
    base, frac = [], []
    for a in range(d):
        size = field.shape[d - 1 - a]
        f = np.clip(pts[a] / h - offset[a], 0.0, size - 1)
        i = np.minimum(f.astype(np.int64), size - 2)
        base.append(i)
        frac.append(f - i)

    def lerp(a, fixed):
        if a < 0:
            return field[tuple(fixed[b] for b in reversed(range(d)))]
        lo = lerp(a - 1, {**fixed, a: base[a]})
        hi = lerp(a - 1, {**fixed, a: base[a] + 1})
        return (1 - frac[a]) * lo + frac[a] * hi

    return lerp(d - 1, {})


def face_offset(a, dim):
    """Where velocity component ``a`` sits in its cell: 0 along ``a``, 1/2 across."""
    return [0.0 if b == a else 0.5 for b in range(dim)]


def velocity(vel, pts, h):
    """The face velocities ``vel`` (one array per component) interpolated at the points ``pts``."""
    return [sample(vel[a], pts, face_offset(a, len(vel)), h) for a in range(len(vel))]


def departure(vel, pts, dt, substeps, h, size):
    """Departure points of a backward trace over ``dt`` through ``vel`` in ``substeps`` RK2 steps, kept inside the
    box of physical ``size``."""
    step = dt / substeps
    for _ in range(substeps):
        v = velocity(vel, pts, h)
        v = velocity(vel, [p - 0.5 * step * w for p, w in zip(pts, v)], h)
        pts = [np.clip(p - step * w, 0.0, s) for p, w, s in zip(pts, v, size)]
    return pts
