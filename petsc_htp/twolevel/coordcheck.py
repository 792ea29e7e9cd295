"""Whether attached coordinates follow the matrix's rows: coupled rows lie near each other.

Morton leaves cut the rows by their coordinates. Coordinates in another order than the rows (a mesh's nodes listed
apart from its matrix's numbering) make leaves of rows that share no coupling: on a 10 000-row 5-point grid with its
coordinates shuffled every row was a piece of its own, the coarse space held 10 243 vectors and its LU took tens of
seconds, where the bare matrix takes 33 CG iterations and 0.1 s. Coupled rows of a mesh lie about one spacing apart
(the bounding box over N^(1/d)); :func:`spread` measures the median length of a sample of couplings in those units,
and above :data:`FAR` the two-level method ignores the coordinates (``-ksp_view`` says so). PETSc-free.
"""
from __future__ import annotations

import numpy as np

from .csr import row_entries

FAR = 8.0               # median coupling length, in spacings, above which coordinates do not follow the rows
SAMPLE = 4096           # rows whose couplings are measured


def spread(rows, start, coords, coll) -> float:
    """The median length of the nonzero couplings between this rank's sampled ``rows`` (CSR, global columns, local
    rows ``start`` ...) and its other rows, over the spacing the bounding box of all ranks' ``coords`` gives; the
    largest over the ranks (collective). 0 where no coupling was sampled."""
    n, dim = coords.shape
    lo = coll.min_array(coords.min(axis=0, initial=np.inf))
    hi = coll.max_array(coords.max(axis=0, initial=-np.inf))
    size = coll.sum(n)
    spacing = float(np.max(hi - lo)) / max(size ** (1.0 / dim) - 1.0, 1.0)
    picked = np.arange(0, n, max(1, n // SAMPLE))
    where, owner = row_entries(rows.indptr, picked)
    col = rows.indices[where].astype(np.int64) - start
    keep = (col >= 0) & (col < n) & (col != picked[owner]) & (rows.data[where] != 0)
    length = np.linalg.norm(coords[picked[owner[keep]]] - coords[col[keep]], axis=1)
    local = float(np.median(length)) / spacing if length.size and spacing > 0 else 0.0
    return float(coll.max_array(np.array([local]))[0])
