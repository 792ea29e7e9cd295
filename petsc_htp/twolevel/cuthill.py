"""Reverse Cuthill-McKee order of a symmetric pattern by PyAMG's compiled breadth-first search, the same order as
scipy's ``reverse_cuthill_mckee(A, symmetric_mode=True)`` without importing ``scipy.sparse.csgraph``, whose import
pulls in ``scipy.sparse.linalg``: 45 of the 89 ms of a fresh process's ``import petsc_htp.pc`` after numpy and
scipy.sparse (results/renew-20261128/imports.txt)."""
from __future__ import annotations

import numpy as np

from .amgkernels import kernels
from .nullspace import pattern_components


def reverse_cuthill_mckee(rows, exact=True) -> np.ndarray:
    """The reverse Cuthill-McKee permutation of the square CSR ``rows`` (a symmetric pattern; every stored entry a
    coupling), as scipy's (with ``exact``): a row's degree its stored entries, plus one where it stores its diagonal;
    each connected component in turn from its row of least degree (numpy's argsort of the degrees), breadth first,
    each row's new neighbours by their degrees, then the whole order reversed; components of one row placed at once.
    Scipy's own where a search reaches less than its component (an asymmetric pattern). ``exact=False`` takes each
    row's new neighbours in their stored order: an order as local, without the sort of every entry by degree (P1
    triangles numbered at random, 262 144 rows: most of the 177 ms)."""
    n = rows.shape[0]
    it = np.int32 if max(n, rows.indices.size) < 2 ** 31 else np.int64
    indptr, indices = rows.indptr.astype(it, copy=False), rows.indices.astype(it, copy=False)
    count = np.diff(indptr)
    row = np.repeat(np.arange(n, dtype=it), count)
    degree = count.copy()
    degree[row[indices == row]] += 1                         # a stored diagonal (once, stored twice or not)
    by_degree = np.ascontiguousarray(indices[np.lexsort((degree[indices], row))] if exact else indices)
    _, label = pattern_components(indptr, by_degree, n)     # no search leaves its component (scipy's if one could)
    size = np.bincount(label, minlength=1)
    seeds = np.argsort(degree.astype(rows.indices.dtype, copy=False))
    starts = seeds[np.sort(np.unique(label[seeds], return_index=True)[1])]     # each component's first seed
    alone = size[label[starts]] == 1
    order, level, done = np.full(n, -1, dtype=it), np.full(n, -1, dtype=it), 0
    search = kernels("graph").breadth_first_search
    for run in np.split(np.arange(starts.size), np.flatnonzero(np.diff(alone)) + 1) if starts.size else ():
        if alone[run[0]]:                                    # rows alone: in their seeds' order, at once
            order[done:done + run.size] = starts[run]
            level[starts[run]] = 0
            done += run.size
            continue
        for seed in starts[run]:
            search(indptr, by_degree, int(seed), order[done:], level)
            done += int(size[label[seed]])
    if n and order.min() < 0:                                # an asymmetric pattern: a search reached less
        from scipy.sparse.csgraph import reverse_cuthill_mckee as scipy_rcm

        return scipy_rcm(rows, symmetric_mode=True).astype(np.int64)
    return order[::-1].astype(np.int64)
