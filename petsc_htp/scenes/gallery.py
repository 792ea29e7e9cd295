"""Problems beyond the generator's scenes, as PyAMG's gallery has them: plain matrices a user would hand over.

:func:`variable_poisson` is the 5-point variable-coefficient Poisson problem of a DMDA program
(``examples/dmda_poisson.py`` assembles the same matrix through a PETSc DMDA): unit squares on an
nx x ny grid in row-major order, conductivity 1 with discs of conductivity ``contrast``, harmonic means
on the faces and homogeneous Dirichlet boundaries (SPD, nonsingular). Nothing is attached: no
coordinates, no density, no null space.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp


def inclusions(nx, ny, contrast=1000.0, seed=0, count=24) -> np.ndarray:
    """Cell conductivity (ny, nx): 1, and ``contrast`` inside ``count`` random discs (radius 0.03-0.1)."""
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[0:ny, 0:nx]
    x, y = (x + 0.5) / nx, (y + 0.5) / ny
    k = np.ones((ny, nx))
    for cx, cy, r in zip(rng.random(count), rng.random(count), rng.uniform(0.03, 0.1, count)):
        k[(x - cx) ** 2 + (y - cy) ** 2 <= r * r] = contrast
    return k


def balls(shape, contrast=1000.0, seed=0, count=24) -> np.ndarray:
    """Cell conductivity on a 3-D grid of ``shape`` (nz, ny, nx): 1, and ``contrast`` inside ``count`` random balls
    (radius 0.05-0.15)."""
    rng = np.random.default_rng(seed)
    grids = np.meshgrid(*[(np.arange(s) + 0.5) / s for s in shape], indexing="ij")
    k = np.ones(shape)
    for _ in range(count):
        c, r = rng.random(3), rng.uniform(0.05, 0.15)
        k[sum((g - ci) ** 2 for g, ci in zip(grids, c)) <= r * r] = contrast
    return k


def face_weights(k) -> tuple:
    """Harmonic-mean conductances of the interior faces along x, y (and z) of a cell conductivity ``k`` (ny, nx)
    or (nz, ny, nx), each one shorter along its axis, and the boundary conductance of every cell: twice its own
    conductivity per Dirichlet face it touches."""
    weights, edge = [], np.zeros_like(k)
    for axis in range(k.ndim - 1, -1, -1):
        lo, hi = [slice(None)] * k.ndim, [slice(None)] * k.ndim
        lo[axis], hi[axis] = slice(None, -1), slice(1, None)
        a, c = k[tuple(lo)], k[tuple(hi)]
        weights.append(2 * a * c / (a + c))
    for axis in range(k.ndim - 1, -1, -1):
        for end in (0, -1):
            face = [slice(None)] * k.ndim
            face[axis] = end
            edge[tuple(face)] += 2 * k[tuple(face)]
    return (*weights, edge)


def variable_poisson(nx, ny=None, contrast=1000.0, seed=0) -> tuple:
    """(A, b, k): the operator (CSR, row-major cells), a unit source times the cell area, the conductivity."""
    ny = nx if ny is None else ny
    k = inclusions(nx, ny, contrast, seed)
    wx, wy, edge = face_weights(k)
    idx = np.arange(nx * ny).reshape(ny, nx)
    i = np.concatenate([idx[:, :-1].ravel(), idx[:-1, :].ravel()])
    j = np.concatenate([idx[:, 1:].ravel(), idx[1:, :].ravel()])
    w = np.concatenate([wx.ravel(), wy.ravel()])
    diag = np.bincount(i, w, nx * ny) + np.bincount(j, w, nx * ny) + edge.ravel()
    A = sp.coo_matrix((np.concatenate([-w, -w, diag]), (np.concatenate([i, j, idx.ravel()]),
                                                         np.concatenate([j, i, idx.ravel()]))),
                      shape=(nx * ny, nx * ny)).tocsr()
    A.sort_indices()
    return A, np.full(nx * ny, 1.0 / (nx * ny)), k
