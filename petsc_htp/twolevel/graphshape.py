"""What a bare matrix's graph shows: its dimension and how anisotropic its couplings are.

The dimension comes from how fast graph balls grow: a ball of radius r holds about r^d rows, so
d ~ log(|B(2R)| / |B(R)|) / log 2 over a few sampled rows (5-point and 9-point stencils and triangle meshes
give 1.6-1.7, 7-point stencils and tet meshes 2.3-2.6; the cut is :data:`CUT`). The mean number of nonzeros
per row cannot tell a 9-point 2-D stencil or a triangle mesh from a 3-D one. The anisotropy is the share of
off-diagonal couplings that are weak in smoothed aggregation's sense; the share that is positive tells rotated
anisotropy's stencils from a mesh Laplacian's rows. Cheap: a breadth-first search from ``SAMPLES`` rows, whose
work is the balls' size (by sparse products where rows are rich), and the strength threshold, weak and positive
shares of :data:`~.aggregation.SAMPLE_ROWS` rows with the diagonal;
no other pass over the whole matrix (1.1-7 ms at 64k rows and 5-17 ms at 1M on the foreign study's matrices,
against 3.5-16 and 53-119 ms with a pass that removed stored zeros first; small matrices by one compiled
shortest-path search). PETSc-free.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from .aggregation import sampled_shares, threshold
from .csr import row_entries

SAMPLES = 16        # rows whose balls are grown
RADIUS = 2          # the balls compared have radius RADIUS and 2 RADIUS
CUT = 2.0           # growth exponent above which the graph is taken as 3-D
PRODUCTS = (60000, 8.0, 2000000)   # the balls grow by sparse products up to this many stored entries, or with
                                    # more stored entries per row than this up to this many (:func:`_by_products`)
DENSE_PRODUCTS = (64.0, 32000000)   # ... or with more than this many a row (Q2 vector blocks) up to this many
PATHS = 2 ** 17     # rows times seeds up to which one compiled shortest-path search grows the balls (_by_paths)
HUB = 16            # rows holding more than HUB times the median row's stored entries are not grown through


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
    theta : float
        The strength threshold (:func:`~.aggregation.threshold`).
    positive : float
        Share of sampled nonzero off-diagonal couplings that are positive (rotated anisotropy's 9-point stencils: a
        quarter; P1 triangles of a Delaunay mesh and 5-point stencils: none); nan where not measured.
    largest : numpy.ndarray or None
        The sampled rows' largest shares (:func:`~.aggregation.sampled_shares`), from which ``theta`` came.
    """

    dim: int
    growth: float
    weak: float
    theta: float = float("nan")
    positive: float = float("nan")
    largest: object = None

    def describe(self) -> str:
        """One line for ``-ksp_view``."""
        growth = "n/a" if np.isnan(self.growth) else f"{self.growth:.2f}"
        weak = "" if np.isnan(self.weak) else f", {100 * self.weak:.0f}% weak couplings (at {self.theta:.3g})"
        weak += "" if np.isnan(self.positive) else f", {100 * self.positive:.0f}% positive"
        return f"graph: {self.dim}-D (ball growth exponent {growth}){weak}"


def _ball_sizes_by_products(A, seeds, radius) -> np.ndarray:
    """:func:`_ball_sizes` by sparse products Y <- Y + Y P (Y: the balls as rows, P: the nonzero pattern) in
    scipy's compiled code. Building P reads every entry once, but where rows are rich the breadth-first search's
    numpy work on the balls costs more (:func:`_by_products`)."""
    n = A.shape[0]
    P = sp.csr_matrix(((A.data != 0).astype(np.float64), A.indices, A.indptr), shape=A.shape)
    Y = sp.csr_matrix((np.ones(seeds.size), (np.arange(seeds.size), seeds)), shape=(seeds.size, n))
    out = []
    for step in range(1, 2 * radius + 1):
        Y = Y + Y @ P                    # positive values: no cancellation; a product of stored zeros is dropped
        if step in (radius, 2 * radius):
            out.append(Y.getnnz(axis=1))
    return np.array(out, dtype=float)


def _ball_sizes_by_paths(A, seeds, radius) -> np.ndarray:
    """:func:`_ball_sizes` by scipy's compiled unweighted shortest paths from the seeds, cut at ``2 radius``: one
    call, whose (seeds, n) distance table keeps it to small matrices (:data:`PATHS`); 0.1-0.2 against 0.25-0.4 ms
    by the other searches on the foreign study's 5- and 7-point matrices at 1 000-8 000 rows."""
    from scipy.sparse.csgraph import dijkstra

    live = A.data != 0                                              # stored zeros couple nothing
    running = np.concatenate(([0], np.cumsum(live)))
    P = sp.csr_matrix((np.ones(int(running[-1])), A.indices[live], running[A.indptr]), shape=A.shape)
    dist = dijkstra(P, indices=seeds, unweighted=True, limit=2 * radius + 0.5)
    return np.array([(dist <= radius).sum(axis=1), (dist <= 2 * radius).sum(axis=1)], dtype=float)


def _by_products(A) -> bool:
    """Whether :func:`_ball_sizes_by_products` is the cheaper search for ``A`` (:data:`PRODUCTS`): on the foreign study's
    matrices 2.5-4.1 against 0.7-1.9 ms on P1 tets at 1 000-64 000 rows, 0.4-0.6 against 0.4 ms on 5-point
    stencils and triangles up to 8 000, but 0.4-0.9 against 0.7-1.5 ms on 5- and 7-point stencils at 64 000.
    Rows of :data:`DENSE_PRODUCTS` entries make the searched balls hold most of a moderate matrix: PETSc's snes ex62
    velocity block (3-D Q2, 36 501 rows of 162 entries) 50 against 481 ms, where P1 tets and Q1 hexahedra at 262 144
    rows (15 and 27 a row) take 5-7 ms either way."""
    small, rich, most = PRODUCTS
    per_row = A.nnz / max(A.shape[0], 1)
    return A.nnz <= small or (per_row > rich and A.nnz <= most) or (
        per_row > DENSE_PRODUCTS[0] and A.nnz <= DENSE_PRODUCTS[1])


def _ball_sizes(A, seeds, radius) -> np.ndarray:
    """Rows within graph distance ``radius`` and ``2 radius`` of each seed in the graph of ``A``'s nonzero entries:
    an array (2, seeds). Breadth-first over all seeds at once on (seed, row) keys, expanding only each step's new
    rows, so the work is the balls' size times the degree, not the matrix's."""
    n = A.shape[0]
    ball = frontier = np.sort(np.arange(seeds.size, dtype=np.int64) * n + seeds)
    out = []
    for step in range(1, 2 * radius + 1):
        seed_of, row = frontier // n, frontier % n
        where, owner = row_entries(A.indptr, row)
        live = A.data[where] != 0                                      # stored zeros couple nothing
        reached = np.unique(seed_of[owner[live]] * n + A.indices[where[live]])
        frontier = reached[~np.isin(reached, ball, assume_unique=True)]
        ball = np.union1d(ball, frontier)
        if step in (radius, 2 * radius):
            out.append(np.bincount(ball // n, minlength=seeds.size))
    return np.array(out, dtype=float)


def hub_rows(indptr, least=0.0) -> np.ndarray:
    """Which rows of a CSR matrix with row pointer ``indptr`` hold more than :data:`HUB` times the median row's
    stored entries (a sample's median) and more than ``least``: dense rows, such as a constraint's or a ground
    node's."""
    count = np.diff(indptr)
    typical = float(np.median(count[::max(1, count.size // 4096)])) if count.size else 0.0
    return count > max(HUB * max(typical, 1.0), least)


def _without_hubs(A):
    """``A``, or where some rows are hubs (:func:`hub_rows`) a copy in which those rows couple nothing, so the balls
    reach them but do not grow through them: an arrow matrix's dense row put every row within distance 2 of every
    seed, and the search over a 20 000-row one took 1.1 s (the dimension then came out as that of the rest of the
    graph)."""
    hub = hub_rows(A.indptr)
    if not hub.any():
        return A
    data = A.data.copy()
    data[np.repeat(hub, np.diff(A.indptr))] = 0.0
    return sp.csr_matrix((data, A.indices, A.indptr), shape=A.shape)


def _coupled_seeds(A, samples, rng) -> np.ndarray:
    """``samples`` distinct random rows with a nonzero off-diagonal entry (fewer where the matrix has fewer):
    random candidates first, a scan of every row only where they fall short."""
    n = A.shape[0]

    def coupled(rows):
        where, owner = row_entries(A.indptr, rows)
        hit = (A.data[where] != 0) & (A.indices[where] != rows[owner])
        return rows[np.bincount(owner[hit], minlength=rows.size) > 0]

    found = coupled(rng.choice(n, min(n, 4 * samples), replace=False))
    if found.size < samples:
        found = coupled(np.arange(n))
    return rng.choice(found, min(samples, found.size), replace=False)


def graph_shape(A, seed=0, want_weak=True, samples=SAMPLES) -> GraphShape:
    """The shape of a square CSR ``A``'s graph (nonzero entries only) from ``samples`` balls; ``want_weak``
    False leaves the strength threshold and the share of weak couplings out (nan), when only the dimension is
    wanted."""
    theta = weak = positive = float("nan")
    largest = None
    if want_weak:
        share, largest, positive = sampled_shares(A)
        theta = threshold(largest)
        weak = float(np.mean(share < theta)) if share.size else 0.0
    seeds = _coupled_seeds(A, samples, np.random.default_rng(seed))
    if seeds.size < samples:
        return GraphShape(2, float("nan"), weak, theta, positive, largest)
    if A.shape[0] * seeds.size <= PATHS:
        balls = _ball_sizes_by_paths
    else:
        balls = _ball_sizes_by_products if _by_products(A) else _ball_sizes
    small, large = balls(_without_hubs(A), seeds.astype(np.int64), RADIUS)
    growth = float(np.median(np.log2(large / small)))
    return GraphShape(3 if growth > CUT else 2, growth, weak, theta, positive, largest)
