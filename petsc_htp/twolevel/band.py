"""One Cholesky factor of the whole matrix as a band: rows in reverse Cuthill-McKee order, factored by LAPACK's
banded Cholesky (``dpbtrf``), a PETSc PC of its own (:class:`BandPC`, PCPYTHON).

Its work is n w^2 for bandwidth w, against PETSc's sparse Cholesky in nested-dissection order, whose fill is less but
whose scalar kernels are slower: a 2-D 5-point matrix of 2 025 rows (w = 45) took 1.7 against 2.4 ms, of 7 921 rows
(w = 89) 8 against 12, a free surface of 16 087 rows (w = 91) 18 against the two-level method's 28 (one rank,
``results/band-20261127``). A chain's band (w = 1 or 2) is as cheap as its rows.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.linalg import lapack

from .csr import row_sums
from .cuthill import reverse_cuthill_mckee
from .nullspace import graph_components, m_regular, vanishing

NATURAL_WIDTH = 16     # the rows' own order's bandwidth up to which it is kept (RCM took 4 ms for a chain of 65 536
#                        rows, more than a factor of that bandwidth)
NULL_PIVOT = 1e-8      # a pivot below this share of its row's diagonal entry: a null direction (grounded: a rank-one
#                        change, where the matrix was only ill-conditioned: a few CG iterations more)
GROUND_MAX = 16        # factorisations at most, each grounding the null pivots it found ...
EVERY_AFTER = 2        # ... and from the third on the last row of every component too


def ordering(rows, reorder=True) -> tuple:
    """(permutation of the symmetric pattern of CSR ``rows``, each stored entry's row and column in that order,
    bandwidth): the rows' own order where its bandwidth is at most :data:`NATURAL_WIDTH`, or at most the square root
    of the rows where most rows span it (:func:`_spanned`: a 2-D grid's row by row, whose fronts RCM's do not undercut:
    the foreign study's grids of 1 024 to 29 929 rows, ``results/small-20261128/widths.txt``), or no more than reverse
    Cuthill-McKee's, or where not ``reorder``; else RCM's."""
    n = rows.shape[0]
    qi, qj = np.repeat(np.arange(n, dtype=rows.indices.dtype), np.diff(rows.indptr)), rows.indices
    natural = own_width(rows)
    if natural <= NATURAL_WIDTH or not reorder or (natural * natural <= n and _spanned(rows, natural)):
        return np.arange(n), qi, qj, natural
    perm = reverse_cuthill_mckee(rows)
    inverse = np.empty(n, dtype=perm.dtype)
    inverse[perm] = np.arange(n, dtype=perm.dtype)
    ri, rj = inverse[qi], inverse[qj]
    width = int(np.abs(ri - rj).max())
    return (np.arange(n), qi, qj, natural) if width >= natural else (perm, ri, rj, width)


def own_width(rows) -> int:
    """The bandwidth of the CSR ``rows`` in their own order: from each row's first and last stored column where the
    columns are sorted (PETSc's are; the 2-D DMDA's 262 144 rows 3.7 against 6.4 ms), else from every entry."""
    if not rows.nnz:
        return 0
    if rows.has_sorted_indices:
        full, first, last = _row_ends(rows)
        return int(max((full - first).max(), (last - full).max(), 0))
    qi = np.repeat(np.arange(rows.shape[0], dtype=rows.indices.dtype), np.diff(rows.indptr))
    return int(np.abs(qi - rows.indices).max())


def _row_ends(rows) -> tuple:
    """(the CSR ``rows``' rows that hold entries, each one's least and largest column): read at each row's ends where
    the columns are sorted, else by a reduction over its entries."""
    full = np.flatnonzero(rows.indptr[:-1] < rows.indptr[1:])
    starts = rows.indptr[full]
    if rows.has_sorted_indices:
        return full, rows.indices[starts], rows.indices[rows.indptr[full + 1] - 1]
    return full, np.minimum.reduceat(rows.indices, starts), np.maximum.reduceat(rows.indices, starts)


def _spanned(rows, width) -> bool:
    """Whether the median row of the CSR ``rows`` reaches at least ``width`` from its first stored column to its last
    (a grid's row by row: twice its width; a chain numbered in reversed blocks, whose band RCM shrinks, only 2)."""
    full, first, last = _row_ends(rows)
    return bool(full.size) and bool(np.median(last - first) >= width)


class Band:
    """The banded Cholesky factor of one pattern: made from CSR ``rows`` (symmetric; its lower triangle in the new
    order is read) and its :func:`ordering` where known, then :meth:`factor` for each set of values and
    :meth:`solve`."""

    def __init__(self, rows, order=None):
        n = rows.shape[0]
        self.perm, qi, qj, self.width = order or ordering(rows)
        self.indptr, self.indices = rows.indptr.copy(), rows.indices.copy()
        self.own = np.array_equal(self.perm, np.arange(n))       # the rows' own order
        self.position = np.empty(n, dtype=np.int64)              # each row's place in the band's order
        self.position[self.perm] = np.arange(n)
        self.lower = np.flatnonzero(qi >= qj)                  # entries in the lower band of the new order
        qi, qj = qi[self.lower].astype(np.int64), qj[self.lower].astype(np.int64)
        self.at = (qi - qj) + qj * (self.width + 1)            # ab[i - j, j], Fortran order (LAPACK's lower form)
        self.on = np.flatnonzero(qi == qj)                      # ... of them the diagonal's, in the columns qj[on]
        self.on_col = qj[self.on]
        self.diag_at = np.arange(n) * (self.width + 1)
        self.shape, self.c = (self.width + 1, n), None

    def same(self, rows) -> bool:
        """Whether CSR ``rows`` has this pattern."""
        return (rows.shape[0] == self.shape[1] and np.array_equal(rows.indptr, self.indptr)
                and np.array_equal(rows.indices, self.indices))

    def factor(self, data, ground=None) -> tuple:
        """Factor the values ``data`` (in the pattern's CSR order) with the rows ``ground`` (the caller's, where known:
        one of each null component, whose null pivot rounding hides at high contrast: 5e-7 of its diagonal entry at
        1e6) grounded, and each null pivot: a pivot below :data:`NULL_PIVOT` of its row's diagonal entry (a singular
        matrix's, where no component was grounded before: the rounding leaves it either side of zero) has that
        diagonal entry raised by its own magnitude, and the values are factored again; where at most one row is given
        and every row sum vanishes, the last row in the band's order is grounded first instead (a connected graph's
        one null pivot, as before rows were given: the Neumann square's iterations stay), and after
        :data:`EVERY_AFTER` more the last row of every component of the graph (many null components). Where the values
        make a nonsingular M-matrix (:func:`.nullspace.m_regular`), the last row is not grounded first, and where
        nothing is grounded and LAPACK factored every column, small pivots stay as they are. Returns (info: k > 0
        where the k-th pivot in the band's order is negative beyond that, the matrix indefinite; -1 where null pivots
        remain after :data:`GROUND_MAX` factorisations; else 0 | the rows grounded, in the original order)."""
        values = data[self.lower]
        diag = np.zeros(self.shape[1])                          # |a_ii| in the band's order
        diag[self.on_col] = np.abs(values[self.on])
        grounded = np.zeros(0, dtype=np.int64)
        given = 0 if ground is None else len(ground)
        rowsum, regular = row_sums(self.indptr, data), None
        if self.shape[1] and given <= 1 and vanishing(rowsum, diag).all():
            regular = self._regular(data, rowsum)
            grounded = np.zeros(0, dtype=np.int64) if regular else np.array([self.shape[1] - 1])
        elif given:
            grounded = np.unique(self.position[ground])
        for attempt in range(GROUND_MAX):
            info, null, done = self._attempt(values, diag, grounded)
            if info > 0 or null.size == 0:
                return info, self.perm[grounded]
            if done and attempt == 0 and not grounded.size and (
                    self._regular(data, rowsum) if regular is None else regular):
                return 0, self.perm[grounded]           # small pivots of a regular matrix: its factor as it is
            if attempt == EVERY_AFTER:
                null = np.union1d(null, self._component_ends(data))
            grounded = np.union1d(grounded, null)
        return -1, self.perm[grounded]

    def _attempt(self, values, diag, grounded) -> tuple:
        """One factorisation of the band of ``values`` (the lower band's entries) with the rows ``grounded`` (band
        order) raised by ``diag``, made afresh (no copy of a band kept for another try): (LAPACK's info where a pivot
        is negative beyond :data:`NULL_PIVOT`, else 0 | the null pivots found, band order | whether LAPACK factored
        every column: a pivot it stopped at, not positive, leaves the columns after it unfactored)."""
        ab = np.zeros(self.shape[0] * self.shape[1])
        ab[self.at] = values
        ab[self.diag_at[grounded]] += diag[grounded]
        self.c, info = lapack.dpbtrf(ab.reshape(self.shape, order="F"), lower=1, overwrite_ab=1)
        if info > 0:                                            # LAPACK leaves the failed pivot in place
            if not self.c[0, info - 1] > -NULL_PIVOT * diag[info - 1]:
                return info, np.zeros(0, dtype=np.int64), False
            return 0, np.array([info - 1]), False
        return 0, np.flatnonzero(self.c[0] ** 2 < NULL_PIVOT * diag), True

    def _regular(self, data, rowsum) -> bool:
        """Whether the values ``data`` make a nonsingular M-matrix by their signs and row sums
        (:func:`.nullspace.m_regular`)."""
        A, count, label = self._components(data)
        return bool(m_regular(A, label, count, rowsum).all())

    def _components(self, data) -> tuple:
        """(the values ``data`` as CSR, the number of connected components of their nonzero entries, each row's)."""
        n = self.shape[1]
        A = sp.csr_matrix((data, self.indices, self.indptr), shape=(n, n))
        return (A,) + graph_components(A)

    def _component_ends(self, data) -> np.ndarray:
        """The last row (band order) of each connected component of the nonzero entries ``data``'s graph."""
        _, count, label = self._components(data)
        ends = np.full(count, -1, dtype=np.int64)
        np.maximum.at(ends, label, self.position)
        return ends

    def solve(self, b, out):
        """out = A^-1 b."""
        x, _ = lapack.dpbtrs(self.c, b[self.perm], lower=1)
        out[self.perm] = x

    @property
    def nbytes(self) -> int:
        """Bytes of the factor."""
        return 8 * self.shape[0] * self.shape[1]


class BandPC:
    """PCPYTHON context: the banded Cholesky factor of the PC's operator, e.g. ``-pc_type python -pc_python_type
    petsc_htp.twolevel.band.BandPC``; on several ranks the whole matrix gathered and factored on every rank, each
    application gathering x (a 1 024-row matrix on 2 ranks: 0.5 ms to gather, order and factor, where PCREDUNDANT's
    LU took 2.2). A pivot that is not positive is an error naming the matrix indefinite (:attr:`info`, LAPACK's, says
    which); a pivot that vanishes is grounded (:meth:`Band.factor`; :attr:`grounded`: the rows, in the operator's
    order). ``made``: (:class:`Band`, rows grounded) already factored for the operator's values, which the first
    setUp takes (the multilevel V-cycle's coarse solve: :func:`..multilevel.cycle.banded`)."""

    def __init__(self, made=None):
        self.band, self.info, self.grounded = None, 0, np.zeros(0, dtype=np.int64)
        self.made = made            # (Band, rows grounded) factored for the operator's values at the first setUp
        self.mpi, self.sizes, self.start, self.work = None, None, 0, None   # several ranks: the rows each owns,
        # this one's first, work arrays

    def setUp(self, pc):
        """Order (on a new pattern) and factor the operator's values, or take the factor :attr:`made` for them
        (collective)."""
        from ..petscmat import gathered_rows, local_rows

        mat = pc.getOperators()[1]
        n = mat.getSize()[0]
        self.mpi = mat.getComm().tompi4py() if mat.getComm().getSize() > 1 else None
        if self.mpi is not None:
            self.sizes, self.start = np.array(self.mpi.allgather(mat.getLocalSize()[0])), mat.getOwnershipRange()[0]
            self.work = np.empty(n), np.empty(n)                       # the gathered x and the solve
        if self.made is not None:                                      # its maker read and gathered the rows
            (self.band, self.grounded), self.made = self.made, None
            return
        with local_rows(mat) as mine:
            rows = mine if self.mpi is None else gathered_rows(mine, self.mpi)
            if self.band is None or not self.band.same(rows):
                self.band = Band(rows)
            self.info, self.grounded = self.band.factor(rows.data)
        if self.info > 0:
            raise ValueError(f"the banded Cholesky factor's pivot {self.info} of {n} (in its band's order) "
                             "is negative: the matrix is not positive semidefinite")
        if self.info < 0:
            raise ValueError(f"the banded Cholesky factor still has null pivots after {GROUND_MAX} factorisations, "
                             f"{self.grounded.size} rows grounded: the matrix's null space is larger than its graph's "
                             "components")

    def apply(self, pc, x, y):
        """y = A^-1 x (on several ranks x gathered on every rank; collective)."""
        if self.mpi is None:
            self.band.solve(x.array_r, y.array_w)
            return
        whole, out = self.work
        self.mpi.Allgatherv(np.ascontiguousarray(x.array_r), (whole, self.sizes))
        self.band.solve(whole, out)
        y.array_w[...] = out[self.start:self.start + y.getLocalSize()]

    applyTranspose = apply

    @property
    def values(self) -> int:
        """Values of the factor this rank holds (0 before the set-up)."""
        return 0 if self.band is None else self.band.nbytes // 8

    def describe(self) -> str:
        """The factor in words."""
        b = self.band
        if b is None:
            return "banded Cholesky (not set up)"
        order = "its own" if b.own else "reverse Cuthill-McKee"
        null = f", {self.grounded.size} null pivot(s) grounded" if self.grounded.size else ""
        where = f", gathered and factored on each of the {self.sizes.size} ranks" if self.mpi is not None else ""
        return f"banded Cholesky (LAPACK dpbtrf) in {order} order, bandwidth {b.width}, {b.shape[1]} rows{null}{where}"

    def view(self, pc, viewer):
        """-ksp_view's line."""
        viewer.printfASCII(f"  {self.describe()}\n")
