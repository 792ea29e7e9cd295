"""The variable-coefficient Poisson problem of a plain PETSc DMDA program (``examples/dmda_poisson.py``, the ``scale``
study's worker :mod:`petsc_htp.bench.dmdarun`): the 5-point (2-D) or 7-point (3-D) operator of
:func:`.gallery.inclusions` (discs) or :func:`.gallery.balls` of conductivity ``contrast`` in a unit conductivity,
harmonic means on the faces, homogeneous Dirichlet boundaries, on a DMDA's grid and in its numbering.

Each rank sets its own rows by whole arrays (DMDA's application ordering gives the neighbours' global numbers): a
loop over two million cells would take minutes. New values of another ``seed`` go into the same Mat (its pattern:
the DMDA's stencil), as a simulation's next frame.
"""
from __future__ import annotations

import numpy as np
from petsc4py import PETSc

from .gallery import balls, face_weights, inclusions


def grid(side, dim) -> PETSc.DMDA:
    """A ``side``^``dim`` DMDA (star stencil of width 1) over every rank of COMM_WORLD."""
    if dim not in (2, 3):
        raise ValueError(f"the DMDA problem is 2-D or 3-D, got dim {dim}")
    da = PETSc.DMDA().create([side] * dim, stencil_width=1, stencil_type=PETSc.DMDA.StencilType.STAR)
    da.setUp()
    return da


def conductivity(shape, contrast, seed) -> np.ndarray:
    """The cell conductivity on ``shape`` ((ny, nx) or (nz, ny, nx)): discs in 2-D, balls in 3-D."""
    return inclusions(shape[1], shape[0], contrast, seed) if len(shape) == 2 else balls(shape, contrast, seed)


def stencil(da, contrast, seed) -> tuple:
    """This rank's rows of the operator as (the natural index of each of its cells, in the order of its rows;
    columns; values): the columns in the DMDA's (PETSc's) numbering and values one row per cell and one column per
    stencil point (-1 where it falls outside the grid)."""
    shape = tuple(da.getSizes())[::-1]                                   # (nz,) ny, nx
    *weights, edge = face_weights(conductivity(shape, contrast, seed))
    cell = [c.ravel() for c in np.meshgrid(*[np.arange(lo, hi) for lo, hi in da.getRanges()[::-1]], indexing="ij")]
    diag = edge[tuple(cell)]
    cols, vals = [], []
    for axis, w in zip(range(len(shape) - 1, -1, -1), weights):        # x (the last axis) first
        for step in (-1, 1):
            other = list(cell)
            other[axis] = cell[axis] + step
            inside = (other[axis] >= 0) & (other[axis] < shape[axis])
            face = list(cell)
            face[axis] = np.clip(np.minimum(cell[axis], other[axis]), 0, shape[axis] - 2)
            weight = np.where(inside, w[tuple(face)], 0.0)
            diag = diag + weight
            other[axis] = np.clip(other[axis], 0, shape[axis] - 1)
            cols.append(np.where(inside, np.ravel_multi_index(tuple(other), shape), -1))
            vals.append(-weight)
    rows = np.ravel_multi_index(tuple(cell), shape)
    cols, vals = np.stack(cols + [rows], 1), np.stack(vals + [diag], 1)
    mapped = da.getAO().app2petsc(np.where(cols >= 0, cols, 0).astype(PETSc.IntType).ravel()).reshape(cols.shape)
    return rows, np.where(cols >= 0, mapped, -1), vals


def operator(da, contrast=1000.0, seed=0, mat=None) -> PETSc.Mat:
    """The operator on ``da``'s grid (into ``mat``, a Mat of :func:`operator` before: new values, same pattern),
    flagged symmetric; nothing else attached."""
    rows, cols, vals = stencil(da, contrast, seed)
    A = da.createMat() if mat is None else mat
    first = A.getOwnershipRange()[0]
    live = cols >= 0
    indptr = np.concatenate(([0], np.cumsum(live.sum(1)))).astype(PETSc.IntType)
    A.setValuesIJV(indptr, cols[live].astype(PETSc.IntType), vals[live],
                   rowmap=np.arange(first, first + rows.size, dtype=PETSc.IntType))
    A.assemble()
    A.setOption(PETSc.Mat.Option.SYMMETRIC, True)          # new values unset it
    return A


def source(A, cells) -> PETSc.Vec:
    """The right-hand side: a unit source times the cell volume (1 / ``cells``) in every cell."""
    b = A.createVecLeft()
    b.set(1.0 / float(cells))
    return b
