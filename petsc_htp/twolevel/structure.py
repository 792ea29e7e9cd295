"""The pattern-fixed structure of the two-level method on one rank: what the analysis of a nonzero pattern
decides, in numpy (collectives carry only sizes, offsets and the components' edges).

The problem's shape and dimension (:mod:`.graphshape`, :mod:`.sizing`), the leaves (:mod:`.leaves`) and their
layout (:mod:`.leaflayout`), the global piece numbering and A's connected components (:mod:`.nullspace`), the
coarse columns of every leaf and W's pattern, and for aggregation leaves where their weak couplings sit (new
values that moved the couplings call for new leaves: :meth:`Structure.moved`).
"""
from __future__ import annotations

import dataclasses

import numpy as np

from . import blocksize, coarseorder, nearnull, nullspace, sizing
from ..collective import Collective
from ..petscmat import diagonal_block, ghost_values
from ..ranksplit import crossing, cut_rows
from .aggregation import THETA, sampled_shares, threshold
from .csr import compact, row_entries
from .graphshape import graph_shape, hub_rows
from .leaflayout import layout
from .leaves import choose_leaves

WEAK_GROWTH = 2.0       # aggregation leaves are made anew once they hold this many times their weak couplings
SEVERE = 1e-4           # a share this weak inside a leaf (a contrast of about 1e7 or more) is never left to old leaves
WEAK_ROWS = 8192        # rows of D whose couplings inside the leaves are counted (every k-th): at 1M rows the count
# over all 2.6 million took 0.25 s of the analysis and again of every sequence frame, and its maps 50 MB; at 65 536
# rows, a sample of every k-th coupling (131 072 at most) still 4 ms


def _growth(shape) -> float:
    """The graph's ball growth exponent, inf where not measured (coordinates attached, too few coupled rows)."""
    return np.inf if shape is None or np.isnan(shape.growth) else shape.growth


class Structure:
    """The analysis of one pattern (see the module docstring).

    Parameters
    ----------
    mat : petsc4py.PETSc.Mat
        The operator (sizes, ownership, and one scatter for other ranks' pieces).
    rows : scipy.sparse.csr_matrix
        This rank's rows of ``mat`` (global columns, sorted).
    coords : numpy.ndarray (n, d), optional
        This rank's row coordinates (Morton leaves).
    cfg : Config
    net_rank : int, optional
        The coarse network's vectors per leaf (learned coarse space).
    """

    def __init__(self, mat, rows, coords, cfg, net_rank=None):
        self.coll, self.N = Collective(mat.getComm()), mat.getSize()[0]
        with diagonal_block(mat, rows) as block:
            self._leaves(mat, rows, block, coords, cfg)
        self.lay = layout(rows, mat.getOwnershipRange()[0], self.leaves)
        self._components(mat, rows)
        self._columns(net_rank, rows)
        self._weak = None
        if self.leaves.kind == "aggregation":
            self.weak_made = self._weak_inside(rows.data)     # its sampled maps are kept for moved()
            self.severe_made = self._weak_inside(rows.data, SEVERE)

    def _leaves(self, mat, rows, block, coords, cfg):
        """What the graph of this rank's diagonal ``block`` shows, the problem-sized configuration and the leaves;
        the block is kept (:attr:`block`, a copy on several ranks) only for a learned coarse space's network."""
        coll = self.coll
        self.shape = graph_shape(block) if coords is None else None
        local = sizing.dimension(None if coords is None else coords.shape[1], self.shape)
        self.dim = int(coll.max_array(np.array([local]))[0])
        self.auto = [name for name, unset in (("leaf", cfg.leaf == 0), ("coarse", cfg.coarse == "auto"),
                                              ("aggregation", cfg.aggregation == "auto")) if unset]
        self.bs, self.bs_source = blocksize.block_size(mat, rows, coll, cfg.block_size)
        self.fixed, self.attached = nearnull.count(mat, self.bs), nearnull.attached(mat)
        self.covered = bool(coll.min_array(np.array([nearnull.spans_constant(mat)], dtype=np.int64))[0])
        self.per_row = coll.sum(rows.nnz) / max(self.N, 1)
        growth, hubs = coll.max_array(np.array([_growth(self.shape)]))[0], hub_rows(rows.indptr, self.N ** 0.5).any()
        self.linear, self.dense = sizing.chain(growth, self.per_row), coll.any(hubs)       # dense: a dense row
        positive = 1.0 if self.shape is None or np.isnan(self.shape.positive) else self.shape.positive
        self.positive = float(coll.max_array(np.array([positive]))[0])
        self.split = (crossing(mat, rows, coll, rows.data != 0) or (1, 0.0))[1]    # couplings that join two ranks
        self.cfg = cfg = self.resolved(cfg, coords is None)
        largest = (self.shape.largest if self.shape is not None else None if cfg.ordering != "aggregation"
                   else sampled_shares(block)[1])                     # coordinates: aggregation leaves if asked
        # from every rank's sampled rows together (the least of the ranks' own: a rank of penalty rows set 5e-7)
        self.theta = THETA if largest is None else threshold(coll.gather_rows(largest[:, None]).ravel())
        self.leaves = choose_leaves(block, coords, cfg.ordering, cfg.leaf, self.bs, cfg.aggregation,
                                    self.theta, mat.getOwnershipRange()[0] % self.bs, cut_rows(rows, block))
        learned = cfg.coarse == "learned"             # only the network reads the block again (the analysis)
        self.block = (block if coll.size == 1 else block.copy()) if learned else None

    def _weak_maps(self) -> tuple:
        """Where the off-diagonal entries of every ``stride``-th row of D (about :data:`WEAK_ROWS` rows) sit in A's
        values, and where the diagonal entries of their rows and of their columns sit; made on first use and kept."""
        if self._weak is None:
            lay = self.lay
            self.stride = max(1, lay.n // WEAK_ROWS)
            picked = np.arange(0, lay.n, self.stride)
            where, owner = row_entries(lay.d_indptr, picked)
            r, c = picked[owner], lay.d_indices[where]
            off = r != c
            diag_src = lay.d_src[lay.d_diag[lay.d_leaf_row[r[off]]]], lay.d_src[lay.d_diag[lay.d_leaf_row[c[off]]]]
            self._weak = (lay.d_src[where[off]],) + diag_src
        return self._weak

    def resolved(self, cfg, bare):
        """``cfg`` with its problem-sized fields (leaf 0, coarse and aggregation auto) set for this matrix, ``bare``
        (no coordinates: 'auto' ordering makes aggregation leaves) and its near null vectors (:mod:`.sizing`)."""
        second = (cfg.aggregation if cfg.aggregation != "auto"
                  else sizing.aggregation(self.dim, self.fixed, self.per_row, cfg.coarse, self.positive,
                                          self.attached, self.split))
        paired = second == "pairs" and (cfg.ordering == "aggregation" or (cfg.ordering == "auto" and bare))
        coarse = sizing.coarse_space(self.dim, self.fixed, paired) if cfg.coarse == "auto" else cfg.coarse
        return dataclasses.replace(cfg, leaf=cfg.leaf or sizing.leaf_size(self.dim, self.N), coarse=coarse,
                                   aggregation=second)

    def _weak_inside(self, data, theta=None) -> int:
        """Weak couplings (at ``theta``, else :attr:`theta`: :func:`.aggregation.threshold` of every rank's sampled
        rows together) among the sampled ones inside the leaves (:meth:`_weak_maps`), for values ``data`` of the analysed
        pattern."""
        src, row_diag, col_diag = self._weak_maps()
        vals = data[src]
        theta = self.theta if theta is None else theta
        bound = theta * np.sqrt(np.abs(data[row_diag])) * np.sqrt(np.abs(data[col_diag]))     # no overflow at 1e200
        return int(np.count_nonzero((np.abs(vals) < bound) & (vals != 0)))

    def moved(self, rows) -> bool:
        """Whether new values ``rows`` (same pattern) moved away from aggregation leaves: they now hold more than
        :data:`WEAK_GROWTH` times the weak couplings they held when made (plus 0.1 % of the rows), so leaves made
        anew would follow the couplings better (a coefficient jump that moved; 5x on a DMDA frame with new
        inclusions, which then takes 45 CG iterations against 26). Always False for other leaves."""
        return self.leaves.kind == "aggregation" and self._grew(rows.data, None, self.weak_made)

    def jumped(self, rows) -> bool:
        """Whether new values ``rows`` put more couplings weaker than :data:`SEVERE` inside the leaves than they held
        when made (as :meth:`moved` counts): a contrast of 1e7 or more that moved, which old leaves leave to CG (1e10
        inclusions on a 10 000-row DMDA matrix: DIVERGED_DTOL)."""
        return self.leaves.kind == "aggregation" and self._grew(rows.data, SEVERE, self.severe_made)

    def _grew(self, data, theta, made) -> bool:
        """Whether the couplings inside aggregation leaves weaker than ``theta`` (:meth:`_weak_inside`) grew past
        :data:`WEAK_GROWTH` times ``made`` plus 0.1 % of the sampled rows."""
        return self._weak_inside(data, theta) > WEAK_GROWTH * made + 1e-3 * self.lay.n / self.stride

    def _components(self, mat, rows):
        """Global piece numbering and the connected components of A over all ranks: on several, each rank's own
        components first (its couplings between its leaves), then the graph of those components joined by the
        couplings between ranks, which alone travel."""
        lay, coll = self.lay, self.coll
        pc = lay.pieces
        self.piece_offset = coll.exscan(pc.n_pieces)
        self.n_pieces = coll.sum(pc.n_pieces)
        row_piece = pc.label[lay.iperm] + np.int64(self.piece_offset)         # global piece of each of A's local rows
        self.isolated = np.zeros(self.n_pieces, dtype=bool)
        self.isolated[self.piece_offset:self.piece_offset + pc.n_pieces] = lay.isolated
        if coll.size == 1:                                            # A's own components, read off its rows
            self.n_comp, labels = nullspace.graph_components(rows)
            self.comp_of_row = labels
            self.comp_of_piece = np.zeros(self.n_pieces, dtype=np.int64)
            self.comp_of_piece[row_piece] = labels
            return
        o_rows, o_cols = lay.o_rows, rows.indices[lay.o_src].astype(np.int64)
        start, n = lay.start, lay.n
        local = (o_cols >= start) & (o_cols < start + n)
        my_piece = pc.label[lay.iperm]                                # this rank's piece of each local row
        inside = np.stack([my_piece[o_rows[local]], my_piece[o_cols[local] - start]], 1)
        n_loc, loc = nullspace.components(pc.n_pieces, inside)        # the rank's own components: no messages
        offset = coll.exscan(n_loc)
        n_all = coll.sum(n_loc)
        row_comp = loc[my_piece] + np.int64(offset)
        far = ~local
        other = ghost_values(mat, row_comp, o_cols[far]).astype(np.int64)      # collective: every rank
        key = np.unique(row_comp[o_rows[far]] * n_all + other)       # couplings between ranks' components
        edges = np.stack([key // n_all, key % n_all], 1)
        self.n_comp, comp = nullspace.components(n_all, coll.gather_rows(edges))
        self.comp_of_row = comp[row_comp]                             # of A's local rows
        self.comp_of_piece = coll.gather_rows((comp[loc + offset])[:, None]).ravel()   # every piece, rank by rank
        self.isolated = coll.max_array(self.isolated.astype(np.int64)) > 0

    def _columns(self, net_rank, rows):
        """Coarse columns of every leaf (near null vectors, modes, extras, then one per piece but decoupled ones, and
        none for the one piece of a leaf where the attached near null vectors span the constant, :attr:`covered`:
        2-D elasticity's coarse LU in blocks of 3 instead of 4 with one column left empty; but each connected
        component's first piece keeps its column, which a null component's drops, so E stays nonsingular),
        their global numbers (leaf after leaf, the leaves in METIS's order where :func:`.sizing.metis_ordered`) and
        W's pattern: a row holds its leaf's lead columns and its own piece's, not the other pieces' (a leaf of 64
        rows coupled only to other ranks, 64 pieces, made W's block and E's rows dense: a 2-D coarse LU of 7 597 rows
        and 81 entries per row on two ranks took 8.6 s). A leaf of decoupled rows alone has no column."""
        lay, cfg = self.lay, self.cfg
        lv, pc = lay.leaves, lay.pieces
        self.q = 0 if cfg.coarse == "const" else (net_rank if cfg.coarse == "learned" else cfg.rank) - 1
        self.extra = (self.q + 1) if cfg.tol > 0 and cfg.coarse != "const" else 0
        self.seeded = self.q + self.extra                              # vectors from S's inverse-iteration step
        self.lead = lead = self.fixed + self.seeded
        self.has_col = ~lay.decoupled
        if self.covered:                                              # the lead columns span a one-piece leaf's
            alone = np.bincount(pc.leaf, minlength=lv.n_leaves) == 1  # constant; each component's first piece keeps
            leading = np.zeros(self.n_pieces, dtype=bool)             # its column, where a null one is dropped
            leading[np.unique(self.comp_of_piece, return_index=True)[1]] = True
            self.has_col &= ~(alone[pc.leaf] & ~self.my_pieces(leading))
        before = np.cumsum(self.has_col) - self.has_col                  # pieces with a column before each one
        self.piece_index = index = np.where(self.has_col, before - before[pc.first][pc.leaf], -1)   # among its leaf's
        count = np.bincount(pc.leaf[self.has_col], minlength=lv.n_leaves)
        coupled = np.bincount(pc.leaf[~lay.decoupled], minlength=lv.n_leaves) > 0
        self.ncols = np.where(coupled, lead + count, 0)
        live = self.ncols[self.ncols > 0]
        sizes = self.coll.max_array(np.array([live.max(initial=0), -live.min(initial=2 ** 40)]))
        self.col_block = int(sizes[0]) if sizes[0] == -sizes[1] else 1     # W's columns come in equal blocks per leaf
        first = self.coll.exscan(self.ncols.sum())
        self.m = self.coll.sum(self.ncols.sum())
        self.ordered = sizing.metis_ordered(cfg.solver, self.dim, self.m, self.coll.size, self.leaves.kind,
                                            self.fixed, lead + 1, self.linear, self.dense)
        order = coarseorder.leaf_order(lay, rows) if self.ordered else np.arange(lv.n_leaves)
        self.leaf_col = np.empty(lv.n_leaves, dtype=np.int64)
        self.leaf_col[order] = first + np.concatenate(([0], np.cumsum(self.ncols[order])[:-1]))
        self.piece_col = np.where(self.has_col, self.leaf_col[pc.leaf] + lead + index, -1)
        piece = pc.label[lay.iperm]                                   # each of A's rows' piece
        own = self.has_col[piece]
        per_row = np.where(self.ncols[lay.leaf[lay.iperm]] > 0, lead + own, 0)   # W entries of each of A's rows:
        row = np.repeat(np.arange(lay.n), per_row)                    # the leaf's lead vectors, its piece's constant
        j = np.arange(row.size) - np.repeat(np.cumsum(per_row) - per_row, per_row)
        j = np.where(j < lead, j, lead + index[piece[row]])
        self.w_j = compact(j, self.ncols.max(initial=0) + 1)           # the column within the leaf
        self.w_p = compact(lay.iperm[row], lay.n)                     # the row in the leaves' order
        self.col_first = int(first)
        self.w_local_col = compact(self.leaf_col[lay.leaf[self.w_p]] - first + self.w_j, int(self.ncols.sum()) + 1)

    def w_pattern(self) -> tuple:
        """W's entries as global (rows, columns), made on demand (W's preallocation) and not kept."""
        lay = self.lay
        return lay.perm[self.w_p].astype(np.int64) + lay.start, self.w_local_col.astype(np.int64) + self.col_first

    def my_pieces(self, flags) -> np.ndarray:
        """This rank's part of a global per-piece array."""
        return flags[self.piece_offset:self.piece_offset + self.lay.pieces.n_pieces]
