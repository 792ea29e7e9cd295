"""Index arithmetic on CSR matrices without a Python loop over rows. PETSc-free."""
from __future__ import annotations

import numpy as np


def row_entries(indptr, rows) -> tuple:
    """Positions of the stored entries of ``rows`` (in ``indices``/``data`` of a CSR matrix with ``indptr``),
    row after row, and the index into ``rows`` of each."""
    rows = np.asarray(rows)
    start, count = indptr[rows], indptr[rows + 1] - indptr[rows]
    where = np.repeat(start - np.cumsum(count) + count, count) + np.arange(int(count.sum()))
    return where, np.repeat(np.arange(rows.size), count)
