"""What HTPPC checks on a matrix before it builds anything, decided by every rank together.

Each rank counts the problems of its own rows; one reduction gives every rank the same counts and the
first offending global row, so every rank raises the same error naming the problem (or none does), and
no rank is left waiting in a collective that another one skipped. Checked: a non-square or empty
matrix, a rank without rows, NaN or Inf entries, empty rows, missing or zero diagonal entries, negative
diagonal entries (HTPPC needs an SPD matrix), attached null space vectors split unlike the rows, coordinates attached
on some ranks only (:func:`check_attached`), and, once per nonzero pattern unless the matrix says it is symmetric
and holds no row of just its diagonal, symmetry: a random probe x^T A y - y^T A x, relative to |x| |A| |y| (where
Dirichlet rows whose columns the other rows keep are the only asymmetry, :func:`check_symmetry` returns them:
:mod:`petsc_htp.keptcolumns` takes them).
"""
from __future__ import annotations

import numpy as np

from .collective import Collective

ASYMMETRY = 1e-8        # |x^T A y - y^T A x| / (|x| |y| max_i sum_j |a_ij|) above this: not symmetric
NO_ROW = np.iinfo(np.int64).max     # no such row on this rank (the ranks' least first row)

PROBLEMS = ("a rank without rows", "NaN or Inf entries", "empty rows", "missing or zero diagonal entries",
            "negative diagonal entries")


class MatrixError(ValueError):
    """The matrix handed to HTPPC cannot be preconditioned; the message names the problem (every rank's)."""


def check_size(mat) -> None:
    """Raise :class:`MatrixError` (every rank alike: the sizes are global) for a non-square or 0 x 0 matrix."""
    n_rows, n_cols = mat.getSize()
    if n_rows != n_cols:
        raise MatrixError(f"HTPPC needs a square matrix, got {n_rows} x {n_cols} (non-square)")
    if n_rows == 0:
        raise MatrixError("HTPPC got an empty matrix (0 x 0)")


def check_layout(mat, b, x) -> None:
    """Raise ValueError on every rank where some rank's part of the right-hand side ``b`` or the solution ``x`` of a
    KSPSolve differs from its rows of ``mat`` (vectors made with another layout than Mat.createVecs'), naming the
    first such rank (collective)."""
    coll, rank = Collective(mat.getComm()), mat.getComm().getRank()
    sizes = np.array([b.getLocalSize(), x.getLocalSize(), *mat.getLocalSize()], dtype=float)
    bad = bool((sizes[:2] != sizes[2:]).any())
    first = coll.min_array(np.array([rank if bad else np.inf]))[0]
    if first == np.inf:
        return
    got = coll.sum_array(sizes if rank == first else np.zeros(4))
    name, k = ("right-hand side", 0) if got[0] != got[2] else ("solution", 1)
    raise ValueError(f"the {name} vector's layout differs from the matrix's on {coll.sum(bad)} rank(s) (rank "
                     f"{int(first)}: {int(got[k])} local entries against {int(got[k + 2])} rows): make the vectors "
                     f"with Mat.createVecs()")


def check_matrix(mat, rows, empty_ok=False) -> None:
    """Raise :class:`MatrixError` on every rank when any rank's ``rows`` (its rows of ``mat``, scipy CSR with
    global columns) show a problem of :data:`PROBLEMS`, a rank without rows only where not ``empty_ok`` (collective;
    after :func:`check_size`)."""
    n_rows, n_cols = mat.getSize()
    start = mat.getOwnershipRange()[0]
    n = rows.shape[0]
    d = rows.diagonal(k=start)
    finite = np.isfinite(rows.data)
    none = np.zeros(0, dtype=np.int64)
    bad = [none if n or empty_ok else np.array([0]),                         # local row numbers
           none if finite.all() else np.unique(np.repeat(np.arange(n), np.diff(rows.indptr))[~finite]),
           np.flatnonzero(np.diff(rows.indptr) == 0),
           np.flatnonzero(d == 0),
           np.flatnonzero(d < 0)]
    counts = np.array([b.size for b in bad] + [_split_apart(mat, n), rows.nnz], dtype=np.int64)
    first = np.array([b[0] + start if b.size else NO_ROW for b in bad] + [0, 0], dtype=np.int64)
    coll = Collective(mat.getComm())
    counts, first = coll.sum_array(counts), coll.min_array(first)
    if counts[-1] == 0:
        raise MatrixError(f"HTPPC got an empty matrix ({n_rows} x {n_cols} with no nonzeros)")
    for k, what in enumerate(PROBLEMS):
        if counts[k]:
            where = "" if k == 0 else f" in {counts[k]} row(s), the first global row {first[k]}"
            raise MatrixError(f"the matrix has {what}{where}; HTPPC needs a finite SPD matrix"
                              + (" with every rank owning rows" if k == 0 else ""))
    if counts[-2]:
        raise MatrixError(f"the matrix's attached null space or near null space holds vectors whose entries are "
                          f"split over the ranks unlike the matrix's rows ({counts[-2]} local part(s) differ); make "
                          f"them with Mat.createVecRight()")


def _split_apart(mat, n) -> int:
    """Vectors of ``mat``'s attached null space and near null space whose local size is not this rank's ``n`` rows
    (each rank read its own part of them: one rank raised, the others waited in a collective)."""
    spaces = [space for space in (mat.getNullSpace(), mat.getNearNullSpace()) if space.handle]
    return sum(vec.getLocalSize() != n for space in spaces for vec in space.getVecs())


def check_attached(mat, coords, density) -> None:
    """Raise :class:`MatrixError` on every rank where :func:`petsc_htp.attach` stored coordinates or densities on
    some ranks of ``mat`` but not on all, or coordinates of different dimensions (``coords``, ``density``: this rank's,
    None where absent): the ranks would build different leaves and wait in different collectives (collective on
    several ranks; at a setup every rank runs: PETSc sets up only the ranks whose operator changed)."""
    coll = Collective(mat.getComm())
    if coll.size == 1:
        return
    width = -1 if coords is None else coords.shape[1]
    have = coll.sum_array(np.array([coords is not None, density is not None], dtype=np.int64))
    widths = coll.max_array(np.array([width, -width if width >= 0 else -99], dtype=np.int64))
    for what, count in zip(("coordinates", "densities"), have):
        if 0 < count < coll.size:
            raise MatrixError(f"{what} are attached on {count} of the {coll.size} ranks only: call petsc_htp.attach "
                              f"on every rank of a parallel matrix")
    if have[0] and widths[0] != -widths[1]:
        raise MatrixError(f"coordinates of {-widths[1]} and {widths[0]} dimensions are attached on different ranks")


def check_symmetry(mat, dirichlet=None):
    """Raise :class:`MatrixError` (every rank) when a probe (:func:`probe_values`) shows ``mat`` is not symmetric,
    but where the asymmetry is only that of Dirichlet rows whose couplings the other rows keep (MatZeroRows;
    ``dirichlet()``: this rank's rows holding just their diagonal, boolean,
    :func:`.twolevel.aggregation.decoupled_rows`, asked only where the answer needs them, given on every rank or on
    none), return them (:mod:`petsc_htp.keptcolumns` drops their columns); None when symmetric. A matrix flagged
    symmetric (MAT_SYMMETRIC) is taken at its word but for rows holding just their diagonal, which are probed: PETSc
    keeps the flag through MatZeroRows. Collective."""
    coll, rows, count = Collective(mat.getComm()), None, 0
    known, symmetric = mat.isSymmetricKnown()
    if known and symmetric:
        rows = None if dirichlet is None else dirichlet()
        count = coll.sum(0 if rows is None else int(np.count_nonzero(rows)))
        if not count:
            return None
    gap, scale = _asymmetry(mat)
    if gap <= ASYMMETRY * scale:
        return None
    if rows is None and dirichlet is not None:
        rows = dirichlet()
        count = coll.sum(int(np.count_nonzero(rows)))
    if count and _asymmetry(mat, rows)[0] <= ASYMMETRY * scale:
        return rows
    if known and symmetric:         # its word for the rest
        return None
    raise MatrixError(f"the matrix is not symmetric (random probe |x^T A y - y^T A x| = {gap / scale:.1e} of "
                      "|x| |y| |A|); HTPPC needs an SPD matrix (if A is symmetric to rounding, say so with "
                      "MatSetOption(A, MAT_SYMMETRIC, PETSC_TRUE))")


def _asymmetry(mat, lone=None) -> tuple:
    """(|x^T A y - y^T A x|, |x| |y| |A|_inf) for the two probes (collective); with ``lone`` (this rank's rows, boolean)
    of A with those rows' columns dropped but their diagonal entries: A (1 - d) v + d a_ii v."""
    from petsc4py import PETSc

    x, y = mat.createVecs()
    ax, ay, tmp = mat.createVecs() + (mat.createVecRight(),)
    start, end = x.getOwnershipRange()
    keep = diag = None
    if lone is not None:
        mat.getDiagonal(tmp)
        keep, diag = np.where(lone, 0.0, 1.0), np.where(lone, tmp.array_r, 0.0)
    try:
        for probe, v, av in zip(probe_values(start, end, (1, 2)), (x, y), (ax, ay)):
            v.setArray(probe)
            if keep is None:
                mat.mult(v, av)
            else:
                tmp.setArray(keep * v.array_r)
                mat.mult(tmp, av)
                av.array[:] += diag * v.array_r
        return abs(x.dot(ay) - y.dot(ax)), x.norm() * y.norm() * mat.norm(PETSc.NormType.INFINITY)
    finally:
        for obj in (x, y, ax, ay, tmp):
            obj.destroy()


def probe_values(start, end, salt) -> np.ndarray:
    """Entries ``start`` to ``end`` of a probe vector in [-0.5, 0.5), a hash (splitmix64) of each global index and
    ``salt``: the same vector on any number of ranks, so that a matrix near the threshold gets the same answer
    (PETSc's random vectors differ with the split: PETSc's ex3 at 10 000 rows, asymmetric by 2.5e-5 where MatZeroRows
    kept the columns, passed on 2 ranks and failed on one). A sequence of salts gives one row for each."""
    salts = np.left_shift(np.array(salt, dtype=np.uint64), np.uint64(40))
    salts = salts[:, None] if salts.ndim else salts            # one row per salt given
    z = (np.arange(start, end, dtype=np.uint64) + salts) * np.uint64(0x9E3779B97F4A7C15)
    z = (z ^ (z >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
    z = (z ^ (z >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
    z ^= z >> np.uint64(31)
    return (z >> np.uint64(11)).astype(np.float64) / float(1 << 53) - 0.5
