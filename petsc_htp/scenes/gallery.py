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


def face_weights(k) -> tuple:
    """Harmonic-mean conductances of the interior x-faces (ny, nx-1) and y-faces (ny-1, nx), and the boundary
    conductance of every cell (ny, nx): twice its own conductivity per Dirichlet face it touches."""
    wx = 2 * k[:, 1:] * k[:, :-1] / (k[:, 1:] + k[:, :-1])
    wy = 2 * k[1:, :] * k[:-1, :] / (k[1:, :] + k[:-1, :])
    edge = np.zeros_like(k)
    edge[:, 0] += 2 * k[:, 0]
    edge[:, -1] += 2 * k[:, -1]
    edge[0, :] += 2 * k[0, :]
    edge[-1, :] += 2 * k[-1, :]
    return wx, wy, edge


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
