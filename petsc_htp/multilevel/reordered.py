"""The copy of the operator whose rows the V-cycles take in their leaves' order, and its new values: on one rank
made from the operator's rows by one sort (where each of its entries lies among the operator's) and refilled by a
gather into its array; on several ranks by PETSc's MatCreateSubMatrix, which searches every row's columns each time
(P1 triangles numbered at random, one rank, medians: made in 24.2 against 25.4 ms and refilled in 4.2 against 21.9 at
65 536 rows, 641 against 1 160 and 155 against 1 196 at 1M: ``results/refill-20261128/refill.txt``)."""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from ..aijarrays import aij
from ..petscmat import keep_symmetry, seqaij_values


class Reordered:
    """:attr:`P` = ``mat``[order, order] (``rows``: this rank's rows of ``mat``; ``perm``: its rows in that order,
    numbered on the rank; ``mat``'s known symmetry kept), its values refilled by :meth:`refill`; P is the caller's
    to free."""

    def __init__(self, mat, rows, perm, order):
        self.mat, self.order, self.take = mat, order, None
        if mat.getComm().getSize() > 1:
            self.P = mat.createSubMatrix(order, order)
            return
        where = permuted_entries(rows, perm)
        self.take = where.data
        self.P = aij(mat.getComm(), mat.getSizes(), sp.csr_matrix((rows.data[self.take], where.indices, where.indptr),
                                                                   shape=where.shape))
        keep_symmetry(mat, self.P)

    def refill(self, rows):
        """:attr:`P`'s values from ``mat``'s new ones: on one rank gathered from ``rows`` (this rank's, the pattern P
        was made from) by the map, on several read from ``mat`` by MatCreateSubMatrix."""
        if self.take is None:
            self.mat.createSubMatrix(self.order, self.order, submat=self.P)
            return
        with seqaij_values(self.P) as values:
            np.take(rows.data, self.take, out=values, mode="clip")     # no bounds check: no buffer (the map is
            # within the pattern's entries, which the numeric step's caller keeps)


def permuted_entries(rows, perm) -> sp.csr_matrix:
    """A[perm][:, perm] of one rank's whole matrix A (``rows``, CSR) with each entry's place among A's stored values
    as its value (column indices sorted)."""
    n = rows.shape[0]
    inverse = np.empty(n, dtype=rows.indices.dtype)
    inverse[perm] = np.arange(n, dtype=inverse.dtype)
    where = sp.csr_matrix((np.arange(rows.nnz, dtype=np.intp), inverse[rows.indices], rows.indptr),
                          shape=(n, n))[perm]       # the columns renumbered, then the rows taken in their new order
    where.sort_indices()
    return where
