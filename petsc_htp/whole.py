"""Whether one factor of the whole matrix serves HTPPC's operator better than the two-level method, and which: the
choice that the ``HTPChoice`` event times, made once per pattern.

Small matrices get the factor their size and rows call for (:func:`.twolevel.sizing.whole_factor`). Above those sizes
ICC(0) of the whole matrix (on several ranks of each rank's block) where the rows are diagonally dominant
(:mod:`.twolevel.dominance`), where the graph is no mesh (:mod:`.twolevel.spread`), or where the rows are strongly
anisotropic, wide, anisotropic along the grid or shifted and a short trial confirms it (:mod:`.twolevel.incomplete`);
one banded Cholesky factor (LAPACK's, :mod:`.twolevel.band`) where the graph is a chain (a 1-D problem's), whose band
holds no more than A: a chain of 64 000 rows took 47 ms (5 iterations) in the two-level method, 15 ms as a band
(1 iteration; ``results/wide-20261127``); and on one rank the same banded factor wherever the bandwidth is at most
:data:`.twolevel.sizing.BAND_WIDTH` in the rows' own order or reverse Cuthill-McKee's (small matrices, thin 2-D
domains, strips: ``results/band-20261127``).
"""
from __future__ import annotations

import numpy as np

from .collective import Collective
from .petscmat import gathered_rows


class WholeChoice:
    """The choice for one pattern: :meth:`kind`, then :attr:`why` (the reason -ksp_view prints, None where the size
    alone decides), :attr:`holds` (what new values may lose, or None) and :meth:`take_made` (what the choice made
    that the factor takes, once). ``exact_only``: why ICC(0) does not serve, else None: M applied once a solve (a
    KSPPREONLY's PC: PCMG's coarse solve, PCFIELDSPLIT's splits); the choice then takes exact factors or the
    two-level method. ICC(0) is chosen for the iterations it saves on its own
    operator, and one application of it is no solve (PCMG's 9-point coarse level of 4 225 rows: 31 outer CG
    iterations, 8 with its Cholesky; PCFIELDSPLIT's shifted split of 66 049 rows: 2 945 FGMRES iterations, 204)."""

    def __init__(self, opts, exact_only=None):
        self.opts, self.why, self.holds, self.made, self.exact_only = opts, None, None, None, exact_only
        self.kept = False           # kept for a new pattern of the same sizes (:meth:`..variants.TwoLevel.direct`)
        self.shape = None          # this rank's block's graph shape (:meth:`block_shape`)

    def take_made(self):
        """What the choice made that the factor takes, or None, handed over once: the ICC(0) trial's PC, set up on the
        whole matrix (one rank), or the banded factor's analysis (:class:`.twolevel.band.Band`)."""
        made, self.made = self.made, None
        return made

    def kind(self, mat, A, coords):
        """The factor of the whole matrix that serves ``mat`` (this rank's rows ``A``; on several ranks gathered on
        every rank, PCREDUNDANT), or None: no two-level option set, and :func:`sizing.whole_factor` by the problem, or
        with ``-htp_direct_max n`` >= 0 Cholesky up to n rows; where a rank owns no rows, :meth:`_empty_rank`
        (collective); above those sizes ICC(0) (on several ranks of each rank's block, 'bjacobi', grown for anisotropy,
        'asm') where the rows are diagonally dominant (:meth:`_dominant`), or, bare, the graph is no mesh
        (:meth:`_graph`) or the rows strongly or grid-aligned anisotropic, wide or shifted (:meth:`_incomplete`), and
        Cholesky in reverse Cuthill-McKee order, 'band', where the bare graph is a chain, :attr:`why` saying so."""
        from .twolevel import sizing

        o = self.opts
        n, coll = mat.getSize()[0], Collective(mat.getComm())
        per_row = coll.sum(A.nnz) / max(n, 1)
        if coll.size > 1 and coll.any(A.shape[0] == 0):
            return self._exact(self._empty_rank(n, coll, A.shape[0], per_row))
        if not o.plain:
            return None
        if o.direct_max >= 0:
            return "cholesky" if n <= o.direct_max else None
        if n > max(*sizing.DIRECT_MAX.values(), *sizing.WHOLE_ICC_MAX.values()):
            if self.exact_only:                 # ICC(0), also each rank's (bjacobi, asm), is chosen for its
                # iterations; only one rank's band stays (a chain on several takes the two-level method), and under a
                # KSP that iterates, diagonally dominant rows' ICC(0) (the 512^2 5-point matrix + 2 I: Richardson 10
                # steps, Chebyshev 32, CGS 4, 0.4 x the V-cycles' time: results/kspsweep-20261129/dominant.txt)
                kind = None if self.exact_only == _once() else self._dominant(mat, A, coll)
                return kind or (self._banded(A) if coords is None and coll.size == 1 and n <= sizing.BAND_CHECK_MAX
                                else None)
            kind = self._dominant(mat, A, coll)
            if kind is None and coords is None:
                kind = self._graph(mat, A, coll, per_row)
            kind = kind or self._incomplete(mat, A, coll, per_row, coords is None)
            if kind is None and coords is None and coll.size == 1 and n <= sizing.BAND_CHECK_MAX:
                kind = self._banded(A)
            return kind
        if mat.getBlockSize() > 1:          # the stored zeros of a block format's blocks are no couplings (7 200
            per_row = coll.sum(np.count_nonzero(A.data)) / max(n, 1)  # rows of 2x2 blocks: ICC(0), 33 its, where
            # one factor served; a DMDA's boundary rows, whose zeros the rules were measured with, keep them)
        if (per_row <= sizing.RICH_ROW or coords is not None) and self._banded(
                A if coll.size == 1 else gathered_rows(A, coll.mpi)):   # on several ranks all rows (collective)
            return "band"                                   # no graph walk (0.5 ms at 1000 rows)
        return self._exact(self._small(mat, A, coll, n, per_row, coords))

    def _exact(self, kind):
        """``kind``, or where ICC(0) does not serve (:attr:`exact_only`) the exact factor in place of ICC(0),
        :attr:`why` saying so."""
        if not (self.exact_only and kind == "icc"):
            return kind
        self.why = f"{self.exact_only}, so exact in place of ICC(0), whose iterations it does not make"
        return "cholesky"

    def _small(self, mat, A, coll, n, per_row, coords):
        """:func:`.twolevel.sizing.whole_factor`'s answer for a small matrix, without the graph walk (0.6 ms at 1000
        rows) wherever the answer needs no dimension (collective)."""
        from .twolevel import sizing

        if n <= sizing.DIRECT_MAX[3] and per_row <= sizing.RICH_ROW:      # the same in any dimension
            return "cholesky"
        if coords is None and per_row > sizing.RICH_ROW and n <= min(sizing.WHOLE_ICC_MAX.values()):
            return "icc"                                                  # the same in any dimension
        dim = coords.shape[1] if coords is not None else self.block_shape(mat, A).dim
        return sizing.whole_factor(int(coll.max_array(np.array([dim]))[0]), n, per_row, coords is None)

    def _banded(self, A):
        """'band' where one rank's matrix ``A`` has a bandwidth of at most :data:`.twolevel.sizing.BAND_WIDTH` in its
        own order or, up to :data:`.twolevel.sizing.BAND_RCM_MAX` rows, in reverse Cuthill-McKee's
        (:func:`.twolevel.band.ordering`), :attr:`why` saying so; else None."""
        from .twolevel import sizing
        from .twolevel.band import Band, ordering, own_width

        reorder = A.shape[0] <= sizing.BAND_RCM_MAX
        if not reorder and own_width(A) > sizing.BAND_WIDTH:
            return None
        order = ordering(A, reorder=reorder)
        width = order[3]
        if width > sizing.BAND_WIDTH:
            return None
        self.made = Band(A, order)
        self.why = (f"{'its own' if self.made.own else 'its reverse Cuthill-McKee'} order has bandwidth {width} (at most "
                    f"{sizing.BAND_WIDTH}): one banded Cholesky factor costs less than the two-level method")
        return "band"

    def _dominant(self, mat, A, coll):
        """'icc' (on several ranks 'bjacobi') where every coupled row is diagonally dominant by at least
        :data:`.twolevel.dominance.MARGIN`, else None (collective)."""
        from .twolevel import dominance

        c = dominance.margin(A, mat.getOwnershipRange()[0])
        c = coll.min_array(np.array([c if c == c else -np.inf]))[0]       # nan (none so far) would split the ranks
        if not c >= dominance.MARGIN:
            return None
        self.why, self.holds = dominance.describe(c), dominance.holds
        return "icc" if coll.size == 1 else "bjacobi"

    def _graph(self, mat, A, coll, per_row):
        """'icc' (on several ranks 'bjacobi') where the graph grows faster than any mesh's (a small-world network) in a
        rank's diagonal block (the largest growth over the ranks: a rank's part of a mesh is a mesh, or fragments that
        grow less), or where a large share of the couplings crosses ranks in the whole graph (:mod:`.twolevel.spread`);
        'band' where that growth shows a chain (:func:`.twolevel.sizing.chain`, ``per_row`` stored entries a row: a
        random graph of 3.2 entries a row split over 2 ranks left blocks growing as 0.44 and 0.92, the whole graph
        2.2); else None (collective)."""
        from .ranksplit import crossing
        from .twolevel import sizing, spread

        growth = self.block_shape(mat, A).growth
        growth = coll.max_array(np.array([growth if growth == growth else -np.inf]))[0]   # nan: too few rows to tell
        if coll.size > 1 and not growth >= sizing.EXPANDER_GROWTH:
            if crossing(mat, A, coll, A.data != 0)[1] >= spread.CROSSING:    # the blocks keep too few couplings to tell
                growth = spread.global_growth(mat, A, coll)
        if np.isfinite(growth) and sizing.chain(growth, per_row):
            self.why = f"its graph is a chain (balls grow with exponent {growth:.2f}): its Cholesky factor is a band"
            return "band"
        if not growth >= sizing.EXPANDER_GROWTH:
            return None
        self.why = (f"its graph is no mesh (balls grow with exponent {growth:.1f}, meshes' 1.6-2.7): a coarse "
                    "space does not pay")
        return "icc" if coll.size == 1 else "bjacobi"

    def _incomplete(self, mat, A, coll, per_row, bare):
        """'icc' (on several ranks 'bjacobi', or 'asm' with each rank's block grown for anisotropy) where the rows are
        shifted or, ``bare``, strongly anisotropic or wide and a trial confirms it
        (:func:`.twolevel.incomplete.why_icc`), else None (collective)."""
        from .twolevel import incomplete

        self.why, self.holds, grown, self.made = incomplete.why_icc(mat, A, per_row, coll, bare)
        if self.why is None:
            return None
        return "icc" if coll.size == 1 else "asm" if grown else "bjacobi"

    def block_shape(self, mat, A):
        """What this rank's diagonal block of the graph shows (:mod:`.twolevel.graphshape`: dimension and growth),
        from 8 sampled balls; found once per choice (the multilevel choice reads it too)."""
        from .petscmat import diagonal_block
        from .twolevel.graphshape import graph_shape

        if self.shape is None:
            with diagonal_block(mat, A) as block:
                self.shape = graph_shape(block, want_weak=False, samples=8)
        return self.shape

    def _empty_rank(self, n, coll, mine, per_row):
        """A matrix with a rank that owns no rows (this rank ``mine``), which the two-level method cannot take as it is:
        whatever the options, up to :data:`~.twolevel.sizing.REDUNDANT_MAX` rows its factor gathered on every rank
        (Cholesky where rows hold at most ``RICH_ROW`` stored entries on average, ``per_row``, else ICC(0)), above
        HTPPC on a subcommunicator, the rows moved there ('telescope': :mod:`.twolevel.telescope`, :attr:`why` saying
        so; collective)."""
        from .twolevel import sizing

        if n <= sizing.REDUNDANT_MAX:
            return "cholesky" if per_row <= sizing.RICH_ROW else "icc"
        empty = coll.sum(int(mine == 0))
        self.why = f"{empty} of the {coll.size} ranks own no rows, and the two-level method needs rows on every rank"
        return "telescope"


def _once() -> str:
    """Why a KSPPREONLY takes no ICC(0) (:data:`..variants.FIXED`): one application of it is no solve."""
    from .variants import FIXED

    return FIXED["preonly"]
