"""When HTPPC as it comes runs the multilevel V-cycles in place of the two-level method: a bare, scalar 2-D graph, or
a 3-D one whose couplings are not positive (:func:`signed`), of at least :data:`MIN_ROWS` rows, where their
iterations (about half the two-level method's) pay for a costlier application and the hierarchy's setup costs less
than the two-level method's analysis and coarse solve."""
from __future__ import annotations

import numpy as np

from ..collective import Collective
from ..twolevel import nearnull
from ..twolevel.blocksize import block_size
from ..twolevel.csr import row_entries
from ..twolevel.graphshape import hub_rows

MIN_ROWS = 30_000       # rows from which the V-cycles serve a bare 2-D graph (one rank, single solves, CG to 1e-8,
# setup + solve ms, two-level against multilevel with its Jacobi smoother, 2026-11-28: 32 768 rows dmda2d 100 / 64,
# lognormal 76 / 52, fem_tri 132 / 111, neumann 78 / 92; 65 536 rows dmda2d 186 / 107, free_surface 105 / 72,
# lognormal 144 / 99, neumann 174 / 136, fem_tri 266 / 246; 16 384 rows level within 10 %, and with Gauss-Seidel
# 40-25 % less on the DMDA, log-normal and Neumann cases, but a random field of 1e4 edges (a fifth of them) took 71
# CG iterations there against the two-level method's 21, as at 65 536 rows 103 against 22 (pyamg's smoothed
# aggregation 361, AMGCL 669: results/gs-20261128/salt.txt)
DIMS = (2, 3)           # the graphs' dimensions the V-cycles serve (3-D: see POSITIVE)
POSITIVE = 0.05         # share of a 3-D graph's sampled off-diagonal couplings above which it keeps the two-level
# method: P1 tetrahedra (a third positive) took 1.5 x its time with any smoother, the 7-point DMDA matrix (none)
# 0.6-0.8 x (results/threed-20261129)
SPAN = 4.0              # see local_order
SAMPLE_ROWS = 4096      # rows whose entries local_order and signed measure


def serves(mat, rows, shape) -> tuple:
    """(why the V-cycles serve ``mat`` (this rank's ``rows``; ``shape()`` gives its diagonal block's
    :class:`..twolevel.graphshape.GraphShape`, the whole-matrix choice's, found once), or '' | whether its rows are
    to be taken in their leaves' order | the graph's dimension) (collective): at
    least :data:`MIN_ROWS` rows, a scalar problem (:func:`unscalar`), a 2-D graph, or a 3-D one not :func:`signed`,
    and, on several ranks, rows in a local order (:func:`local_order`, on every rank). One rank takes rows numbered
    at random in their leaves' order (P1 triangles, CG to 1e-8, setup + solve ms against the two-level method's,
    2026-11-28, results/gs-20261128/run.txt: 1 048 576 rows 9 763 / 19 512 (18 / 38 iterations), 262 144 rows
    1 620 / 2 947 (17 / 37), 65 536 rows 412 / 465 (16 / 34); a sequence frame at 65 536 rows 339-385 / 335-359
    (24-27 / 50-57, frames65536.txt)); on two ranks split at random the V-cycles' set-up took 44 s (the two-level
    method 0.34)."""
    n = mat.getSize()[0]
    dim = 0 if n < MIN_ROWS or unscalar(mat, rows) else dimension(mat, rows, shape)
    if dim not in DIMS or dim == 3 and signed(mat, rows):
        return "", False, dim
    coll = Collective(mat.getComm())
    local = not coll.any(not local_order(rows, mat.getOwnershipRange()[0]))
    if coll.size > 1 and not local:
        return "", False, dim
    order = "" if local else ", numbered at random: its rows taken in their leaves' order"
    kind = "" if dim == 2 else f", at most {100 * POSITIVE:.0f}% of its couplings positive"
    return (f"multilevel V-cycles in place of the two-level method (by the problem: a bare {dim}-D graph of {n} rows, "
            f"at least {MIN_ROWS}{kind}{order}; -htp_variant twolevel keeps the two-level method)"), not local, dim


def fixed_point(mat, rows, shape) -> tuple:
    """(why | reorder | dimension), as :func:`serves` says them, for a bare matrix under KSPRICHARDSON that
    :func:`serves` declined: a scalar 3-D graph of any size above the whole-matrix factors', in any order. The
    two-level method's leaf solves put eigenvalues of M A above 2 there, which a fixed-point iteration does not
    survive, while the V-cycles' smoothers are damped below it (P1 tets at 12 000 and 30 000 rows: DIVERGED_DTOL after
    81 and 85 steps, the backward-Euler tets after 1 907 and 71, on 2 ranks split at random none in 10 000; V-cycles
    122, 147, 108 and 121 steps, on 2 ranks 366 and at 64 000 rows 283; PETSc's GAMG 206 at 30 000; 2-D graphs
    converge under the two-level method: results/kspsweep-20261129/sweep.txt). Collective."""
    if unscalar(mat, rows) or dimension(mat, rows, shape) != 3:
        return "", False, 0
    local = not Collective(mat.getComm()).any(not local_order(rows, mat.getOwnershipRange()[0]))
    return ("multilevel V-cycles in place of the two-level method (by the KSP: a fixed-point iteration, KSPRICHARDSON, "
            "which the leaf solves' M A, above 2 on a 3-D graph, makes diverge; -htp_variant twolevel keeps the "
            "two-level method)"), not local, 3


def signed(mat, rows) -> bool:
    """Whether more than :data:`POSITIVE` of the nonzero off-diagonal couplings of :data:`SAMPLE_ROWS` evenly spaced
    rows are positive on some rank (``rows``: this rank's; collective)."""
    n, start = rows.shape[0], mat.getOwnershipRange()[0]
    pick = np.linspace(0, n - 1, min(n, SAMPLE_ROWS)).astype(np.int64) if n else np.zeros(0, dtype=np.int64)
    where, which = row_entries(rows.indptr, pick)
    value = rows.data[where]
    off = (value != 0) & (rows.indices[where] != start + pick[which])
    share = float(np.mean(value[off] > 0)) if off.any() else 0.0
    return Collective(mat.getComm()).any(share > POSITIVE)


def unscalar(mat, rows, option=0) -> str:
    """What keeps the V-cycles, whose coarse vectors are constants, from ``mat`` (this rank's ``rows``), or ''
    (collective): a near null space of its own, a null space of vectors (D A D's null vector D^-1 1 at 22 500 rows:
    251 CG iterations, where the two-level method takes that vector into its coarse space), a block size
    (``-htp_block_size``, ``option``, where set; else the Mat's or its pattern's: :mod:`..twolevel.blocksize`,
    elasticity handed over as a plain AIJ), or a dense row
    (:func:`..twolevel.graphshape.hub_rows`, more than sqrt(N) entries: a constraint's or a ground node's), which
    the smoothed coarse vectors spread into dense Galerkin operators (three hubs each coupled to 8 000 of a 200^2
    grid's rows: 354 s)."""
    coll = Collective(mat.getComm())
    if nearnull.attached(mat):
        return "the Mat's near null space"
    if not constant_null(mat):
        return "a null space of vectors other than the constant (the coarse vectors are constants)"
    bs, source = block_size(mat, rows, coll, option)
    if bs > 1:
        return f"block size {bs} ({source})"
    if coll.any(hub_rows(rows.indptr, mat.getSize()[0] ** 0.5).any()):
        return "a dense row (its couplings would fill every coarse level)"
    return ""


def constant_null(mat) -> bool:
    """Whether ``mat``'s null space, where attached, is the constant: PETSc's flag, or one vector whose entries agree
    to 1e-12 of their largest (a user's vector of ones; collective)."""
    null = mat.getNullSpace()
    vecs = null.getVecs() if null.handle else []
    if not vecs:
        return True
    if len(vecs) > 1 or null.hasConstant():
        return False
    low, high = vecs[0].min()[1], vecs[0].max()[1]
    return high - low <= 1e-12 * max(abs(low), abs(high))


def dimension(mat, rows, shape) -> int:
    """The largest dimension of the ranks' graphs (``shape()``: this rank's :class:`..twolevel.graphshape.GraphShape`;
    0 on a rank without rows; collective)."""
    dim = shape().dim if rows.shape[0] else 0
    return int(Collective(mat.getComm()).max_array(np.array([dim]))[0])


def local_order(rows, start) -> bool:
    """Whether coupled rows lie near each other in the numbering (every rank's sampled entries: the median |i - j|
    at most :data:`SPAN` sqrt(n)): the levels keep the rows' order, so a mesh numbered at random makes every product
    a random walk through memory (P1 triangles at 1M rows numbered at random: median |i - j| 247 331, V-cycles
    7.7 s against the two-level method's 5.4, before the levels took the rows in their leaves' order; the 2-D DMDA:
    1)."""
    n = rows.shape[0]
    pick = np.linspace(0, n - 1, min(n, SAMPLE_ROWS)).astype(np.int64) if n else np.zeros(0, dtype=np.int64)
    where, which = row_entries(rows.indptr, pick)
    span = np.abs(rows.indices[where] - start - pick[which])
    local = float(np.median(span)) if span.size else 0.0
    return local <= SPAN * np.sqrt(max(n, 1))
