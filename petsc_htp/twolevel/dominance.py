"""Diagonal dominance: where every coupled row's diagonal exceeds the sum of its off-diagonal magnitudes by a margin
c (a_ii >= (1 + c) sum_j |a_ij|: a mass matrix plus a time step's stiffness, a shifted operator), Gershgorin puts
Jacobi's preconditioned spectrum in [c / (1 + c), (2 + c) / (1 + c)], a condition number of at most (2 + c) / c
whatever N, and ICC(0) of the whole matrix converges in a number of iterations that no coarse space improves on for
its cost.

Measured (``results/dominance-20261126/run.py``: one rank, fresh KSP, CG to rtol 1e-8; A = K + c diag(sum_j
|k_ij|) for the foreign study's matrices K at 64k rows): at c = 0.003 ICC(0) of the whole matrix took 0.33-0.89 x the
two-level method's time (DMDA 2-D 77 against 138 ms, 3-D 66 against 201, free surface 67 against 107, log-normal
76 against 130, P1 triangles numbered at random 195 against 220; 1M rows of DMDA 1 856 against 3 540), at c = 0.01
0.23-0.52 x, at c = 0.001 0.44-1.34 x (the triangles, whose random numbering slows ICC(0), 299 against 224 ms), so
the rule starts at :data:`MARGIN` (a margin of 0.003 computed with rounding must pass). ICC(0)'s iterations (80 at c
= 0.003 in 2-D, 45 at 0.01) do not grow with N; the two-level method's cost per row does. PETSc-free.
"""
from __future__ import annotations

import numpy as np

from .csr import row_entries, row_sums

MARGIN = 0.0025     # dominance margin c from which ICC(0) of the whole matrix beats the two-level method
SAMPLE = 4096       # rows whose margin is looked at first
PINNED = 1e8        # a_ii / sum_j |a_ij| from which a row is pinned (a penalty's Dirichlet row: tgv = 1e30)
SOLVED = 1e2        # ... from which its own diagonal decides it: out of the scaling's quotients and, unless the
# pieces take row-scaled vectors, out of W (a penalty of 1e10 beside a coefficient of 1e4 is no pinned row: P1
# triangles of 40 000 rows with a checkerboard of 1 and 1e4 took 255 CG iterations, now 36, those of the same rows
# zeroed by MatZeroRowsColumns; under |diag|^-1/2 such rows of D A D hold their share of the near null vector D^-1 1:
# 98 iterations without them)
SCREEN = 1e3        # ... looked for only where a_ii exceeds this times the median of a sample of rows' ...
TYPICAL = 16384     # ... of this many rows at random, or of all (every 64th row's, on a square of side 128 whose rows
# were every other one a wall's penalty row, had been a penalty's: none looked at)


def margin(rows, start) -> float:
    """The smallest margin c_i = a_ii / sum_j |a_ij| - 1 (j != i) over this rank's ``rows`` (CSR, global columns,
    local rows from ``start``) that hold a nonzero off-diagonal entry (inf where none does; 0 or less where a
    diagonal is not above its row's off-diagonal sum), or, where every :data:`SAMPLE`-th row's already falls below
    :data:`MARGIN`, theirs: enough to tell, for a pass over a few thousand rows (28 against 0.2 ms at 1M rows)."""
    n = rows.shape[0]
    if n > 4 * SAMPLE:
        c = _smallest(rows, start, np.arange(0, n, n // SAMPLE))
        if c < MARGIN:
            return c
    return _smallest(rows, start, None)


def _smallest(rows, start, picked) -> float:
    """:func:`margin` over the rows ``picked`` (None: all)."""
    if picked is None:
        diag = rows.diagonal(k=start)
        total = row_sums(rows.indptr, np.abs(rows.data))
    else:
        where, owner = row_entries(rows.indptr, picked)
        on = rows.indices[where] == picked[owner] + start
        diag = np.bincount(owner[on], rows.data[where[on]], minlength=picked.size)
        total = np.bincount(owner, np.abs(rows.data[where]), minlength=picked.size)
    off = total - np.abs(diag)
    coupled = off > 0
    if not coupled.any():
        return float("inf")
    return float((diag[coupled] / off[coupled]).min() - 1.0)


def pinned(rows, start, coll=None) -> tuple:
    """(this rank's rows, local indices, that their own diagonal decides, a_ii >= :data:`SOLVED` sum_j |a_ij| > 0,
    and each one's a_ii / sum_j |a_ij|) (``rows``: CSR, global columns, local rows from ``start``): a penalty method's
    Dirichlet rows, pinned from :data:`PINNED`. In W they would put a_ii into E = W^T A W beside the piece's other
    entries, which rounding then loses (tgv = 1e30 on P1 triangles: a "converged" CG at a true residual of 0.56, the
    balanced form indefinite); the leaf solve takes them exactly. Only rows whose diagonal passes :data:`SCREEN` times
    a typical one are looked at (6 ms at 1M rows): the least over the ranks (``coll``, collective; a rank whose rows
    are mostly a penalty's, boundary rows numbered last, took its own median for typical and none of its rows: 377 CG
    iterations on 9 ranks against 25 on one)."""
    diag = np.abs(rows.diagonal(k=start))
    sample = diag if diag.size <= TYPICAL else diag[np.random.default_rng(0).integers(0, diag.size, TYPICAL)]
    typical = np.median(sample) if sample.size else np.inf
    if coll is not None:
        typical = float(coll.min_array(np.array([typical]))[0])
    if not diag.size:
        return np.zeros(0, dtype=np.int64), np.zeros(0)
    high = np.flatnonzero(diag > SCREEN * typical)
    where, owner = row_entries(rows.indptr, high)
    offdiag = rows.indices[where] != high[owner] + start            # summed apart: 1e30 + 4 - 1e30 is 0
    off = np.bincount(owner[offdiag], np.abs(rows.data[where[offdiag]]), minlength=high.size)
    keep = (off > 0) & (diag[high] >= SOLVED * off)
    return high[keep], diag[high][keep] / off[keep]


def left_out(solved, ratios, weighted) -> tuple:
    """(this rank's rows W leaves out, the bound they pass): those their own diagonal decides (``solved``, with their
    ``ratios``: :func:`pinned`), but under row-scaled piece vectors (``weighted``), which weigh them by |a_ii|^-1/2
    already, only the pinned ones (:data:`PINNED`)."""
    return (solved[ratios >= PINNED], PINNED) if weighted else (solved, SOLVED)


def holds(rows, start) -> bool:
    """Whether this rank's ``rows`` (their diagonal in column ``start`` + row) are still dominant by :data:`MARGIN`."""
    return margin(rows, start) >= MARGIN


def describe(c) -> str:
    """Why ICC(0) serves a matrix of margin ``c`` (``-ksp_view``)."""
    if c == float("inf"):
        return "its rows hold no nonzero off-diagonal entry: ICC(0) is exact"
    return (f"its rows are diagonally dominant (every diagonal at least {1 + c:.4g} x its row's off-diagonal sum): "
            f"Jacobi's condition number is at most {(2 + c) / c:.3g} at any size, and no coarse space pays")
