"""SPD matrices as other programs assemble them: the families of the benchmark's ``foreign`` study.

None of these comes from this project's generator, and none is shaped for the preconditioner: each is what a
PETSc user, a liquid simulation or a finite-element code hands over. Every function returns ``(A, b)``
(scipy CSR with sorted indices, a right-hand side) and is deterministic for its ``seed``. PETSc-free.

- :func:`dmda`: 5/7-point variable-coefficient Poisson on a DMDA's node grid, the outer layer Dirichlet rows
  stored as identity rows whose couplings stay as explicit zeros (in both directions), as a DMDA matrix keeps
  its stencil pattern.
- :func:`free_surface`: a liquid's pressure, air cells eliminated with a ghost-fluid diagonal, solid walls,
  liquid cells in row-major order; the liquid moves with ``frame``, so the pattern changes every frame.
- :func:`anisotropic`: rotated anisotropic diffusion, 9-point (PyAMG's stencil), Dirichlet boundaries.
- :func:`lognormal`: 5-point Poisson with a log-normal permeability of the given contrast.
- :func:`neumann`: 5-point variable coefficients with no-flux walls (singular; the constant is its null space).
- :func:`cubes`: 3-D finite volumes with random cubes of a high conductivity.
- :func:`cells`: the 5/7-point operator of given cell conductivities, Dirichlet walls or no flux.
- :func:`pockets`: a closed 2-D domain holding sealed pockets, each a null component of its own (singular).
- :mod:`petsc_htp.scenes.meshes`: P1 finite elements on unstructured triangles and tets.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from .gallery import balls, inclusions


def _csr(rows, cols, vals, n) -> sp.csr_matrix:
    """A CSR matrix from triplets, duplicates summed, explicit zeros kept, indices sorted."""
    A = sp.csr_matrix((vals, (rows, cols)), shape=(n, n))
    A.sum_duplicates()
    A.sort_indices()
    return A


def _field(shape, contrast, seed) -> np.ndarray:
    """Cell conductivity on a grid of ``shape`` (2-D or 3-D): 1 with random balls of ``contrast``."""
    if len(shape) == 2:
        return inclusions(shape[1], shape[0], contrast, seed)
    return balls(shape, contrast, seed)


def _faces(k):
    """For each axis: (lower cell ids, upper cell ids, harmonic-mean conductances) of a grid's interior faces."""
    idx = np.arange(k.size).reshape(k.shape)
    out = []
    for axis in range(k.ndim):
        lo = [slice(None)] * k.ndim
        hi = [slice(None)] * k.ndim
        lo[axis], hi[axis] = slice(None, -1), slice(1, None)
        a, c = k[tuple(lo)], k[tuple(hi)]
        out.append((idx[tuple(lo)].ravel(), idx[tuple(hi)].ravel(), (2 * a * c / (a + c)).ravel()))
    return out


def dmda(dim, side, contrast=1e3, seed=0) -> tuple:
    """A DMDA program's matrix on ``side``^``dim`` nodes: the outer layer identity rows, couplings to them zero.

    Interior rows hold the 5- (7-) point harmonic-mean stencil of a conductivity of 1 with balls of ``contrast``;
    a coupling between an interior and a boundary node is stored as an explicit zero in both rows (its value
    went to the right-hand side), and each boundary row stores its whole stencil with zeros off the diagonal.
    """
    shape = (side,) * dim
    k = _field(shape, contrast, seed)
    n = k.size
    boundary = np.zeros(shape, dtype=bool)
    for axis in range(dim):
        index = [slice(None)] * dim
        for end in (0, -1):
            index[axis] = end
            boundary[tuple(index)] = True
    boundary = boundary.ravel()
    rows, cols, vals = [np.arange(n)], [np.arange(n)], [np.zeros(n)]
    diag = np.zeros(n)
    for i, j, w in _faces(k):
        live = ~boundary[i] & ~boundary[j]
        w = np.where(live, w, 0.0)
        np.add.at(diag, i, np.where(boundary[j], 0.0, w))      # a Dirichlet neighbour: its coupling stays in
        np.add.at(diag, j, np.where(boundary[i], 0.0, w))
        bi, bj = boundary[i] & ~boundary[j], boundary[j] & ~boundary[i]
        np.add.at(diag, i, np.where(bj, 2 * k.ravel()[i], 0.0))   # ... the diagonal, its value on the rhs
        np.add.at(diag, j, np.where(bi, 2 * k.ravel()[j], 0.0))
        rows += [i, j]
        cols += [j, i]
        vals += [-w, -w]
    diag[boundary] = 1.0
    vals[0] = diag
    A = _csr(np.concatenate(rows), np.concatenate(cols), np.concatenate(vals), n)
    b = np.where(boundary, 0.0, 1.0 / n)
    return A, b


def _grid5(k) -> tuple:
    """(rows, cols, vals, diag) of a 2-D 5-point (3-D 7-point) operator on conductivity ``k``, no-flux walls."""
    rows, cols, vals = [], [], []
    diag = np.zeros(k.size)
    for i, j, w in _faces(k):
        rows += [i, j]
        cols += [j, i]
        vals += [-w, -w]
        np.add.at(diag, i, w)
        np.add.at(diag, j, w)
    return rows, cols, vals, diag


def lognormal(side, contrast=1e10, seed=0) -> tuple:
    """5-point Poisson on ``side``^2 cells with a smooth log-normal permeability spanning about ``contrast``,
    Dirichlet boundaries (SPD)."""
    rng = np.random.default_rng(seed)
    g = rng.standard_normal((side, side))
    freq = np.fft.fftfreq(side)
    kx, ky = np.meshgrid(freq, freq)
    g = np.real(np.fft.ifft2(np.fft.fft2(g) * np.exp(-(kx ** 2 + ky ** 2) * (side / 8.0) ** 2)))
    g = (g - g.mean()) / (g.std() + 1e-300)
    k = np.exp(g / np.ptp(g) * np.log(contrast))
    rows, cols, vals, diag = _grid5(k)
    edge = np.zeros((side, side))
    edge[:, 0] += 2 * k[:, 0]
    edge[:, -1] += 2 * k[:, -1]
    edge[0, :] += 2 * k[0, :]
    edge[-1, :] += 2 * k[-1, :]
    n = side * side
    A = _csr(np.concatenate(rows + [np.arange(n)]), np.concatenate(cols + [np.arange(n)]),
             np.concatenate(vals + [diag + edge.ravel()]), n)
    return A, np.full(n, 1.0 / n)


def cells(k, walls=True) -> sp.csr_matrix:
    """The 5-point (7-point) harmonic-mean operator of the cell conductivities ``k`` (2-D or 3-D): Dirichlet walls
    half a cell outside (each wall face adds 2 k to its cell's diagonal) or, ``walls`` False, no flux."""
    rows, cols, vals, diag = _grid5(k)
    n = k.size
    if walls:
        for axis in range(k.ndim):
            for face in (0, k.shape[axis] - 1):
                wall = [slice(None)] * k.ndim
                wall[axis] = face
                diag[np.arange(n).reshape(k.shape)[tuple(wall)].ravel()] += 2 * k[tuple(wall)].ravel()
    return _csr(np.concatenate(rows + [np.arange(n)]), np.concatenate(cols + [np.arange(n)]),
                np.concatenate(vals + [diag]), n)


def neumann(side, contrast=1e3, seed=0) -> tuple:
    """5-point variable coefficients with no-flux walls on every side: singular, its null space the constant.
    The right-hand side has zero mean (consistent)."""
    A = cells(inclusions(side, side, contrast, seed), walls=False)
    b = np.random.default_rng(seed).standard_normal(side * side)
    return A, b - b.mean()


def pockets(side, every, size=3, seed=1, extra=()) -> tuple:
    """A closed domain of ``side``^2 cells, 5-point couplings of random weight (0.5 .. 2), Dirichlet walls, holding
    pockets of ``size``^2 cells every ``every`` cells from (8, 8) and at the corners ``extra``, coupled to nothing
    else: each a null component of its own (singular, handed over bare); b random with zero mean on each pocket
    (consistent)."""
    rng = np.random.default_rng(seed)
    cell, pocket = np.arange(side * side).reshape(side, side), np.full((side, side), -1)
    corners = [(i, j) for i in range(8, side - 8, every) for j in range(8, side - 8, every)] + list(extra)
    for k, (i, j) in enumerate(corners):
        pocket[i:i + size, j:j + size] = k
    rows, cols, vals = [], [], []
    for di, dj in ((0, 1), (1, 0)):
        a, b = cell[:side - di, :side - dj].ravel(), cell[di:, dj:].ravel()
        w = np.where(pocket.ravel()[a] == pocket.ravel()[b], rng.uniform(0.5, 2.0, a.size), 0.0)
        rows += [a, b, a, b]
        cols += [b, a, a, b]
        vals += [-w, -w, w, w]
    edge = np.isin(np.arange(side), (0, side - 1))
    A = sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(side * side,) * 2)
    A = (A + sp.diags(2.0 * (edge[:, None] | edge[None, :]).ravel())).tocsr()
    A.eliminate_zeros()
    A.sort_indices()
    b = rng.standard_normal(side * side)
    label = pocket.ravel()
    mean = np.bincount(label + 1, b) / np.maximum(np.bincount(label + 1), 1)
    return A, np.where(label >= 0, b - mean[label + 1], b)


def cubes(side, contrast=1e6, count=60, seed=5) -> tuple:
    """Cell-centred finite volumes on ``side``^3 cells, conductivity 1 with ``count`` random cubes of 5^3 cells at
    ``contrast`` (harmonic face means), Dirichlet walls (SPD); b = A x for a random x."""
    rng = np.random.default_rng(seed)
    k = np.ones((side,) * 3)
    for i, j, m in rng.integers(0, side - 6, (count, 3)):
        k[i:i + 5, j:j + 5, m:m + 5] = contrast
    A = cells(k)
    return A, A @ np.random.default_rng(1).standard_normal(k.size)


def anisotropic(side, eps=0.01, angle=np.pi / 6, frame=0) -> tuple:
    """Rotated anisotropic diffusion (``eps``, ``angle``) on ``side``^2 nodes: PyAMG's 9-point FD stencil,
    Dirichlet boundaries; ``frame`` turns the angle by 0.02 rad a frame (same pattern, new values)."""
    from pyamg.gallery import diffusion_stencil_2d, stencil_grid

    stencil = diffusion_stencil_2d(epsilon=eps, theta=angle + 0.02 * frame, type="FD")
    A = stencil_grid(stencil, (side, side), format="csr")
    A.sort_indices()
    return A, np.full(side * side, 1.0 / (side * side))


def free_surface(side, frame=0, seed=0) -> tuple:
    """A liquid's pressure matrix on a ``side``^2 box at ``frame``: a sloshing pool and a falling drop.

    Liquid cells are the unknowns, in row-major order; a face to a solid wall carries no flux; a face to an air
    cell adds w / theta to the diagonal (ghost fluid: theta, the liquid fraction of the face's distance to the
    surface, at least 0.01). The liquid moves with ``frame``, so each frame has its own pattern.
    """
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[0:side, 0:side]
    x, y = (x + 0.5) / side, (y + 0.5) / side
    t = 0.05 * frame
    phase = rng.uniform(0, 2 * np.pi, 3)
    height = 0.45 + 0.08 * np.sin(2 * np.pi * x + 3 * t + phase[0]) + 0.03 * np.sin(6 * np.pi * x - 5 * t + phase[1])
    cx, cy = 0.3 + 0.4 * rng.random(), 0.85 - 0.3 * t % 0.35
    phi = np.minimum(y - height, np.hypot(x - cx, y - cy) - 0.08)       # < 0 in the liquid
    liquid = phi < 0
    ids = -np.ones(side * side, dtype=np.int64)
    ids[liquid.ravel()] = np.arange(int(liquid.sum()))
    n = int(liquid.sum())
    cell = np.arange(side * side).reshape(side, side)
    rows, cols, vals = [], [], []
    diag = np.zeros(n)
    flat = phi.ravel()
    for a, c in ((cell[:, :-1], cell[:, 1:]), (cell[:-1, :], cell[1:, :])):
        a, c = a.ravel(), c.ravel()
        for p, q in ((a, c), (c, a)):
            lp, lq = ids[p] >= 0, ids[q] >= 0
            both = lp & lq
            rows.append(ids[p[both]])
            cols.append(ids[q[both]])
            vals.append(-np.ones(int(both.sum())))
            np.add.at(diag, ids[p[both]], 1.0)
            air = lp & ~lq
            theta = np.maximum(flat[p[air]] / (flat[p[air]] - flat[q[air]]), 0.01)
            np.add.at(diag, ids[p[air]], 1.0 / theta)
    A = _csr(np.concatenate(rows + [np.arange(n)]), np.concatenate(cols + [np.arange(n)]),
             np.concatenate(vals + [diag]), n)
    b = rng.standard_normal(n) / side
    return A, b


def pyamg_examples() -> dict:
    """PyAMG's shipped example matrices that are symmetric with a positive diagonal (name -> CSR); unit_square is
    singular (a Neumann Laplacian), the others SPD."""
    from pyamg.gallery import load_example

    out = {}
    for name in ("airfoil", "bar", "knot", "local_disc_galerkin_diffusion", "unit_cube", "unit_square"):
        A = sp.csr_matrix(load_example(name)["A"], dtype=np.float64)
        A.sort_indices()
        if abs(A - A.T).max() <= 1e-12 * abs(A).max() and np.all(A.diagonal() > 0):
            out[name] = A
    return out
