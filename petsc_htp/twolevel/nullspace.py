"""Pieces of the leaves and the null space of a Neumann-type operator: one rule for every two-level back-end.

A *piece* is a connected part of one leaf's graph (the leaf's rows and the nonzero entries between
them). Every piece's normalised indicator is a coarse vector, so the constant of each connected
component of A lies exactly in the coarse space. A component is *null* when A annihilates its
constant, which for these matrices means that A's row sums vanish on it. Such a constant would
make the coarse operator W^T A W singular; :func:`dropped` names the coarse vector to leave out for
each: the first piece of the component, or, when the component is a single piece with no coupling
out of its leaf, that piece, whose leaf block is then grounded (one diagonal entry raised) so that
the leaf factor stays nonsingular. Everything here is numpy and knows nothing of PETSc or torch.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from .amgkernels import kernels
from .csr import compact, row_sums

NULL_TOL = 1e-10        # |row sum| <= NULL_TOL * max |a_ii| on every row of a component: A 1_c = 0
STRICT = 1e-12          # a row sum beyond this share of the row's sum of |a_ij|: no rounding's (:func:`m_regular`,
#                         and :mod:`.consistency`'s null components: every row sum within it) ...
SUM_ROUNDING = 2 * np.finfo(float).eps      # ... and within this share of it below 0, times the row's entries (at
#                                             least 16): a vanishing one's rounding


@dataclass(frozen=True, eq=False)
class Pieces:
    """The pieces of a set of leaves, numbered leaf by leaf.

    Attributes
    ----------
    label : numpy.ndarray (n,)
        Piece of each row (rows in the leaves' order).
    leaf : numpy.ndarray (P,)
        Leaf of each piece.
    count : numpy.ndarray (K,)
        Pieces per leaf.
    first : numpy.ndarray (K,)
        First piece of each leaf.
    size : numpy.ndarray (P,)
        Rows per piece.
    index : numpy.ndarray (n,)
        Index of each row's piece within its leaf (0 for the leaf's first piece).
    """

    label: np.ndarray
    leaf: np.ndarray
    count: np.ndarray
    first: np.ndarray
    size: np.ndarray
    index: np.ndarray

    @property
    def n_pieces(self) -> int:
        """Number of pieces P."""
        return int(self.size.size)


def find_pieces(indptr, indices, leaf_of_row, n_leaves, order=None) -> Pieces:
    """Connected parts of each leaf from the leaf blocks' CSR structure.

    ``indptr``/``indices`` hold only entries between rows of the same leaf: rows in the leaves' order (each leaf's
    rows contiguous), or in any order with ``order``, the structure's row of each row in the leaves' order.
    ``leaf_of_row`` is in the leaves' order.
    """

    n = leaf_of_row.size
    n_pieces, label = pattern_components(indptr, indices, n)
    # either numbers parts by their lowest row, so in the leaves' order pieces run leaf by leaf
    if order is not None:                       # else number them by their first row in the leaves' order
        label = label[order]
        first = np.empty(n_pieces, dtype=np.int64)
        first[label[::-1]] = np.arange(n - 1, -1, -1)
        renumber = np.empty(n_pieces, dtype=np.int64)
        renumber[np.argsort(first)] = np.arange(n_pieces)
        label = renumber[label]
    leaf = np.zeros(n_pieces, dtype=np.int64)
    leaf[label] = leaf_of_row
    count = np.bincount(leaf, minlength=n_leaves)
    first = np.concatenate(([0], np.cumsum(count)[:-1]))
    return Pieces(compact(label, n_pieces), leaf, count, first, np.bincount(label, minlength=n_pieces),
                  compact(label - first[leaf_of_row], n))


def pattern_components(indptr, indices, n) -> tuple:
    """(number, label of each row) of the connected components of the graph of CSR ``indptr``/``indices`` (n rows):
    PyAMG's compiled search, which follows each row's entries (no validation, no transpose: 50 against 250 ms for
    scipy's at 1M rows); a pattern that is not symmetric (an entry one way only) can split a component, so scipy's
    then decides."""
    it = np.int32 if max(n, int(indptr[-1])) < 2 ** 31 else np.int64
    label = np.empty(n, dtype=it)
    kernels("graph").connected_components(n, indptr.astype(it, copy=False), indices.astype(it, copy=False), label)
    if np.any(np.repeat(label, np.diff(indptr)) != label[indices]):
        from scipy.sparse.csgraph import connected_components

        graph = sp.csr_matrix((np.ones(len(indices), dtype=np.int8), indices, indptr), shape=(n, n))
        return connected_components(graph, directed=False)
    return int(label.max(initial=-1)) + 1, label


def graph_components(A) -> tuple:
    """(number, label of each row) of the connected components of a square scipy CSR matrix's nonzero entries."""
    if A.shape[0] != A.shape[1]:
        raise ValueError(f"connected components need a square matrix, got shape {A.shape}")
    nonzero = A.data != 0
    if nonzero.all():
        return pattern_components(A.indptr, A.indices, A.shape[0])
    kept = np.concatenate(([0], np.cumsum(nonzero)))        # the stored zeros dropped, without a scipy copy
    return pattern_components(kept[A.indptr], A.indices[nonzero], A.shape[0])


def first_rows(label, marked) -> np.ndarray:
    """The first row (in ``label``'s order) of every marked piece (``marked``: bool per piece)."""
    first = np.full(marked.size, -1)
    first[label[::-1]] = np.arange(label.size)[::-1]
    return first[marked]


def ground(values, diag, rows):
    """Raise the diagonal entries ``values[diag[rows]]`` by their own magnitude (in place): a grounded piece's
    leaf block is nonsingular, and exact on vectors orthogonal to its constant."""
    values[diag[rows]] += np.abs(values[diag[rows]])


def components(n_pieces, edges) -> tuple:
    """Connected components of the pieces joined by ``edges`` (pairs of piece ids, couplings between leaves).

    Returns (number of components, component of each piece).
    """
    edges = np.asarray(edges, dtype=np.int64).reshape(-1, 2)
    both = np.concatenate([edges, edges[:, ::-1]])                  # each edge both ways: a symmetric pattern
    graph = sp.csr_matrix((np.ones(len(both), dtype=np.int8), (both[:, 0], both[:, 1])), shape=(n_pieces, n_pieces))
    return pattern_components(graph.indptr, graph.indices, n_pieces)


def vanishing(rowsum, diag) -> np.ndarray:
    """Boolean (n,): rows whose |row sum| is at most NULL_TOL times the largest |a_ii| (``diag``)."""
    return np.abs(rowsum) <= NULL_TOL * np.abs(diag).max(initial=0.0)


def null_by_rowsums(rowsum, diag, comp_of_row, n_comp, reduce_max=None) -> np.ndarray:
    """Boolean (C,): components on which every |row sum| is at most NULL_TOL times the largest |a_ii|.

    ``reduce_max`` (an elementwise maximum over MPI ranks) makes it collective.
    """
    top = np.array([np.abs(diag).max(initial=0.0)])
    if reduce_max is not None:
        top = reduce_max(top)
    above = np.bincount(comp_of_row[np.abs(rowsum) > NULL_TOL * top[0]], minlength=n_comp).astype(float)
    if reduce_max is not None:                   # rows above the tolerance per component (np.maximum.at: 3 ms at 65k)
        above = reduce_max(above)
    return above == 0


def m_regular(A, comp_of_row, n_comp, rowsum=None) -> np.ndarray:
    """Boolean (C,): the components of the square CSR ``A`` (``comp_of_row``, ``n_comp``; ``rowsum``: its row sums,
    where found) that are nonsingular M-matrices by their signs and row sums alone: positive diagonal, no positive
    coupling, no row sum below -:data:`SUM_ROUNDING` times its entries (at least 16) of the row's sum of |a_ij|
    (rounding's bound), and some row sum above :data:`STRICT` of it (an irreducibly diagonally dominant matrix is
    nonsingular). NULL_TOL's test, against the largest diagonal entry, takes such a component for null where its
    couplings span many orders (log-normal edge weights exp(7 N(0, 1)) on 100^2 cells: its banded factor grounded and
    CG took 354 iterations, 1 without: ``results/robust-20261128/edges.txt``)."""
    n = A.shape[0]
    row = np.repeat(np.arange(n), np.diff(A.indptr))
    rowsum = row_sums(A.indptr, A.data) if rowsum is None else rowsum
    size = row_sums(A.indptr, np.abs(A.data))
    bad = (A.diagonal() <= 0) | (rowsum < -SUM_ROUNDING * np.maximum(np.diff(A.indptr), 16) * size)
    bad[row[(A.data > 0) & (A.indices != row)]] = True
    broken = np.bincount(comp_of_row[bad], minlength=n_comp) > 0
    return (np.bincount(comp_of_row[rowsum > STRICT * size], minlength=n_comp) > 0) & ~broken


def null_regions(A, regions) -> np.ndarray:
    """Boolean per region of a scipy matrix A: its row sums vanish there, so its constant is a null vector."""
    diag = A.diagonal()
    return null_by_rowsums(np.asarray(A.sum(axis=1)).ravel(), diag, regions, regions.max(initial=0) + 1)


def null_from_vectors(vectors, constant, comp_of_row, n_comp, reduce_max=None) -> np.ndarray:
    """Boolean (C,): components that an attached null space touches (all of them for the constant)."""
    if constant:
        return np.ones(n_comp, dtype=bool)
    touched = np.zeros(n_comp)
    for z in vectors:
        np.maximum.at(touched, comp_of_row, (np.abs(z) > 0).astype(float))
    if reduce_max is not None:
        touched = reduce_max(touched)
    return touched > 0


def dropped(null, comp_of_piece, isolated) -> tuple:
    """Which pieces' coarse vectors to leave out, and which pieces to ground.

    Parameters
    ----------
    null : numpy.ndarray of bool (C,)
        Null components.
    comp_of_piece : numpy.ndarray (P,)
        Component of every piece (global numbering: the same on every rank).
    isolated : numpy.ndarray of bool (P,)
        Pieces without a coupling out of their leaf (each then is a whole component).

    Returns
    -------
    drop : numpy.ndarray of bool (P,)
        The first piece of every null component.
    ground : numpy.ndarray of bool (P,)
        The dropped pieces that are whole components (their leaf block is singular).
    """
    drop = np.zeros(comp_of_piece.size, dtype=bool)
    pieces = np.flatnonzero(null[comp_of_piece])
    if pieces.size:
        _, first = np.unique(comp_of_piece[pieces], return_index=True)
        drop[pieces[first]] = True
    return drop, drop & isolated
