"""AIJ matrices made from this rank's CSR arrays, which PETSc keeps as they are: no insertion row by row.

PETSc's ``MatCreateAIJ`` with a CSR (and ``MatCreateMPIAIJWithArrays``) sets the rows one by one: 90 ms for the
1024^2 5-point matrix on one rank, 80 ms for half of it on each of two ranks; ``MatCreateSeqAIJWithArrays`` takes
the arrays themselves (10 ms), ``MatCreateMPIAIJWithSplitArrays`` the diagonal block's and the rest's (13-30 ms on
two ranks). petsc4py's ``createAIJWithArrays`` calls them and keeps the arrays with the Mat.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from petsc4py import PETSc


def split(rows, start, stop):
    """This rank's ``rows`` (scipy CSR, global columns) as its diagonal block (columns ``start:stop``, numbered from
    ``start``) and the rest (global columns; None where there is none), each scipy CSR."""
    inside = (rows.indices >= start) & (rows.indices < stop)
    if inside.all():
        return sp.csr_matrix((rows.data, rows.indices - start if start else rows.indices, rows.indptr),
                             shape=(rows.shape[0], stop - start)), None
    n = rows.shape[0]
    own = np.zeros(rows.indices.size + 1, dtype=rows.indptr.dtype)
    np.cumsum(inside, out=own[1:])              # entries inside up to each one: at each row's start, the row pointer
    own = own[rows.indptr]
    diag = sp.csr_matrix((rows.data[inside], rows.indices[inside] - start, own), shape=(n, stop - start))
    off = sp.csr_matrix((rows.data[~inside], rows.indices[~inside], rows.indptr - own), shape=rows.shape)
    return diag, off


def aij(comm, sizes, diag, off=None) -> PETSc.Mat:
    """An AIJ matrix of ``sizes`` (PETSc's ((rows, global rows), (columns, global columns))) on ``comm`` whose rows on
    this rank are the scipy CSR ``diag`` (the diagonal block: this rank's columns, numbered from its first) and
    ``off`` (global columns outside them; None where there are none), whose arrays PETSc keeps (collective)."""
    (n, M), (m, N) = sizes
    if diag.shape != (n, m) or (off is not None and off.shape != (n, N)):
        raise ValueError(f"the blocks' shapes {diag.shape} and {None if off is None else off.shape} do not match this "
                         f"rank's {n} rows, {m} columns of {N}")
    if comm.getSize() == 1:
        return PETSc.Mat().createAIJWithArrays(sizes, _arrays(diag if off is None else diag + off), comm=comm)
    other = sp.csr_matrix((n, N)) if off is None else off
    return PETSc.Mat().createAIJWithArrays(sizes, (_arrays(diag), _arrays(other)), comm=comm)


def _arrays(block) -> tuple:
    """The CSR arrays of the scipy ``block`` in PETSc's types, its column indices sorted in each row."""
    if not block.has_sorted_indices:
        block.sort_indices()
    return (block.indptr.astype(PETSc.IntType, copy=False), block.indices.astype(PETSc.IntType, copy=False),
            np.ascontiguousarray(block.data, dtype=PETSc.ScalarType))
