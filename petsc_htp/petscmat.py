"""The PETSc side of the data: geometry attached to a Mat, a sequential Mat read as scipy CSR and its values written."""
from __future__ import annotations

import contextlib
import ctypes
import functools
import itertools
import math

import numpy as np
import scipy.sparse as sp
from petsc4py import PETSc

from .collective import Collective
from .twolevel.nullspace import null_regions

__all__ = ["attach", "attached", "read_csr", "aij_operator", "frame_mat", "frame_vec", "region_nullspace",
           "preallocated_aij", "local_csr", "gathered", "ghost_values"]

COORDS_ATTR = "petsc_htp_coords"
DENSITY_ATTR = "petsc_htp_density"
VERSION_ATTR = "petsc_htp_attached"     # bumped by every attach()
_ATTACHED = itertools.count(1)


def _local_rows(mat, values, what, width):
    """Rows of ``values`` owned by this rank of ``mat`` (given global or local arrays)."""
    arr = np.ascontiguousarray(values, dtype=np.float64)
    n_global = mat.getSize()[0]
    start, end = mat.getOwnershipRange()
    shape_tail = () if width is None else (width,)
    if arr.shape == (n_global, *shape_tail):
        return arr[start:end].copy()
    if arr.shape == (end - start, *shape_tail):
        return arr.copy()
    raise ValueError(f"{what} must have shape ({n_global}{', %d' % width if width else ''}) (global) or "
                     f"({end - start}{', %d' % width if width else ''}) (this rank's rows), got {arr.shape}")


def attach(mat, coords=None, density=None):
    """Store per-row geometry on a PETSc Mat for :class:`HTPPC`.

    Parameters
    ----------
    mat : petsc4py.PETSc.Mat
        The preconditioning matrix (sequential or distributed AIJ).
    coords : array_like, shape (N, d) or (n_local, d), d = 2 or 3, optional
        Point coordinates of the rows (global array, or this rank's rows).
        With coordinates HTP uses the Morton ordering (or keeps rows already in
        Morton order) and geometric features.
    density : array_like, shape (N,) or (n_local,), optional
        Per-row density (material coefficient) feature.

    The arrays are kept with ``Mat.setAttr`` in the PETSc object's own Python
    dictionary, so they survive new Python wrappers of the same Mat (e.g. the
    one ``pc.getOperators()`` returns). For a parallel matrix this rank's rows
    are also attached to its diagonal block (``Mat.getDiagonalBlock``), which
    is the matrix PETSc's one-block-per-rank block Jacobi hands to a
    ``-sub_pc_type python -sub_pc_python_type petsc_htp.HTPPC``. Sub-matrices
    that PETSc extracts itself (several blocks per rank) carry nothing, and HTP
    falls back to matrix-only features and RCM there. Passing ``None`` removes
    a previously attached array. The Mat's object state is increased, so a KSP
    that was already set up runs HTP's setup again at its next solve. Call it
    on every rank of a parallel matrix. Returns ``mat``.
    """
    local = {}
    dim = 3 if coords is not None and np.ndim(coords) == 2 and np.shape(coords)[1] == 3 else 2
    for attr, values, what, width in ((COORDS_ATTR, coords, "coords", dim), (DENSITY_ATTR, density, "density", None)):
        local[attr] = None if values is None else _local_rows(mat, values, what, width)
        if local[attr] is not None and not np.all(np.isfinite(local[attr])):
            raise ValueError(f"{what} must be finite")
    targets = [mat]
    if mat.getComm().getSize() > 1:
        try:
            targets.append(mat.getDiagonalBlock())
        except PETSc.Error:
            pass
    version = next(_ATTACHED)
    for target in targets:
        for attr, arr in local.items():
            target.setAttr(attr, arr)
        target.setAttr(VERSION_ATTR, version)
        target.stateIncrease()          # PETSc then sets up the preconditioner again
    return mat


def attached(mat):
    """(coords, density) stored by :func:`attach` on ``mat``, each possibly None."""
    return mat.getAttr(COORDS_ATTR), mat.getAttr(DENSITY_ATTR)


@contextlib.contextmanager
def local_rows(mat, copy=False):
    """This rank's rows of ``mat`` as scipy CSR (global columns) for the duration of the block.

    For a sequential AIJ matrix and ``copy=False`` the arrays are views of PETSc's own (through its C API:
    no copy of the matrix per frame), for an MPIAIJ one views of its merged local rows (:func:`_mpiaij_local`);
    they must not be kept past the block; otherwise :func:`read_csr`'s copy.
    """
    kind = mat.getType()
    if copy or kind not in ("seqaij", "mpiaij"):
        yield read_csr(mat)
        return
    if kind == "mpiaij":
        with _mpiaij_local(mat) as rows:
            yield rows
        return
    with _seqaij_view(mat.handle, mat.getSize()) as rows:
        yield rows


@contextlib.contextmanager
def _seqaij_view(handle, shape):
    """The SEQAIJ Mat at the C pointer ``handle`` as scipy CSR of ``shape`` on views of PETSc's arrays."""
    lib, it = _c_api()
    handle = ctypes.c_void_p(handle)
    n, ia, ja, done = it(), ctypes.POINTER(it)(), ctypes.POINTER(it)(), ctypes.c_int()
    values = ctypes.POINTER(ctypes.c_double)()
    ij = (handle, it(0), ctypes.c_int(0), ctypes.c_int(0), ctypes.byref(n), ctypes.byref(ia), ctypes.byref(ja),
          ctypes.byref(done))
    if lib.MatGetRowIJ(*ij) or not done.value or lib.MatSeqAIJGetArrayRead(handle, ctypes.byref(values)):
        raise RuntimeError("PETSc's MatGetRowIJ / MatSeqAIJGetArrayRead failed on a seqaij matrix")
    try:
        indptr = np.ctypeslib.as_array(ia, shape=(n.value + 1,))
        nnz = int(indptr[-1])
        yield sp.csr_matrix((np.ctypeslib.as_array(values, shape=(nnz,)) if nnz else np.zeros(0),
                             np.ctypeslib.as_array(ja, shape=(nnz,)) if nnz else np.zeros(0, dtype=indptr.dtype),
                             indptr), shape=shape)
    finally:
        lib.MatSeqAIJRestoreArrayRead(handle, ctypes.byref(values))
        lib.MatRestoreRowIJ(*ij)


@contextlib.contextmanager
def seqaij_values(mat):
    """The stored values of the SEQAIJ ``mat`` as a writable view of PETSc's array for the duration of the block;
    the Mat's state is raised at its end (MatSeqAIJRestoreArray: its SOR diagonal is then found again)."""
    if mat.getType() != "seqaij":
        raise TypeError(f"seqaij_values takes a seqaij matrix, not {mat.getType()}")
    lib = _c_api()[0]
    handle, values = ctypes.c_void_p(mat.handle), ctypes.POINTER(ctypes.c_double)()
    if lib.MatSeqAIJGetArray(handle, ctypes.byref(values)):
        raise RuntimeError("PETSc's MatSeqAIJGetArray failed on a seqaij matrix")
    try:
        nnz = int(mat.getInfo()["nz_used"])
        yield np.ctypeslib.as_array(values, shape=(nnz,)) if nnz else np.zeros(0)
    finally:
        if lib.MatSeqAIJRestoreArray(handle, ctypes.byref(values)):
            raise RuntimeError("PETSc's MatSeqAIJRestoreArray failed on a seqaij matrix")


def _mpiaij_rows(mat) -> sp.csr_matrix:
    """This rank's rows of the MPIAIJ ``mat`` (global columns, sorted), a copy of :func:`_mpiaij_local`'s: 15 ms for
    half the 1024^2 5-point matrix on each of two ranks, against 31 for petsc4py's row-by-row getValuesCSR."""
    with _mpiaij_local(mat) as rows:
        return sp.csr_matrix((rows.data.copy(), rows.indices.copy(), rows.indptr.copy()), shape=rows.shape)


@contextlib.contextmanager
def _mpiaij_local(mat):
    """This rank's rows of the MPIAIJ ``mat`` (global columns, sorted) as scipy CSR on views of the SEQAIJ matrix
    MatMPIAIJGetLocalMat merges them into, freed at the end of the block (no copy of its arrays: at 1M rows on two
    ranks the five reads of a setup took 61 ms with them)."""
    lib = _c_api()[0]
    local = ctypes.c_void_p()
    if lib.MatMPIAIJGetLocalMat(ctypes.c_void_p(mat.handle), ctypes.c_int(0), ctypes.byref(local)):   # INITIAL
        raise RuntimeError("PETSc's MatMPIAIJGetLocalMat failed on an mpiaij matrix")
    try:
        start, end = mat.getOwnershipRange()
        with _seqaij_view(local.value, (end - start, mat.getSize()[1])) as rows:
            yield rows
    finally:
        lib.MatDestroy(ctypes.byref(local))


@contextlib.contextmanager
def diagonal_block(mat, rows):
    """This rank's diagonal block of ``mat`` (its own rows and columns) as scipy CSR for the duration of the block:
    ``rows`` (this rank's rows, :func:`local_rows`) on one rank, else the MPIAIJ's own diagonal block, by
    :func:`local_rows` (a view of PETSc's arrays where it is SEQAIJ: no column slicing of ``rows``)."""
    if mat.getComm().getSize() == 1:
        yield rows
        return
    with local_rows(mat.getDiagonalBlock()) as block:
        yield block


def post_solve(pc, ksp) -> None:
    """PETSc's PCPostSolve, for a preSolve that raises: PETSc counts a PC's presolves and lowers the count only there,
    which a KSPSolve that stops with an error skips, so two such errors left the KSP refusing every later solve
    ("Cannot embed PCPreSolve() more than twice")."""
    _c_api()[0].PCPostSolve(ctypes.c_void_p(pc.handle), ctypes.c_void_p(ksp.handle))


@functools.lru_cache(maxsize=1)
def _c_api():
    """PETSc's C library (reached through petsc4py's extension module) and the ctypes type of PetscInt."""
    return ctypes.CDLL(PETSc.__file__), (ctypes.c_int32 if np.dtype(PETSc.IntType).itemsize == 4 else ctypes.c_int64)


def _aij_type(mat) -> str:
    """The AIJ type for ``mat``'s communicator."""
    return "mpiaij" if mat.getComm().getSize() > 1 else "seqaij"


def _converted(mat) -> PETSc.Mat:
    """``mat`` converted to a new AIJ (MPISBAIJ from its upper triangle: :func:`_symmetric`), or a ValueError that
    names its type."""
    try:
        out = mat.convert(_aij_type(mat), out=PETSc.Mat())
    except PETSc.Error as exc:
        raise ValueError(f"HTPPC needs an assembled matrix that converts to AIJ; cannot convert a "
                         f"'{mat.getType()}' matrix to {_aij_type(mat)}") from exc
    return _symmetric(out, mat) if mat.getType() == "mpisbaij" else out


def _symmetric(converted, mat) -> PETSc.Mat:
    """U + U^T for U the upper triangle of ``converted`` (freed), the AIJ copy of the MPISBAIJ ``mat``, its diagonal
    halved, whose entries within a rank's diagonal block come from that block's own conversion: PETSc's MPI
    conversion reads the diagonal bs x bs blocks of a matrix set from its upper triangle wrongly (both halves; the
    block's own the lower halves; a SEQSBAIJ matrix of its own converts rightly), where SBAIJ's products read them
    rightly (3-D elasticity of 46 800 rows, 3x3 blocks, 2 ranks: CG stopped at 3 000 iterations, the relative
    residual 1.6e-2, against 34 as AIJ)."""
    lo, hi = mat.getOwnershipRange()
    shape = (hi - lo, mat.getSize()[1])
    indptr, indices, data = converted.getValuesCSR()
    converted.destroy()
    block = mat.getDiagonalBlock().convert("seqaij", out=PETSc.Mat())
    bi, bj, bv = block.getValuesCSR()
    block.destroy()
    row = np.repeat(np.arange(hi - lo), np.diff(indptr))
    out = (indices < lo) | (indices >= hi)
    inside = np.repeat(np.arange(hi - lo), np.diff(bi))             # one COO of both (an addition drops zeros)
    rows = sp.coo_matrix((np.concatenate([data[out], bv]), (np.concatenate([row[out], inside]),
                                                             np.concatenate([indices[out], bj + lo]))),
                         shape=shape).tocsr()
    upper = sp.triu(rows, k=lo, format="csr")
    upper.sort_indices()
    upper.data[upper.indices == np.repeat(np.arange(hi - lo), np.diff(upper.indptr)) + lo] *= 0.5   # no new entry
    U = PETSc.Mat().createAIJ(mat.getSizes(), bsize=mat.getBlockSize(), comm=mat.getComm(),
                              csr=(upper.indptr.astype(PETSc.IntType), upper.indices.astype(PETSc.IntType), upper.data))
    full = U.transpose(PETSc.Mat())
    full.axpy(1.0, U, PETSc.Mat.Structure.DIFFERENT_NONZERO_PATTERN)
    U.destroy()
    return full


def aij_operator(mat, previous=None) -> PETSc.Mat:
    """``mat`` itself when it is its communicator's AIJ, else an AIJ copy of it (BAIJ, SBAIJ: both triangles; MPIAIJ
    on one rank, whose products with the coarse space's SEQAIJ PETSc does not support) with its null spaces,
    near null space and known symmetry: PETSc's sparse products take AIJ only. ``previous``, an earlier copy, takes
    the new values when its pattern is the same on every rank (the same Mat: the analysis is reused; a pattern grown
    within one rank had left the ranks on two Mats, and they hung); otherwise a new copy comes
    back and ``previous`` is left to the caller (an analysis may still hold it). (PETSc's own MAT_REUSE_MATRIX
    conversion from SBAIJ left a factor of the copy reading freed memory.)"""
    if mat.getType() == _aij_type(mat):
        return mat
    out = _converted(mat)
    same = previous is not None and all(np.array_equal(a, b) for a, b in zip(out.getRowIJ(), previous.getRowIJ()))
    if previous is not None and not Collective(mat.getComm()).any(not same):     # on every rank, or on none
        out.copy(previous, PETSc.Mat.Structure.SAME_NONZERO_PATTERN)
        out.destroy()
        out = previous
    out.setNullSpace(mat.getNullSpace())                   # an empty one clears a reused copy's
    out.setNearNullSpace(mat.getNearNullSpace())
    keep_symmetry(mat, out)
    return out


def keep_symmetry(mat, copy) -> None:
    """Flag ``copy`` symmetric or not as ``mat`` is known to be (nothing where it is not known)."""
    known, symmetric = mat.isSymmetricKnown()
    if known:
        copy.setOption(PETSc.Mat.Option.SYMMETRIC, symmetric)


def read_csr(mat) -> sp.csr_matrix:
    """This rank's rows of ``mat`` as a scipy CSR matrix (global columns; the whole matrix on one rank), a copy.

    Nothing is checked here: :func:`petsc_htp.validation.check_matrix` decides on every rank together.
    """
    if mat.getType() == "mpiaij":
        return _mpiaij_rows(mat)
    cols = mat.getSize()[1]
    src = mat if mat.getType() == "seqaij" else _converted(mat)   # a copy: the caller's Mat stays
    start, end = mat.getOwnershipRange()
    indptr, indices, data = src.getValuesCSR()                 # fresh arrays, ours to keep
    if src is not mat:
        src.destroy()
    return sp.csr_matrix((np.asarray(data, dtype=np.float64), indices, indptr), shape=(end - start, cols))


def gathered_rows(rows, mpi) -> sp.csr_matrix:
    """Every rank's ``rows`` (scipy CSR, global columns; ranks in order) on every rank of the mpi4py communicator
    ``mpi``: the whole matrix (collective)."""
    counts, sizes = np.array(mpi.allgather(rows.nnz)), np.array(mpi.allgather(rows.shape[0]))
    data, indices = np.empty(counts.sum()), np.empty(counts.sum(), dtype=rows.indices.dtype)
    lengths = np.empty(sizes.sum(), dtype=rows.indptr.dtype)
    mpi.Allgatherv(np.ascontiguousarray(rows.data, dtype=np.float64), (data, counts))
    mpi.Allgatherv(np.ascontiguousarray(rows.indices), (indices, counts))
    mpi.Allgatherv(np.diff(rows.indptr), (lengths, sizes))
    indptr = np.zeros(sizes.sum() + 1, dtype=rows.indptr.dtype)
    np.cumsum(lengths, out=indptr[1:])
    return sp.csr_matrix((data, indices, indptr), shape=(int(sizes.sum()), rows.shape[1]))


def _ownership_range(n, size, rank):
    """Rows owned by ``rank`` under PETSc's default (PETSC_DECIDE) split."""
    base, extra = divmod(n, size)
    start = rank * base + min(rank, extra)
    return start, start + base + (rank < extra)


def region_nullspace(mat, regions, null=None):
    """Null space of a Neumann operator: the constant, or one unit indicator per connected region.

    Parameters
    ----------
    mat : petsc4py.PETSc.Mat
        Gives the communicator and this rank's rows.
    regions : numpy.ndarray of int, shape (N,)
        Region (0 .. R-1) of every global row.
    null : numpy.ndarray of bool, shape (R,), optional
        The regions whose constant is a null vector (default: all of them).

    Returns
    -------
    petsc4py.PETSc.NullSpace
    """
    comm = mat.getComm()
    count = regions.max(initial=0) + 1
    null = np.ones(count, dtype=bool) if null is None else np.asarray(null, dtype=bool)
    if count == 1 and null[0]:
        return PETSc.NullSpace().create(constant=True, comm=comm)
    start, end = mat.getOwnershipRange()
    vectors = []
    for region in np.flatnonzero(null):
        inside = regions == region
        vec = mat.createVecLeft()
        vec.setArray(inside[start:end] / math.sqrt(np.count_nonzero(inside)))
        vectors.append(vec)
    return PETSc.NullSpace().create(vectors=vectors, comm=comm)


def preallocated_aij(A, comm=None):
    """A distributed AIJ preallocated for the scipy CSR ``A``'s pattern, each rank its block of rows (PETSc's
    default split), no values yet; returns ``(mat, start, end)``, this rank's rows ``start:end``.

    ``MAT_NEW_NONZERO_ALLOCATION_ERR`` is set (on every rank: a flag that differs across ranks deadlocks MPIAIJ
    assembly); insert the rows with ``mat.setValuesCSR(*local_csr(A, start, end))``.
    """
    comm = PETSc.COMM_WORLD if comm is None else PETSc.Comm(comm)
    n = A.shape[0]
    start, end = _ownership_range(n, comm.getSize(), comm.getRank())
    indptr, indices, _ = local_csr(A, start, end)
    row_nnz = np.diff(indptr)
    in_block = (indices >= start) & (indices < end)
    d_nnz = np.bincount(np.repeat(np.arange(end - start), row_nnz)[in_block], minlength=end - start)
    mat = PETSc.Mat().createAIJ(size=((end - start, n), (end - start, n)),
                                nnz=(d_nnz.astype(PETSc.IntType), (row_nnz - d_nnz).astype(PETSc.IntType)),
                                comm=comm)
    mat.setOption(PETSc.Mat.Option.NEW_NONZERO_ALLOCATION_ERR, True)
    return mat, start, end


def local_csr(A, start, end) -> tuple:
    """Rows ``start:end`` of the scipy CSR ``A`` as PETSc CSR arrays (indptr, global column indices, values)."""
    lo, hi = A.indptr[start], A.indptr[end]
    return ((A.indptr[start:end + 1] - lo).astype(PETSc.IntType), A.indices[lo:hi].astype(PETSc.IntType),
            A.data[lo:hi])


def gathered(vec) -> np.ndarray:
    """The whole of a (distributed) Vec as a numpy array on every rank."""
    if vec.getComm().getSize() == 1:
        return vec.getArray().copy()
    scatter, full = PETSc.Scatter.toAll(vec)
    try:
        scatter.scatter(vec, full, PETSc.InsertMode.INSERT, PETSc.ScatterMode.FORWARD)
        return full.getArray().copy()
    finally:
        scatter.destroy()
        full.destroy()


def ghost_values(mat, values, cols) -> np.ndarray:
    """The entries ``cols`` (global rows, any rank's) of a Vec laid out like ``mat``'s rows whose local part is
    ``values`` (one scatter)."""
    owned = mat.createVecLeft()
    owned.getArray()[:] = values
    want, where = np.unique(cols, return_inverse=True)
    ghost = PETSc.Vec().createSeq(want.size, comm=PETSc.COMM_SELF)
    index = PETSc.IS().createGeneral(want.astype(PETSc.IntType), comm=PETSc.COMM_SELF)
    scatter = PETSc.Scatter().create(owned, index, ghost, None)
    try:
        scatter.scatter(owned, ghost, PETSc.InsertMode.INSERT, PETSc.ScatterMode.FORWARD)
        return ghost.getArray().copy()[where]
    finally:
        for obj in (owned, ghost, index, scatter):
            obj.destroy()


def frame_mat(frame, comm=None):
    """Distributed PETSc AIJ copy of a frame's ``A`` with its null space (one constant per connected region
    whose row sums vanish; none for a nonsingular A).

    Parameters
    ----------
    comm : petsc4py.PETSc.Comm or mpi4py communicator, optional
        Defaults to ``PETSc.COMM_WORLD``; each rank inserts only its rows.

    Returns
    -------
    petsc4py.PETSc.Mat
    """
    mat, start, end = preallocated_aij(frame.A, comm)
    mat.setValuesCSR(*local_csr(frame.A, start, end))
    mat.assemble()
    from scipy.sparse.csgraph import connected_components     # not at import: it loads scipy.sparse.linalg

    regions = connected_components(frame.A, directed=False)[1]
    null = null_regions(frame.A, regions)
    if null.any():
        mat.setNullSpace(region_nullspace(mat, regions, null))
    mat.setOption(PETSc.Mat.Option.SYMMETRIC, True)
    return mat


def frame_vec(frame, mat):
    """Rank-local part of a frame's ``b`` in a Vec laid out like ``mat``'s rows."""
    vec = mat.createVecs("left")
    start, end = vec.getOwnershipRange()
    vec.setArray(frame.b[start:end])
    return vec
