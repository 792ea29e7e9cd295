"""The ball growth of a matrix's whole graph over the ranks (not of a rank's diagonal block), for the no-mesh rule
(:data:`.sizing.EXPANDER_GROWTH`) on several ranks.

A rank's diagonal block of a mesh is a mesh, or in a scattered numbering fragments that grow less, so the block's
growth decides wherever the ranks' rows hang together. Where a large share of the couplings crosses ranks
(:func:`petsc_htp.ranksplit.crossing`) the blocks keep too few of them to tell: a random graph of both signs
(``results/expander-20261126/run.py``, 60 000 rows) split over 2 ranks kept about 3 couplings a row in each block,
which grew as 3.0 (meshes: 1.6-2.7), and took the two-level method's 909 ms of setup (a dense coarse hierarchy)
where ICC(0) of each block took 25 ms in all. There the balls are grown in the whole graph (:func:`global_growth`,
4.9 there; P1 triangles and tets numbered at random, ``examples/matrix_file.py -case fem_tri``, 1.8 and 2.7).
Collective.
"""
from __future__ import annotations

import numpy as np

from .csr import row_entries
from .graphshape import RADIUS, hub_rows
from .sizing import SPLIT_PAIRED

CROSSING = SPLIT_PAIRED  # share of off-diagonal couplings between ranks from which the whole graph's growth counts
# (meshes in their program's order: 0.2 % on 2 ranks; rows at random over p ranks: 1 - 1/p)
SAMPLES = 8         # seeds whose balls are grown


def _seeds(rows, start, N, coll, hub, rng, samples=SAMPLES) -> np.ndarray:
    """Up to ``samples`` global rows with a nonzero off-diagonal entry, none of them a ``hub`` (this rank's rows'
    flags), the same on every rank."""
    candidates = rng.choice(N, min(N, 8 * samples), replace=False)
    coupled = np.zeros(candidates.size)
    mine = np.flatnonzero((candidates >= start) & (candidates < start + rows.shape[0]))
    if mine.size:
        where, owner = row_entries(rows.indptr, candidates[mine] - start)
        hit = (rows.data[where] != 0) & (rows.indices[where] != candidates[mine][owner])
        coupled[mine] = (np.bincount(owner[hit], minlength=mine.size) > 0) & ~hub[candidates[mine] - start]
    return candidates[coll.max_array(coupled) > 0][:samples]


def global_growth(mat, rows, coll, seed=0, samples=SAMPLES) -> float:
    """The ball-growth exponent of the whole graph of ``mat`` (median of log2 |B(2R)| / |B(R)| over ``samples`` seeds, R =
    :data:`.graphshape.RADIUS`): a breadth-first search from the seeds whose balls every rank holds, each rank
    expanding the rows it owns and one allgather of the rows reached per step (the work is the balls' size, as in
    :func:`.graphshape.graph_shape`: 1-6 ms at 64k rows); hub rows (:func:`.graphshape.hub_rows`) are reached but
    neither grown through nor seeds. nan where too few coupled rows were found."""
    N, (start, end) = mat.getSize()[0], mat.getOwnershipRange()
    hub = hub_rows(rows.indptr)
    seeds = _seeds(rows, start, N, coll, hub, np.random.default_rng(seed), samples)
    if seeds.size < samples:
        return float("nan")
    ball = frontier = np.sort(np.arange(seeds.size, dtype=np.int64) * N + seeds)
    sizes = []
    for step in range(1, 2 * RADIUS + 1):
        seed_of, row = frontier // N, frontier % N - start
        grow = (row >= 0) & (row < end - start)                  # this rank's rows, hubs not grown through
        grow[grow] = ~hub[row[grow]]
        seed_of, row = seed_of[grow], row[grow]
        where, owner = row_entries(rows.indptr, row)
        live = rows.data[where] != 0
        reached = seed_of[owner[live]] * N + rows.indices[where[live]]
        reached = np.unique(coll.gather_rows(reached.reshape(-1, 1)).ravel())
        frontier = reached[~np.isin(reached, ball, assume_unique=True)]
        ball = np.union1d(ball, frontier)
        if step in (RADIUS, 2 * RADIUS):
            sizes.append(np.bincount(ball // N, minlength=seeds.size))
    return float(np.median(np.log2(sizes[1] / sizes[0])))
