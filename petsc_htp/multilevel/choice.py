"""When HTPPC as it comes runs the multilevel V-cycles in place of the two-level method: a bare, scalar 2-D graph of
at least :data:`MIN_ROWS` rows, where their iterations (about half the two-level method's) pay for a costlier
application and the hierarchy's setup costs less than the two-level method's coarse LU."""
from __future__ import annotations

import numpy as np

from ..collective import Collective
from ..twolevel import nearnull
from ..twolevel.csr import row_entries

MIN_ROWS = 200_000      # rows from which the V-cycles serve a bare 2-D graph (one rank, single solves, CG to 1e-8,
# setup + solve ms, two-level against multilevel, 2026-11-28: 262 144 rows dmda2d 728 / 605, free_surface 500 / 402,
# lognormal 685 / 564, neumann 651 / 631, fem_tri 1178 / 1268; 1 048 576 rows dmda2d 3 608 / 2 908, free_surface
# 2 832 / 1 992; 65 536 rows level or the two-level method ahead; 3-D: the Galerkin products of the smoothed coarse
# vectors cost more than the levels save, dmda3d at 1M 4.0 / 6.3 s)
DIM = 2
SPAN = 4.0              # see local_order
SAMPLE_ROWS = 4096      # rows whose entries local_order measures


def serves(mat, rows, shape) -> str:
    """Why the V-cycles serve ``mat`` (this rank's ``rows``; ``shape()`` gives its diagonal block's
    :class:`..twolevel.graphshape.GraphShape`, the whole-matrix choice's, found once), or '' (collective): at
    least :data:`MIN_ROWS` rows, no block size or near null space of its own, a 2-D graph on some rank and rows in a
    local order (:func:`local_order`, on every rank)."""
    n = mat.getSize()[0]
    if n < MIN_ROWS or nearnull.attached(mat) or mat.getBlockSize() > 1:
        return ""
    dim = shape().dim if rows.shape[0] else 0
    coll = Collective(mat.getComm())
    if int(coll.max_array(np.array([dim]))[0]) != DIM or coll.any(not local_order(rows, mat.getOwnershipRange()[0])):
        return ""
    return (f"multilevel V-cycles in place of the two-level method (by the problem: a bare 2-D graph of {n} rows, at "
            f"least {MIN_ROWS}; -htp_variant twolevel keeps the two-level method)")


def local_order(rows, start) -> bool:
    """Whether coupled rows lie near each other in the numbering (every rank's sampled entries: the median |i - j|
    at most :data:`SPAN` sqrt(n)): the levels keep the rows' order, so a mesh numbered at random makes every product
    a random walk through memory (P1 triangles at 1M rows numbered at random: median |i - j| 247 331, V-cycles
    7.7 s against the two-level method's 5.4; the 2-D DMDA: 1)."""
    n = rows.shape[0]
    pick = np.linspace(0, n - 1, min(n, SAMPLE_ROWS)).astype(np.int64) if n else np.zeros(0, dtype=np.int64)
    where, which = row_entries(rows.indptr, pick)
    span = np.abs(rows.indices[where] - start - pick[which])
    local = float(np.median(span)) if span.size else 0.0
    return local <= SPAN * np.sqrt(max(n, 1))
