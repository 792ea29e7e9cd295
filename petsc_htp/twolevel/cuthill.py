"""Reverse Cuthill-McKee order of a symmetric pattern by PyAMG's compiled breadth-first search, the same order as
scipy's ``reverse_cuthill_mckee(A, symmetric_mode=True)`` without importing ``scipy.sparse.csgraph``, whose import
pulls in ``scipy.sparse.linalg``: about 95 ms of a fresh process's first HTPPC (2026-11-28, this machine)."""
from __future__ import annotations

import numpy as np

from .amgkernels import kernels
from .nullspace import pattern_components


def reverse_cuthill_mckee(rows) -> np.ndarray:
    """The reverse Cuthill-McKee permutation of the square CSR ``rows`` (a symmetric pattern; every stored entry a
    coupling): each connected component in turn from its row of least stored entries (numpy's argsort of the counts,
    as scipy's), breadth first, each row's new neighbours by their counts, then the whole order reversed; scipy's own
    where a search reaches less than its component (an asymmetric pattern)."""
    n = rows.shape[0]
    indptr, indices = rows.indptr, rows.indices
    it = np.int32 if max(n, indices.size) < 2 ** 31 else np.int64
    indptr, indices = indptr.astype(it, copy=False), indices.astype(it, copy=False)
    degree = np.diff(indptr)
    row = np.repeat(np.arange(n, dtype=it), degree)
    by_degree = np.ascontiguousarray(indices[np.lexsort((degree[indices], row))])   # each row's, stably
    _, label = pattern_components(indptr, by_degree, n)     # no search leaves its component (scipy's if one could)
    size = np.bincount(label, minlength=1)
    seeds = np.argsort(degree)
    first = np.unique(label[seeds], return_index=True)[1]
    order, level, done = np.full(n, -1, dtype=it), np.full(n, -1, dtype=it), 0
    search = kernels("graph").breadth_first_search
    for seed in seeds[np.sort(first)]:               # each component from its first seed in that order
        search(indptr, by_degree, int(seed), order[done:], level)
        done += int(size[label[seed]])
    if n and not np.array_equal(np.bincount(order.clip(0), minlength=n), np.ones(n, dtype=np.int64)):
        from scipy.sparse.csgraph import reverse_cuthill_mckee as scipy_rcm    # an asymmetric pattern: a search
        return scipy_rcm(rows, symmetric_mode=True).astype(np.int64)          # reached less than its component
    return order[::-1].astype(np.int64)
