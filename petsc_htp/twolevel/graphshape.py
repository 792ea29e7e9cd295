"""What a bare matrix's graph shows: its dimension and how anisotropic its couplings are.

The dimension comes from how fast graph balls grow: a ball of radius r holds about r^d rows, so
d ~ log(|B(2R)| / |B(R)|) / log 2 over a few sampled rows (5-point and 9-point stencils and triangle meshes
give 1.6-1.7, 7-point stencils and tet meshes 2.3-2.6; the cut is :data:`CUT`). The mean number of nonzeros
per row cannot tell a 9-point 2-D stencil or a triangle mesh from a 3-D one. The anisotropy is the share of
off-diagonal couplings that are weak in smoothed aggregation's sense. Cheap: a breadth-first search from
``SAMPLES`` rows, whose work is the balls' size. PETSc-free.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .aggregation import THETA

SAMPLES = 16        # rows whose balls are grown
RADIUS = 2          # the balls compared have radius RADIUS and 2 RADIUS
WEAK_ROWS = 4096    # rows sampled for the share of weak couplings
CUT = 2.0           # growth exponent above which the graph is taken as 3-D


@dataclass(frozen=True)
class GraphShape:
    """What the graph showed.

    Attributes
    ----------
    dim : int
        2 or 3.
    growth : float
        The measured ball-growth exponent (nan where too few coupled rows were sampled).
    weak : float
        Share of nonzero off-diagonal couplings below the strength threshold.
    """

    dim: int
    growth: float
    weak: float

    def describe(self) -> str:
        """One line for ``-ksp_view``."""
        growth = "n/a" if np.isnan(self.growth) else f"{self.growth:.2f}"
        weak = "" if np.isnan(self.weak) else f", {100 * self.weak:.0f}% weak couplings"
        return f"graph: {self.dim}-D (ball growth exponent {growth}){weak}"


def _ball_sizes(indptr, indices, seeds, radius) -> np.ndarray:
    """Rows within graph distance ``radius`` and ``2 radius`` of each seed: an array (2, seeds). Breadth-first
    over all seeds at once on (seed, row) keys, expanding only each step's new rows, so the work is the balls'
    size times the degree, not the matrix's."""
    n = indptr.size - 1
    ball = frontier = np.sort(np.arange(seeds.size) * n + seeds)
    out = []
    for step in range(1, 2 * radius + 1):
        seed_of, row = frontier // n, frontier % n
        start, count = indptr[row], indptr[row + 1] - indptr[row]
        within = np.arange(int(count.sum())) - np.repeat(np.cumsum(count) - count, count)
        reached = np.unique(np.repeat(seed_of, count) * n + indices[np.repeat(start, count) + within])
        frontier = reached[~np.isin(reached, ball, assume_unique=True)]
        ball = np.union1d(ball, frontier)
        if step in (radius, 2 * radius):
            out.append(np.bincount(ball // n, minlength=seeds.size))
    return np.array(out, dtype=float)


def _weak_share(A, every) -> float:
    """Share of the nonzero off-diagonal couplings of every ``every``-th row that are weak."""
    diag = np.abs(A.diagonal())
    sub = A[::every]
    rows = np.repeat(np.arange(0, A.shape[0], every), np.diff(sub.indptr))
    off = (sub.data != 0) & (sub.indices != rows)
    strong = np.abs(sub.data[off]) >= THETA * np.sqrt(diag[rows[off]] * diag[sub.indices[off]])
    return float(1.0 - strong.mean()) if strong.size else 0.0


def graph_shape(A, seed=0, weak=True, samples=SAMPLES) -> GraphShape:
    """The shape of a square CSR ``A``'s graph (nonzero entries only) from ``samples`` balls; ``weak`` False
    leaves the share of weak couplings out (nan), when only the dimension is wanted."""
    n = A.shape[0]
    rows = np.repeat(np.arange(n), np.diff(A.indptr))
    off = (A.data != 0) & (A.indices != rows)
    weak = _weak_share(A, max(1, n // WEAK_ROWS)) if weak else float("nan")
    coupled = np.flatnonzero(np.bincount(rows[off], minlength=n) > 0)
    if coupled.size < samples:
        return GraphShape(2, float("nan"), weak)
    indptr = np.concatenate(([0], np.cumsum(np.bincount(rows[off], minlength=n))))
    seeds = np.random.default_rng(seed).choice(coupled, samples, replace=False)
    small, large = _ball_sizes(indptr, A.indices[off].astype(np.int64), seeds, RADIUS)
    growth = float(np.median(np.log2(large / small)))
    return GraphShape(3 if growth > CUT else 2, growth, weak)
