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
  the couplings, once the couplings moved; the multilevel V-cycles make new leaves in their numeric step);
- ``once(ksp, pc, setup)``: whether a solve by ``ksp`` calls for a new analysis (M applied once, PREONLY);
- ``destroy(analysis)``: free what the analysis and its setups hold;
- ``title``: what runs, in a few words; ``model``: a line naming the model, or None.

A new variant is one class and its entry in :data:`VARIANTS`, the one registry (``-htp_variant`` takes its
names). The paper's variant and the learned coarse space run torch, an optional dependency (the ``learned``
extra): asking for them without it is an error that says what to install.
"""
from __future__ import annotations

from importlib import import_module

import numpy as np

from .twolevel.config import Config

TORCH_EXTRA = "pip install 'petsc_htp[learned]'"
FIXED = {"preonly": "applied once (KSPPREONLY)",              # KSPs that ICC(0) of the whole matrix does not serve
         "richardson": "applied by a fixed-point iteration (KSPRICHARDSON), which ICC(0)'s M A with eigenvalues "
                       "above 2 makes diverge",  # (rotated anisotropy at 500-1 500 rows, PyAMG's bar: DIVERGED_DTOL)
         "chebyshev": "applied by a Chebyshev iteration (KSPCHEBYSHEV), whose eigenvalue estimate ICC(0)'s M A "
                      "outruns",    # (PyAMG's bar, P1 triangles of 7 921 rows: DIVERGED_NANORINF after 1 143 steps,
         # PETSc's own ICC(0) too, then a SEGV at exit; the exact factor: 28 steps)
         "cgs": "applied by CGS (KSPCGS), which squares ICC(0)'s residual polynomial"}   # (bar: DIVERGED_DTOL, as
# under PETSc's own ICC(0); the exact factor: none)
KEEP_SHARE = 0.1    # another Mat whose rows and entries a row lie within this share of those the last fresh choice was
# made for keeps that choice where it was no whole factor (a liquid's pattern changes every frame; the choice is
# -log_view's HTPChoice event)
VARIANTS = {"twolevel": ("petsc_htp.variants", "TwoLevel"), "multilevel": ("petsc_htp.multilevel.variant", "Multilevel"),
            "paper": ("petsc_htp.paper.variant", "Paper")}


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
    note = ""                                      # what -ksp_view adds (coordinates ignored)
    title = "two-level preconditioner: leaf solves, a coarse space per leaf, Galerkin coarse operator (no network)"

    def __init__(self, opts, prefix=""):
        self.opts, self.prefix = opts, prefix
        self.net, self.stale_ms = None, None       # stale_ms: the extra ms of old leaves when values last moved
        self.choice = None                         # whether and why the whole matrix is factored (WholeChoice)
        self.kept, self.chosen_for = None, None    # the sizes that chose no whole factor (direct), the last Mat's id
        self.exact_only = None                     # why ICC(0) of the whole matrix does not serve (:meth:`once`)
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
        coords = self._followed(mat, A, coords)
        with phase("HTPChoice", times, "choice"):
            kind = self.direct(mat, A, coords)
        if kind is not None:
            from .twolevel.direct import DirectPC

            c = self.choice
            setup = DirectPC(mat, A, kind, self.prefix + "htp_", c.why, c.holds, c.take_made())
        else:
            setup = self.composed(mat, A, coords)
            if self.choice.kept:
                self.note = "; ".join(filter(None, (self.note, "the whole-matrix choice kept from the last pattern")))
        setup.analysis_ms += times["choice"]           # -ksp_view's analysis: the choice (a trial) included
        return setup

    def composed(self, mat, A, coords):
        """The method for a matrix not factored whole: the two-level one (:class:`.twolevel.composed.TwoLevelPC`), or
        with no two-level option set (nor ``-htp_variant`` itself) where :func:`.multilevel.choice.serves` (a bare 2-D
        graph, or 3-D without positive couplings, of at least ``MIN_ROWS`` rows, in a local order on several ranks)
        or, under KSPRICHARDSON, :func:`.multilevel.choice.fixed_point` (a bare 3-D graph) the multilevel V-cycles,
        :attr:`note` saying so."""
        if self._chooses(coords):
            from .multilevel.choice import fixed_point, serves

            shape = lambda: self.choice.block_shape(mat, A)     # noqa: E731
            why, reorder, dim = serves(mat, A, shape)
            fixed = not why and self.exact_only == FIXED["richardson"]
            if fixed:
                why, reorder, dim = fixed_point(mat, A, shape)
            if why:
                from .multilevel.setup import MultilevelPC

                self.note = why
                return MultilevelPC(mat, A, self.prefix + "htp_", dim, reorder=reorder, signed=None if fixed else False)
        from .twolevel.composed import TwoLevelPC

        return TwoLevelPC(mat, A, coords, self.config(), self.prefix + "htp_", self.net)

    def _chooses(self, coords) -> bool:
        """Whether the method follows the problem (:meth:`composed`): a bare matrix (no ``coords``), no option of the
        two-level method set, nor ``-htp_variant`` itself, nor a network."""
        from petsc4py import PETSc

        return (coords is None and self.opts.plain and self.opts.direct_max < 0 and self.net is None
                and not PETSc.Options(self.prefix).hasName("htp_variant"))

    def _followed(self, mat, A, coords):
        """``coords``, or None where coupled rows lie far apart in them (:mod:`.twolevel.coordcheck`: coordinates
        in another order than the rows; :attr:`note` says so; collective)."""
        from .collective import Collective
        from .twolevel.coordcheck import FAR, spread

        self.note = ""
        far = 0.0 if coords is None else spread(A, mat.getOwnershipRange()[0], coords, Collective(mat.getComm()))
        if far <= FAR:
            return coords
        self.note = (f"coordinates ignored: coupled rows lie {far:.2f} as far apart in them as rows at random "
                     f"(medians), so they do not follow the rows; the leaves come from the matrix")
        return None

    def direct(self, mat, A, coords):
        """The factor of the whole matrix that serves ``mat`` (this rank's rows ``A``), or None: the two-level method
        (:class:`~petsc_htp.whole.WholeChoice`, kept as :attr:`choice`; collective). Another Mat (a new pattern) of as
        many rows and entries a row as the one the last choice was made for (within :data:`KEEP_SHARE`), alike
        coordinates, null space, block size and KSP, above the sizes that small matrices' factors take and with no
        option of the two-level method set and no rank without rows, keeps that choice where it was no whole factor
        (its :attr:`~petsc_htp.whole.WholeChoice.kept` then set; the graph's shape found again), also across a
        KSPReset (which a new size calls for; a KSPSetFromOptions makes PCPYTHON a new context, which chooses
        afresh). The same Mat with new values chooses afresh."""
        from .collective import Collective
        from .twolevel import sizing
        from .whole import WholeChoice

        n, (nnz, empty) = mat.getSize()[0], Collective(mat.getComm()).sum_array(np.array([A.nnz, A.shape[0] == 0]))
        counts = (n, nnz / max(n, 1))
        alike = (0 if coords is None else coords.shape[1], bool(mat.getNullSpace().handle), mat.getBlockSize(),
                 self.exact_only)
        other, self.chosen_for = mat.getId() != self.chosen_for, mat.getId()
        if (self.kept is not None and other and alike == self.kept[1] and not empty
                and all(abs(a - b) <= KEEP_SHARE * b for a, b in zip(counts, self.kept[0]))
                and n > max(*sizing.DIRECT_MAX.values(), *sizing.WHOLE_ICC_MAX.values())):
            self.choice.kept, self.choice.shape = True, None       # the graph's shape found again where asked
            return None
        self.choice = WholeChoice(self.opts, self.exact_only)
        kind = self.choice.kind(mat, A, coords)
        plain = self.opts.plain and self.opts.direct_max < 0 and not empty
        self.kept = (counts, alike) if kind is None and self.choice.why is None and plain else None
        return kind

    def once(self, ksp, pc, setup) -> bool:
        """Whether a solve by ``ksp`` calls for a new analysis: one of :data:`FIXED` (a KSPPREONLY: PCMG's coarse
        solve, PCFIELDSPLIT's splits; KSPRICHARDSON, KSPCGS, KSPCHEBYSHEV and its eigenvalue estimate, a KSP of prefix
        ``esteig_`` on the same PC, whose GMRES had taken ICC(0) back at each setup) where ``setup`` is ICC(0), or
        KSPRICHARDSON where it is the two-level method on a 3-D graph whose method follows the problem
        (:func:`.multilevel.choice.fixed_point`), or
        another after a choice made for such a KSP (a KSPReset and a new type: ICC(0) may serve again); the choice
        takes exact factors or the two-level method while the KSP is one of them (:attr:`exact_only`,
        :class:`~petsc_htp.whole.WholeChoice`). (A Pmat apart from the Amat keeps ICC(0): P = A with its diagonal x
        1.05, 16 384 rows, took it 482 CG iterations in about 240 ms, the two-level method 293 in 335-708.)"""
        from .twolevel.consistency import ESTIMATE
        from .twolevel.direct import INCOMPLETE

        kind = "chebyshev" if (ksp.getOptionsPrefix() or "").endswith(ESTIMATE) else ksp.getType()
        made = self.choice is not None and self.choice.exact_only is not None     # the choice in use took them
        once, self.exact_only = kind in FIXED, FIXED.get(kind)
        three = (kind == "richardson" and getattr(getattr(setup, "st", None), "dim", 0) == 3
                 and self._chooses(getattr(setup, "coords", 0)))
        return (not made and (getattr(setup, "kind", None) in INCOMPLETE or three)) if once else made

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
        coarse space was made and the first and the most since its leaves were (:mod:`.twolevel.spacereuse`), and the
        deflated form's start ends; a DirectPC keeps none."""
        if hasattr(setup, "solved"):
            setup.solved(its, seconds)

    def moved(self, analysis, A) -> bool:
        """Whether the new values ``A`` moved away from the leaves (a new analysis follows them; the multilevel
        V-cycles build their hierarchy anew in the numeric step instead, their ``renew``), judged with what old leaves
        cost the last time values moved (kept across analyses of the pattern)."""
        from .twolevel.spacereuse import stale_cost

        moved = analysis.moved(A, self.stale_ms)          # a DirectPC only where its rows lost their dominance
        renewed = moved or getattr(analysis, "renew", False)
        cost = stale_cost(analysis.leaf_its, analysis.ms_per_it) if renewed and not getattr(analysis, "whole", False) \
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
