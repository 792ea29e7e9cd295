"""AIJ matrices made from this rank's CSR arrays, which PETSc keeps as they are: no insertion row by row.

PETSc's ``MatCreateAIJ`` with a CSR (and ``MatCreateMPIAIJWithArrays``) sets the rows one by one: 90 ms for the
1024^2 5-point matrix on one rank, 80 ms for half of it on each of two ranks; ``MatCreateSeqAIJWithArrays`` takes
the arrays themselves (10 ms), and ``MatCreateMPIAIJWithSeqAIJ`` joins two such blocks into an MPIAIJ (3 ms).
"""
from __future__ import annotations

import ctypes

import numpy as np
import scipy.sparse as sp
from petsc4py import PETSc

from .petscmat import _c_api

_SLOT = "petsc_htp_made"        # the name a made MPIAIJ is composed under for a moment, to wrap its handle


def split(rows, start, stop):
    """This rank's ``rows`` (scipy CSR, global columns) as its diagonal block (columns ``start:stop``, numbered from
    ``start``) and the rest (global columns; None where there is none), each scipy CSR."""
    inside = (rows.indices >= start) & (rows.indices < stop)
    if inside.all():
        return sp.csr_matrix((rows.data, rows.indices - start if start else rows.indices, rows.indptr),
                             shape=(rows.shape[0], stop - start)), None
    n = rows.shape[0]
    row = np.repeat(np.arange(n), np.diff(rows.indptr))
    own = np.zeros(n + 1, dtype=np.int64)
    np.cumsum(np.bincount(row[inside], minlength=n), out=own[1:])
    diag = sp.csr_matrix((rows.data[inside], rows.indices[inside] - start, own), shape=(n, stop - start))
    off = sp.csr_matrix((rows.data[~inside], rows.indices[~inside], rows.indptr - own), shape=rows.shape)
    return diag, off


def aij(comm, sizes, diag, off=None) -> PETSc.Mat:
    """An AIJ matrix of ``sizes`` (PETSc's ((rows, global rows), (columns, global columns))) on ``comm`` whose rows on
    this rank are the scipy CSR ``diag`` (the diagonal block: this rank's columns, numbered from its first) and
    ``off`` (global columns outside them; None where there are none). Collective."""
    (n, M), (m, N) = sizes
    if diag.shape != (n, m) or (off is not None and off.shape != (n, N)):
        raise ValueError(f"the blocks' shapes {diag.shape} and {None if off is None else off.shape} do not match this "
                         f"rank's {n} rows, {m} columns of {N}")
    if comm.getSize() == 1:
        return _seq(diag if off is None else diag + off, comm)
    seq = _seq(diag)
    other = _seq(sp.csr_matrix((n, N)) if off is None else off)
    lib, it = _c_api()
    for block in (seq, other):
        block.incRef()                  # the MPIAIJ takes both blocks without a reference of its own
    made = ctypes.c_void_p()
    if lib.MatCreateMPIAIJWithSeqAIJ(_c_comm(comm), it(M), it(N), ctypes.c_void_p(seq.handle),
                                     ctypes.c_void_p(other.handle), None, ctypes.byref(made)):
        raise RuntimeError("PETSc's MatCreateMPIAIJWithSeqAIJ failed")
    return _wrapped(made)


def _c_comm(comm):
    """The C MPI_Comm of the PETSc ``comm`` as a ctypes value (an int in MPICH, a pointer in Open MPI)."""
    from mpi4py import MPI

    handle = MPI._handleof(comm.tompi4py())
    return (ctypes.c_int if MPI._sizeof(MPI.Comm) == ctypes.sizeof(ctypes.c_int) else ctypes.c_void_p)(handle)


def _seq(block, comm=PETSc.COMM_SELF) -> PETSc.Mat:
    """A SEQAIJ on ``comm`` (of one rank) on the arrays of the scipy CSR ``block`` (column indices sorted in each row;
    PETSc's integer type)."""
    if not block.has_sorted_indices:
        block.sort_indices()
    arrays = (block.indptr.astype(PETSc.IntType, copy=False), block.indices.astype(PETSc.IntType, copy=False),
              np.ascontiguousarray(block.data, dtype=PETSc.ScalarType))
    return PETSc.Mat().createAIJWithArrays(block.shape, arrays, comm=comm)


def _wrapped(made) -> PETSc.Mat:
    """A petsc4py Mat for the C Mat at ``made``, which then holds its only reference: composed on a scratch object
    for a moment and queried back (petsc4py makes no wrapper from a bare handle)."""
    lib = _c_api()[0]
    scratch = PETSc.Mat()
    scratch.create(PETSc.COMM_SELF)
    name = _SLOT.encode()
    lib.PetscObjectCompose(ctypes.c_void_p(scratch.handle), name, made)
    mat = scratch.query(_SLOT)
    scratch.destroy()                   # drops the composed reference
    lib.PetscObjectDereference(made)    # and the one MatCreateMPIAIJWithSeqAIJ made: the wrapper holds the last
    return mat
