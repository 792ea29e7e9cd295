"""Whether new values of the pattern moved away from the finest level's leaves (a coefficient jump that moved), as
the two-level method's :meth:`~petsc_htp.twolevel.structure.Structure.moved` judges its own: the weak couplings
inside the leaves, over sampled rows, grew past WEAK_GROWTH times those the leaves held when made."""
from __future__ import annotations

import numpy as np

from ..twolevel.aggregation import THETA
from ..twolevel.csr import row_entries
from ..twolevel.structure import WEAK_GROWTH, WEAK_ROWS


class WeakInside:
    """The sampled entries of this rank's ``rows`` (global columns, first row ``start``) that join two rows of one
    leaf (``leaf``: each row's), and how many of them were weak when the leaves were made."""

    def __init__(self, rows, start, leaf):
        n = rows.shape[0]
        self.start = start
        self.stride = max(1, n // WEAK_ROWS)
        sample = np.arange(0, n, self.stride)
        where, which = row_entries(rows.indptr, sample)
        row = sample[which]
        col = rows.indices[where] - start
        inside = (col >= 0) & (col < n) & (col != row)
        inside[inside] = leaf[row[inside]] == leaf[col[inside]]
        self.src, self.row, self.col = where[inside], row[inside], col[inside]
        self.made, self.floor = self.count(rows), 1e-3 * sample.size

    def count(self, rows) -> int:
        """Weak couplings (|a_ij| < THETA sqrt(|a_ii a_jj|)) among the sampled inside entries of ``rows``."""
        root = np.sqrt(np.abs(rows.diagonal(k=self.start)))      # square roots first: no overflow at 1e200
        vals = np.abs(rows.data[self.src])
        return int(np.count_nonzero((vals < THETA * root[self.row] * root[self.col]) & (vals != 0)))

    def moved(self, rows) -> bool:
        """Whether ``rows``' new values hold more than WEAK_GROWTH times the weak couplings this rank's leaves held
        (plus 0.1 % of the sampled rows); this rank's alone (HTPPC's setup or's it over the ranks)."""
        return self.count(rows) > WEAK_GROWTH * self.made + self.floor
