"""Whether attached coordinates follow the matrix's rows: coupled rows lie nearer each other than rows at random.

Morton leaves cut the rows by their coordinates. Coordinates in another order than the rows (a mesh's nodes listed
apart from its matrix's numbering) make leaves of rows that share no coupling: on a 10 000-row 5-point grid with its
coordinates shuffled every row was a piece of its own, the coarse space held 10 243 vectors and its LU took tens of
seconds, where the bare matrix takes 33 CG iterations and 0.1 s. :func:`spread` compares, on each rank, the median
distance between coupled rows with the median distance between rows paired at random (scale-free: a graded,
stretched or perforated mesh keeps its coordinates; a grid of n rows gives about 2 / n^(1/d), shuffled coordinates
about 1, coordinates all equal 0 / 0, taken as 1); above :data:`FAR` on any rank of at least :data:`JUDGED` rows the
two-level method ignores the coordinates (``-ksp_view`` says so). PETSc-free.
"""
from __future__ import annotations

import numpy as np

from .csr import row_entries

FAR = 0.5               # coupled over random median distance above which coordinates do not follow the rows
JUDGED = 1024           # rows a rank needs for its ratio to count (a 3-D grid of 1 024 rows: about 0.2)
SAMPLE = 4096           # rows whose couplings are measured


def spread(rows, start, coords, coll) -> float:
    """The largest over the ranks of at least :data:`JUDGED` rows of the median distance between the nonzero
    couplings of this rank's sampled ``rows`` (CSR, global columns, local rows ``start`` ...) within the rank, over
    the median distance between as many pairs of its rows drawn at random (collective); 0 where no rank judges."""
    n = coords.shape[0]
    local = 0.0
    if n >= JUDGED:
        picked = np.arange(0, n, max(1, n // SAMPLE))
        where, owner = row_entries(rows.indptr, picked)
        col = rows.indices[where].astype(np.int64) - start
        keep = (col >= 0) & (col < n) & (col != picked[owner]) & (rows.data[where] != 0)
        i, j = picked[owner[keep]], col[keep]
        if i.size:
            other = np.random.default_rng(0).integers(0, n, i.size)
            near = float(np.median(np.linalg.norm(coords[i] - coords[j], axis=1)))
            apart = float(np.median(np.linalg.norm(coords[i] - coords[other], axis=1)))
            local = near / apart if apart > 0 else 1.0
    return float(coll.max_array(np.array([local]))[0])
