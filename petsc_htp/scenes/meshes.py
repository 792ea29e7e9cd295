"""P1 finite-element Laplacians on unstructured simplices (triangles in 2-D, tetrahedra in 3-D), and the matrix of one
implicit heat-equation step there, M + dt K.

Nodes are a jittered lattice of the unit square (cube) in a random order, meshed by Delaunay; the boundary
nodes are Dirichlet and eliminated, so the matrix is SPD with the interior nodes as unknowns, in the
shuffled order a mesh generator leaves them. PETSc-free; scipy's Delaunay.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.spatial import Delaunay

from .gallery import balls


def _points(dim, side, rng) -> tuple:
    """A jittered ``side``^dim lattice in a random order and which of its points lie on the boundary."""
    grid = np.stack(np.meshgrid(*[np.arange(side)] * dim, indexing="ij"), -1).reshape(-1, dim).astype(float)
    boundary = np.any((grid == 0) | (grid == side - 1), axis=1)
    grid += np.where(boundary[:, None], 0.0, rng.uniform(-0.3, 0.3, grid.shape))
    order = rng.permutation(len(grid))
    return grid[order] / (side - 1), boundary[order]


def _elements(points, simplices):
    """The simplices that are not flat, their volumes and the gradients of their P1 basis functions (E, d+1, d)."""
    dim = points.shape[1]
    X = points[simplices]                                   # (E, d+1, d)
    J = X[:, 1:, :] - X[:, :1, :]                           # (E, d, d)
    det = np.linalg.det(J)
    keep = np.abs(det) > 1e-14
    ref = np.vstack([-np.ones((1, dim)), np.eye(dim)])     # reference gradients (d+1, d)
    G = np.einsum("ad,ekd->eak", ref, np.linalg.inv(J[keep]))   # gradients: ref @ J^-T
    return keep, np.abs(det[keep]) / np.prod(np.arange(1, dim + 1)), G


def _assemble(n, simplices, local) -> sp.csr_matrix:
    """The n x n matrix summed from the element matrices ``local`` (E, d+1, d+1) of ``simplices``."""
    k = simplices.shape[1]
    rows = np.repeat(simplices, k, axis=1).ravel()
    cols = np.tile(simplices, (1, k)).ravel()
    return sp.csr_matrix((local.ravel(), (rows, cols)), shape=(n, n))


def stiffness(points, simplices, coefficient=None) -> sp.csr_matrix:
    """The P1 stiffness matrix of a simplicial mesh (any dimension), with a conductivity per element (default 1)."""
    keep, vol, G = _elements(points, simplices)
    kappa = np.ones(keep.sum()) if coefficient is None else coefficient[keep]
    K = (kappa * vol)[:, None, None] * np.einsum("eak,ebk->eab", G, G)
    return _assemble(len(points), simplices[keep], K)


def mass(points, simplices) -> sp.csr_matrix:
    """The P1 (consistent) mass matrix of a simplicial mesh: vol (1 + delta_ab) / ((d + 1)(d + 2)) per element."""
    keep, vol, _ = _elements(points, simplices)
    k = simplices.shape[1]
    local = (np.ones((k, k)) + np.eye(k)) / (k * (k + 1))
    return _assemble(len(points), simplices[keep], vol[:, None, None] * local[None])


def _mesh(dim, n, seed):
    """(points, simplices, interior nodes, h): the Delaunay mesh of a jittered lattice, about ``n`` interior nodes."""
    side = int(round(n ** (1.0 / dim))) + 2
    points, boundary = _points(dim, side, np.random.default_rng(seed))
    return points, Delaunay(points).simplices, np.flatnonzero(~boundary), 1.0 / (side - 1)


def _interior(A, inner) -> sp.csr_matrix:
    """``A`` on the ``inner`` nodes (the Dirichlet boundary eliminated), duplicates summed, indices sorted."""
    A = A[inner][:, inner].tocsr()
    A.sum_duplicates()
    A.sort_indices()
    return A


def p1_laplacian(dim, n, seed=0, frame=0) -> tuple:
    """(A, b): a P1 Laplacian with about ``n`` unknowns on unstructured triangles (``dim`` 2) or tets (3).

    ``seed`` makes the mesh; ``frame`` > 0 gives every element a log-normal conductivity (e^N(0, 1)) drawn from
    it, so frames of one mesh share the pattern and differ in values."""
    points, simplices, inner, _ = _mesh(dim, n, seed)
    kappa = np.exp(np.random.default_rng([seed, frame]).standard_normal(len(simplices))) if frame else None
    A = _interior(stiffness(points, simplices, kappa), inner)
    m = A.shape[0]
    return A, np.full(m, 1.0 / m)


def p1_heat(dim, n, steps=10.0, seed=0, frame=0) -> tuple:
    """(A, b): one backward-Euler step of the heat equation on :func:`p1_laplacian`'s mesh, A = M + dt K with the
    time step dt = ``steps`` h^2 (h the lattice spacing): a mass matrix's positive couplings beside the stiffness's
    negative ones, rows summing to the mass. ``frame`` > 0 scales dt by e^N(0, 0.25^2) (a step size control's new
    step: the pattern stays); b standard normal."""
    points, simplices, inner, h = _mesh(dim, n, seed)
    dt = steps * h * h * (np.exp(np.random.default_rng([seed, frame]).normal(0.0, 0.25)) if frame else 1.0)
    A = _interior(mass(points, simplices) + dt * stiffness(points, simplices), inner)
    return A, np.random.default_rng([seed, frame, 1]).standard_normal(A.shape[0])


def _hex_nodes(side) -> np.ndarray:
    """(elements, 8): the nodes of every hexahedron of a cube mesh with ``side`` nodes per edge (node (x, y, z) is
    number (x side + y) side + z), in the order (x, y, z) bits."""
    e = np.arange(side - 1)
    ex, ey, ez = np.meshgrid(e, e, e, indexing="ij")
    corner = (ex * side * side + ey * side + ez).ravel()
    bits = np.array([(i >> 2) * side * side + ((i >> 1) & 1) * side + (i & 1) for i in range(8)])
    return corner[:, None] + bits[None, :]


def _q1_element() -> np.ndarray:
    """The trilinear (Q1) hexahedron's 8 x 8 Laplacian stiffness on a unit cube, nodes in the order (x, y, z) bits:
    diagonal 1/3, edge neighbours 0, face diagonals -1/12, the opposite corner -1/12 (the unit cube's)."""
    k = np.empty((8, 8))
    for i in range(8):
        for j in range(8):
            differ = bin(i ^ j).count("1")
            k[i, j] = (1 / 3, 0.0, -1 / 12, -1 / 12)[differ]
    return k


def q1_laplacian(n, frame=0, contrast=None) -> tuple:
    """(A, b): a Q1 (trilinear hexahedra) Laplacian with about ``n`` unknowns on a uniform cube mesh, Dirichlet
    boundary nodes eliminated: 27-point rows, diagonal 8/3, the six axis neighbours 0 (stored zeros), twelve -1/6
    and eight -1/12, so no coupling reaches 1/16 of the diagonal (smoothed aggregation's measure).
    ``frame`` > 0 gives every element a log-normal conductivity (e^N(0, 1)); frames share the pattern. ``contrast``:
    in place of the log-normal field, the elements in 8 random balls (:func:`.gallery.balls`, drawn from ``frame``)
    take that conductivity, the others 1."""
    side = max(3, int(round(n ** (1.0 / 3.0)))) + 2            # nodes per edge, the two boundary layers included
    e = side - 1
    nodes = _hex_nodes(side)
    if contrast is not None:
        kappa = balls((e, e, e), contrast, frame, count=8).ravel()
    else:
        kappa = np.exp(np.random.default_rng(frame).standard_normal(len(nodes))) if frame else np.ones(len(nodes))
    vals = kappa[:, None, None] * _q1_element()[None, :, :]
    rows = np.repeat(nodes, 8, axis=1).ravel()
    cols = np.tile(nodes, (1, 8)).ravel()
    A = sp.csr_matrix((vals.ravel(), (rows, cols)), shape=(side ** 3,) * 2)
    A.sum_duplicates()
    x, y, z = np.meshgrid(*(np.arange(side),) * 3, indexing="ij")
    inner = np.flatnonzero(((x > 0) & (x < e) & (y > 0) & (y < e) & (z > 0) & (z < e)).ravel())
    A = A[inner][:, inner].tocsr()
    A.sort_indices()
    m = A.shape[0]
    return A, np.full(m, 1.0 / m)


def _q1_elasticity_element(E=1.0, nu=0.3) -> np.ndarray:
    """The trilinear hexahedron's 24 x 24 isotropic linear-elasticity stiffness on a unit cube (Young's modulus E,
    Poisson's ratio nu; 2 x 2 x 2 Gauss points), unknowns (u_x, u_y, u_z) node after node, nodes in the order
    (x, y, z) bits as :func:`_q1_element`."""
    lam, mu = E * nu / ((1 + nu) * (1 - 2 * nu)), E / (2 * (1 + nu))
    D = np.zeros((6, 6))
    D[:3, :3] = lam
    D[np.arange(6), np.arange(6)] += np.r_[2 * mu, 2 * mu, 2 * mu, mu, mu, mu]
    corner = np.array([[(i >> 2) & 1, (i >> 1) & 1, i & 1] for i in range(8)])
    sign = 2 * corner - 1
    pairs = ((3, 0, 1), (4, 1, 2), (5, 0, 2))                  # shear rows: (row, component a, component b)
    K = np.zeros((24, 24))
    for point in (np.array(q) for q in np.ndindex(2, 2, 2)):
        xi = (1 + (2 * point - 1) / np.sqrt(3)) / 2               # the Gauss point in [0, 1]^3
        f = np.where(corner == 1, xi, 1 - xi)                     # each node's 1-D factors there
        grad = sign * np.stack([f[:, 1] * f[:, 2], f[:, 0] * f[:, 2], f[:, 0] * f[:, 1]], 1)
        B = np.zeros((6, 24))
        for a in range(3):
            B[a, a::3] = grad[:, a]
        for row, a, b in pairs:
            B[row, a::3], B[row, b::3] = grad[:, b], grad[:, a]
        K += B.T @ D @ B / 8
    return K


def q1_elasticity(elements) -> tuple:
    """(A, B): 3-D linear elasticity on a cube of ``elements``^3 trilinear hexahedra (E = 1, nu = 0.3), the face x = 0
    clamped (its nodes eliminated), three unknowns per node node after node (block size 3; 81-entry rows inside),
    and its six rigid-body modes B (n, 6) (the translations, then the rotations), the near null space GAMG reads."""
    side = elements + 1
    nodes = _hex_nodes(side)
    dofs = (3 * nodes[:, :, None] + np.arange(3)).reshape(len(nodes), 24)
    K = _q1_elasticity_element()
    A = sp.csr_matrix((np.tile(K.ravel(), len(nodes)), (np.repeat(dofs, 24, axis=1).ravel(), np.tile(dofs, 24).ravel())),
                      shape=(3 * side ** 3,) * 2)
    A.sum_duplicates()
    x, y, z = (c.ravel().astype(np.float64) for c in np.meshgrid(*(np.arange(side),) * 3, indexing="ij"))
    free = np.flatnonzero(x > 0)
    keep = (3 * free[:, None] + np.arange(3)).ravel()
    A = A[keep][:, keep].tocsr()
    A.sort_indices()
    x, y, z = x[free], y[free], z[free]
    B = np.zeros((keep.size, 6))
    for a in range(3):
        B[a::3, a] = 1.0
    B[0::3, 3], B[1::3, 3] = -y, x
    B[1::3, 4], B[2::3, 4] = -z, y
    B[0::3, 5], B[2::3, 5] = z, -x
    return A, B
