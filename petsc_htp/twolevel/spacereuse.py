"""Whether a numeric step keeps the coarse space W of an earlier one (``-htp_coarse_space_every k``), as GAMG's
``-pc_gamg_reuse_interpolation`` keeps its interpolation: the leaf factor, A W, W^T A W and the coarse solve are
refreshed, so M stays exact for the new values with a W made for older ones.

k >= 1 computes W at every k-th numeric setup. k = 0, the default, keeps W while it serves: for at most
:data:`AUTO_AGE` numeric setups, and only while the last solve took at most :data:`AUTO_GROWTH` times (plus
:data:`AUTO_SLACK`) the iterations of the first solve with it, so values that moved away from W cost one frame's
extra iterations before a new W. On the project's own frames in sequence mode W made one to three frames earlier
served as well as a fresh one (``petsc-htp bench --studies sequence``, README). The piece constants alone (the
const space of paired aggregation leaves) are made anew at every step under k = 0: they cost about what keeping
them does, and their row-scaled form follows new values that rescale the rows (:mod:`.scaling`). Any other space
is made anew, whatever k, where new values rescaled the rows (:class:`DiagonalWatch`).

Leaves whose couplings moved (:meth:`.structure.Structure.moved`) are made anew only where that pays
(:func:`keeps_leaves`): on the foreign study's sequences at 65 536 rows, whose coefficients move every frame,
frames with the old leaves took 114-132 against 139-188 ms (DMDA 2-D, 39-48 against 34-35 iterations), 83-105
against 131-151 (no-flux walls) and 120-176 against 491-614 (Q1 hexahedra, 27-30 against 16).
"""
from __future__ import annotations

import numpy as np

AUTO_AGE = 4            # auto: a coarse space serves at most this many numeric setups
AUTO_GROWTH = 1.25      # ... while the last solve took at most this times the iterations of the first with it
AUTO_SLACK = 2          # ... plus this many
RESCALED = 0.05         # median deviation of log(new / old |diagonal|) from its median above which W is made anew
WATCHED = 4096          # diagonal entries per rank that watch for a new row scaling


def keeps(every: int, age: int, its: list, renewed: bool = False) -> bool:
    """Whether the next numeric setup keeps a coarse space made ``age`` numeric setups ago under
    ``-htp_coarse_space_every every``, after solves since it was made that took ``its`` iterations (the first and the
    last); under k = 0 never a ``renewed`` one (the piece constants alone: :attr:`.space.CoarseSpace.renewed`)."""
    if every > 0:
        return age + 1 < every
    return not renewed and bool(its) and age + 1 < AUTO_AGE and its[-1] <= AUTO_GROWTH * its[0] + AUTO_SLACK


def keeps_leaves(analysis_ms: float, its: list, ms_per_it: float, penalty=None) -> bool:
    """Whether leaves whose couplings moved are kept: a new analysis would not pay back within one frame unless the
    extra iterations of the worst solve with them over the first (``its``: the first and the most since the
    analysis), at ``ms_per_it``, cost more than the analysis took (``analysis_ms``). After one solve only, what old
    leaves cost the last time values moved (``penalty``, ms; None: never measured, so they are tried) decides: the
    3-D DMDA frames otherwise took old leaves every other frame (58 against 26 iterations)."""
    cost = stale_cost(its, ms_per_it)
    cost = penalty if cost is None else cost
    return cost is None or cost <= analysis_ms


def stale_cost(its: list, ms_per_it: float):
    """The ms the worst solve with a pattern's leaves took beyond the first with them (``its``: the first and the
    most since the analysis), or None after one solve."""
    return (its[-1] - its[0]) * ms_per_it if len(its) > 1 else None


class DiagonalWatch:
    """A sample of A's diagonal as it was when W was made (``where``: the diagonal's positions in D's values), against
    which new values tell a new row scaling, D A D, which W made for the old one serves poorly (the eig space of a
    2-D Laplacian kept through D in 0.5 .. 2: 64 CG iterations against a new one's 30): the typical row's diagonal
    moved against the others'. A common factor, or a minority of rows that changed (an interface that moved), keeps
    W."""

    def __init__(self, where, coll):
        self.where, self.coll, self.at_made = where[::max(1, where.size // WATCHED)], coll, None

    def made(self, d_values):
        """W was made for these values."""
        self.at_made = np.abs(d_values[self.where])

    def rescaled(self, d_values) -> bool:
        """Whether new values rescaled the rows since W was made, on any rank (collective)."""
        spread = 0.0
        if self.at_made is not None:
            new = np.abs(d_values[self.where])
            ok = (new > 0) & (self.at_made > 0)
            r = np.log(new[ok]) - np.log(self.at_made[ok])
            spread = float(np.median(np.abs(r - np.median(r)))) if r.size else 0.0
        return bool(self.coll.max_array(np.array([spread]))[0] > RESCALED)
