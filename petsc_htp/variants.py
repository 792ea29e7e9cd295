"""The preconditioner variants behind HTPPC, each a two-step setup: analysis (pattern) and numeric (values).

A variant is a class constructed from :class:`~petsc_htp.pcoptions.HTPOptions` and the PC's
options prefix, with

- ``analyse(mat, A, coords)``: the per-pattern step (ordering, leaves, structure) on the PETSc Mat
  and ``A``, this rank's rows as scipy CSR, returning an object with ``analysis_ms``;
- ``numeric(analysis, mat, A, density, previous)``: the per-values step, returning the setup object
  (``check(probes)``, ``describe()``, ``inner_pcs()``, ``nbytes``); ``previous`` is the last setup of the same
  analysis, whose buffers it may reuse;
- ``apply(setup, x, y)``: y = M x on PETSc Vecs;
- ``presolve(setup, ksp, b, x, stale)``: called before each KSPSolve (``stale``: the setup is reused on
  an operator whose values changed since); returns the KSP settings it changed ({'guess': the initial-guess flag,
  'divtol': the divergence tolerance}, given back after the solve), else None;
- ``solved(setup, its)``: called after each KSPSolve with its iterations;
- ``moved(analysis, A)``: whether new values of the same pattern call for a new analysis (leaves that follow
  the couplings, once the couplings moved);
- ``destroy(analysis)``: free what the analysis and its setups hold;
- ``title``: what runs, in a few words; ``model``: a line naming the model, or None.

A new variant is one class and its entry in :data:`VARIANTS`, the one registry (``-htp_variant`` takes its
names). The paper's variant and the learned coarse space run torch, an optional dependency (the ``learned``
extra): asking for them without it is an error that says what to install.
"""
from __future__ import annotations

from importlib import import_module

import numpy as np

from .collective import Collective
from .twolevel.config import Config

TORCH_EXTRA = "pip install 'petsc_htp[learned]'"
VARIANTS = {"twolevel": ("petsc_htp.variants", "TwoLevel"), "paper": ("petsc_htp.paper.variant", "Paper")}


def require_torch(what: str):
    """Import torch, or raise ModuleNotFoundError saying that ``what`` needs the ``learned`` extra."""
    try:
        import torch
    except ModuleNotFoundError:
        raise ModuleNotFoundError(f"{what} runs torch, which is not installed: {TORCH_EXTRA}") from None
    return torch


def variant_class(name: str):
    """The class registered as ``name`` (torch checked first where it needs it)."""
    module, cls = VARIANTS[name]
    if name == "paper":
        require_torch("-htp_variant paper (the paper's network)")
    return getattr(import_module(module), cls)


class TwoLevel:
    """Exact leaf solves, a coarse space per leaf and its exact Galerkin operator (float64), from PETSc parts
    (:mod:`petsc_htp.twolevel.composed`), on any number of ranks; a small matrix on one rank gets one sparse
    factor (:mod:`petsc_htp.twolevel.direct`). The analysis object is the setup: its numeric step refreshes it
    in place."""

    model = None
    title = "two-level preconditioner: leaf solves, a coarse space per leaf, Galerkin coarse operator (no network)"

    def __init__(self, opts, prefix=""):
        self.opts, self.prefix = opts, prefix
        self.net, self.stale_ms = None, None       # stale_ms: the extra ms of old leaves when values last moved
        self.why, self.holds, self.factor = None, None, None   # why the whole matrix is factored, what new values
        # may lose, and the ICC(0) trial's PC set up on the whole matrix (one rank; handed to the DirectPC)
        if opts.coarse == "learned":
            require_torch("-htp_coarse learned (the coarse network)")
            from .twolevel import coarsenet

            self.net, prov = coarsenet.cached(opts.coarse_checkpoint or None)
            self.model = (f"coarse network {self.net.n_parameters()} parameters, r={self.net.cfg.rank}; "
                          f"checkpoint {opts.coarse_checkpoint or 'shipped ' + str(coarsenet.DEFAULT)}")

    def config(self) -> Config:
        """The two-level configuration from the options."""
        o = self.opts
        return Config(o.leaf, o.ordering, o.coarse, o.coarse_rank, o.coarse_tol, o.form, o.overlap, o.coarse_solver,
                      aggregation=o.aggregation, block_size=o.block_size)

    def analyse(self, mat, A, coords):
        """Leaves, index maps, components and every matrix with its pattern (see
        :class:`~petsc_htp.twolevel.composed.TwoLevelPC`), or the small matrix's factor."""
        if self.net is not None and coords is not None and coords.shape[1] != 2:
            raise ValueError(
                f"-htp_coarse learned is 2-D only: the coarse network's features are 2-D cell coordinates and "
                f"it was trained on 2-D scenes, but {coords.shape[1]}-D coordinates are attached; use "
                "-htp_coarse eig (the default) or const")
        from .events import phase                       # petsc4py: not at import (the fast path imports none)
        times = {}
        with phase("HTPChoice", times, "choice"):
            kind = self.direct(mat, A, coords)
        if kind is not None:
            from .twolevel.direct import DirectPC

            setup, self.factor = DirectPC(mat, A, kind, self.prefix + "htp_", self.why, self.holds, self.factor), None
        else:
            from .twolevel.composed import TwoLevelPC

            setup = TwoLevelPC(mat, A, coords, self.config(), self.prefix + "htp_", self.net)
        setup.analysis_ms += times["choice"]           # -ksp_view's analysis: the choice (a trial) included
        return setup

    def direct(self, mat, A, coords):
        """The factor of the whole matrix that serves ``mat`` (this rank's rows ``A``; on several ranks gathered on
        every rank, PCREDUNDANT), or None: no two-level option set, and :func:`sizing.whole_factor` by the problem,
        or with ``-htp_direct_max n`` >= 0 Cholesky up to n rows; where a rank owns no rows, :meth:`_empty_rank`
        (collective); above those sizes ICC(0) (on several ranks of each rank's block, 'bjacobi', grown for anisotropy,
        'asm') where the rows are diagonally dominant (:meth:`_dominant`), or, bare, the graph is no mesh
        (:meth:`_no_mesh`) or the rows strongly anisotropic, wide or shifted (:meth:`_incomplete`), :attr:`why`
        saying so."""
        from .twolevel import sizing

        self.why, self.holds, self.factor = None, None, None
        o = self.opts
        plain = (o.leaf, o.ordering, o.aggregation, o.coarse, o.coarse_solver, o.overlap, o.coarse_tol, o.coarse_rank,
                 o.form, o.coarse_space_every) == (0, "auto", "auto", "auto", "auto", 0, 0.0, 2, "auto", 0)
        n, coll = mat.getSize()[0], Collective(mat.getComm())
        per_row = coll.sum(A.nnz) / max(n, 1)
        if coll.size > 1 and coll.any(A.shape[0] == 0):
            return self._empty_rank(n, coll.size, per_row)
        if not plain:
            return None
        if o.direct_max >= 0:
            return "cholesky" if n <= o.direct_max else None
        if n > max(*sizing.DIRECT_MAX.values(), *sizing.WHOLE_ICC_MAX.values()):
            kind = self._dominant(mat, A, coll)
            if kind is None and coords is None:
                kind = self._no_mesh(mat, A, coll)
            return kind or self._incomplete(mat, A, coll, per_row, coords is None)
        # whole_factor's answer wherever it needs no dimension: the graph walk costs 0.6 ms at 1000 rows
        if n <= sizing.DIRECT_MAX[3] and per_row <= sizing.RICH_ROW:      # the same in any dimension: no graph walk
            return "cholesky"
        if coords is None and per_row > sizing.RICH_ROW and n <= min(sizing.WHOLE_ICC_MAX.values()):
            return "icc"                                                  # the same in any dimension
        dim = coords.shape[1] if coords is not None else self._block_shape(mat, A).dim
        return sizing.whole_factor(int(coll.max_array(np.array([dim]))[0]), n, per_row, coords is None)

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

    def _no_mesh(self, mat, A, coll):
        """'icc' (on several ranks 'bjacobi') where the graph grows faster than any mesh's (a small-world network) in a
        rank's diagonal block (the largest growth over the ranks: a rank's part of a mesh is a mesh, or fragments
        that grow less), or where a large share of the couplings crosses ranks in the whole graph
        (:mod:`.twolevel.spread`), else None (collective)."""
        from .ranksplit import crossing
        from .twolevel import sizing, spread

        growth = self._block_shape(mat, A).growth
        growth = coll.max_array(np.array([growth if growth == growth else -np.inf]))[0]   # nan: too few rows to tell
        if coll.size > 1 and not growth >= sizing.EXPANDER_GROWTH:
            if crossing(mat, A, coll, A.data != 0)[1] >= spread.CROSSING:    # the blocks keep too few couplings to tell
                growth = spread.global_growth(mat, A, coll)
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

        self.why, self.holds, grown, self.factor = incomplete.why_icc(mat, A, per_row, coll, bare)
        if self.why is None:
            return None
        return "icc" if coll.size == 1 else "asm" if grown else "bjacobi"

    @staticmethod
    def _block_shape(mat, A):
        """What this rank's diagonal block of the graph shows (:mod:`.twolevel.graphshape`: dimension and growth),
        from 8 sampled balls."""
        from .petscmat import diagonal_block
        from .twolevel.graphshape import graph_shape

        with diagonal_block(mat, A) as block:
            return graph_shape(block, want_weak=False, samples=8)

    @staticmethod
    def _empty_rank(n, ranks, per_row):
        """A matrix with a rank that owns no rows, which the two-level method cannot take: whatever the options, up to
        :data:`~.twolevel.sizing.REDUNDANT_MAX` rows its factor gathered on every rank (Cholesky where rows hold at
        most ``RICH_ROW`` stored entries on average, ``per_row``, else ICC(0)), above a named error."""
        from .twolevel import sizing
        from .validation import MatrixError

        if n <= sizing.REDUNDANT_MAX:
            return "cholesky" if per_row <= sizing.RICH_ROW else "icc"
        raise MatrixError(f"the matrix has a rank without rows ({n} rows on {ranks} ranks); HTPPC's two-level "
                          f"method needs rows on every rank (up to {sizing.REDUNDANT_MAX} rows one factor of the whole "
                          "matrix serves instead): give every rank rows, or take PCTELESCOPE around HTPPC")

    def numeric(self, analysis, mat, A, density, previous):
        """New values; the coarse space is kept while it serves (``-htp_coarse_space_every``,
        :mod:`.twolevel.spacereuse`; a DirectPC has none)."""
        from .twolevel.spacereuse import keeps

        space = getattr(previous, "space", None)
        keep = space is not None and keeps(self.opts.coarse_space_every, space.age, previous.its, space.renewed)
        analysis.numeric(A, density, keep_space=keep)
        return analysis

    @staticmethod
    def solved(setup, its, seconds):
        """A KSPSolve with ``setup`` took ``its`` iterations in ``seconds``: kept as the first and the last since its
        coarse space and its leaves were made (:mod:`.twolevel.spacereuse`), and the deflated form's start ends; a
        DirectPC keeps none."""
        if hasattr(setup, "solved"):
            setup.solved(its, seconds)

    def moved(self, analysis, A) -> bool:
        """Whether the new values ``A`` moved away from the leaves (a new analysis follows them), judged with what
        old leaves cost the last time values moved (kept across analyses of the pattern)."""
        from .twolevel.spacereuse import stale_cost

        moved = analysis.moved(A, self.stale_ms)          # a DirectPC only where its rows lost their dominance
        cost = stale_cost(analysis.leaf_its, analysis.ms_per_it) if moved and not getattr(analysis, "whole", False) \
            else None
        if cost is not None:
            self.stale_ms = cost
        return moved

    @staticmethod
    def apply(setup, x, y):
        """y = M x in PETSc."""
        setup.mult(x, y)

    @staticmethod
    def presolve(setup, ksp, b, x, stale):
        """The deflated form's start (x0 += Q r0); returns the KSP settings to give back after the solve, or None."""
        return setup.presolve(ksp, b, x, stale)

    @staticmethod
    def inner_pcs(setup) -> dict:
        """The setup's inner PETSc solvers by role."""
        return setup.inner_pcs()

    @staticmethod
    def destroy(analysis):
        """Free the PETSc objects."""
        analysis.destroy()
