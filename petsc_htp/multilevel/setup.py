"""The multilevel variant's setup (the interface of :class:`~petsc_htp.twolevel.composed.TwoLevelPC`): its
hierarchy and V-cycle, whose leaves new values of the pattern keep while they follow the couplings."""
from __future__ import annotations

import time

import numpy as np
from petsc4py import PETSc

from ..collective import Collective
from ..events import phase
from ..twolevel.inner import held
from ..twolevel.spacereuse import stale_cost
from . import choice, cycle
from .choice import local_order
from .hierarchy import MAX_LEVELS, Hierarchy, default_coarse_max
from .level import JACOBI, LEAST, banded_leaves, leaves, row_scaled
from .moved import WeakInside
from .ranges import Ranges
from .reordered import Reordered


RENEW = 1.5             # a solve taking this many times the first one's iterations on kept leaves renews them


WEIGHTED = " weighted by |diag|^-1/2 (a row-scaled operator)"      # -ksp_view's words on the finest leaf vectors


def _check(prefix, coarse_max, max_levels, damping, jacobi, smoother):
    """A ValueError naming the options ``prefix`` + ... out of range, or none."""
    if coarse_max < 1 or max_levels < 1 or not 0 < damping < 2 or not jacobi > 0:
        raise ValueError(f"-{prefix}coarse_max and -{prefix}max_levels must be at least 1, -{prefix}damping in (0, 2) "
                         f"and -{prefix}jacobi positive; got {coarse_max}, {max_levels}, {damping}, {jacobi}")
    if smoother not in cycle.SMOOTHERS:
        raise ValueError(f"-{prefix}smoother {smoother}: expected auto or one of {', '.join(cycle.SMOOTHERS)}")


class MultilevelPC:
    """V-cycles of :mod:`petsc_htp.multilevel` on ``mat`` (this rank's ``rows``; its graph of dimension ``dim``)
    under the options ``prefix`` + ``ml_`` (PCMG's, and ``coarse_max``, ``max_levels``: :mod:`.hierarchy`;
    ``jacobi``: :mod:`.level`; ``damping``, ``smoother``: :mod:`.cycle`, auto by ``dim`` and ``signed``, found where
    not given; ``reorder``: :meth:`numeric`, auto unless set: the ``reorder`` given, where known, else found)."""

    title = "multilevel preconditioner: V-cycles on an aggregation hierarchy of leaves (PCMG)"
    whole = False

    def __init__(self, mat, rows, prefix, dim, reorder=None, signed=None):
        t0 = time.perf_counter()
        self.mat, self.prefix = mat, prefix + "ml_"
        db = PETSc.Options(self.prefix)
        self.coarse_max, self.least = db.getInt("coarse_max", default_coarse_max(dim)), LEAST[3 if dim > 2 else 2]
        self.max_levels = db.getInt("max_levels", MAX_LEVELS)
        self.damping = db.getReal("damping", cycle.DAMPING)
        self.jacobi = db.getReal("jacobi", JACOBI)
        self.smoother = cycle.smoother(db.getString("smoother", "auto"), dim,
                                       lambda: choice.signed(mat, rows) if signed is None else signed)
        if db.getString("reorder", "auto").lower() != "auto":
            reorder = db.getBool("reorder")
        elif reorder is None:               # collective: createSubMatrix on every rank or none
            reorder = Collective(mat.getComm()).any(not local_order(rows, mat.getOwnershipRange()[0]))
        self.reorder = reorder
        _check(self.prefix, self.coarse_max, self.max_levels, self.damping, self.jacobi, self.smoother)
        self.hierarchy = self.pc = self.P = self.perm = self.order = self.xp = self.yp = self.weak = self.range = None
        self.xw = self.reordered = None     # the projected input's work vector (:meth:`mult`); P, its values' map
        self.age, self.first_its, self.build_ms, self.refresh_ms = 0, None, 0.0, 0.0
        self.renew, self.ranges = False, Ranges(mat)
        self.anew = None            # why the last numeric step made the leaves anew on this analysis, else None
        self.scales, self.times, self.leaf_its, self.ms_per_it, self.its = [], {}, [], 0.0, None
        self.analysis_ms = 1e3 * (time.perf_counter() - t0)

    def numeric(self, rows, density=None, keep_space=False):
        """The hierarchy and its V-cycle for the operator's new values: on the operator itself, or (``reorder``, by
        default where some rank's rows are not in a local order, :func:`.choice.local_order`) on its copy with each
        rank's rows in the order of their leaves, so that a leaf's rows lie together whatever the user's numbering
        (P1 triangles numbered at random, 262 144 rows: setup + solve 1 685 against 1 235 ms; the 2-D DMDA at 1M rows,
        its own order: 2 908 against 3 180). New values of the pattern keep the finest level's leaves and make the
        coarser levels anew (:meth:`.hierarchy.Hierarchy.refresh`) unless they moved away from them on some rank
        (:meth:`moved`) or a solve took more than :data:`RENEW` times the iterations of the first on them: then the
        hierarchy is built anew (its leaves' order too, where reordered), the analysis (the whole-matrix choice, whether
        to reorder, the null components) kept."""
        self.times = {}
        renew, self.renew = Collective(self.mat.getComm()).any(self.renew), False
        grew = bool(self.first_its and self.its and self.its > RENEW * self.first_its)
        self.anew = (None if self.hierarchy is None else "the couplings moved away from the last ones" if renew
                     else f"a solve took {self.its} iterations, more than {RENEW} x the first's {self.first_its}"
                     if grew else None)
        if self.anew is None and self.hierarchy is not None:
            self.pc.destroy()               # first: the old coarser levels it holds go before the new are made
            self.pc = None
            with phase("HTPLevels", self.times, "levels"):
                if self.P is not None:
                    self.reordered.refill(rows)
                self.hierarchy.refresh(rows if self.P is None else None)
            self._cycle(rows)
            self.age += 1
            self.refresh_ms = sum(self.times.values())
            return
        self._free()
        self.age, self.first_its, self.its, self.leaf_its = 0, None, None, []
        with phase("HTPLevels", self.times, "levels"):
            leaf = leaves(self.mat, rows)
            self.weak = WeakInside(rows, self.mat.getOwnershipRange()[0], leaf)
            A = self.mat
            if self.reorder:
                leaf = banded_leaves(self.mat, rows, leaf)          # numbered so: each level's coarse columns too
                self.perm = np.argsort(leaf, kind="stable")    # intp: numpy would convert PETSc's int32 indices at
                # each take, twice a V-cycle
                self.order = PETSc.IS().createGeneral((self.perm + self.mat.getOwnershipRange()[0]).astype(
                    PETSc.IntType), comm=self.mat.getComm())
                self.reordered = Reordered(self.mat, rows, self.perm, self.order)
                A = self.P = self.reordered.P
                leaf = leaf[self.perm]
                self.xp, self.yp = A.createVecs()
            self.hierarchy = Hierarchy(A, self.coarse_max, self.max_levels, self.jacobi, leaf,
                                       self.smoother == "leaves", rows if self.P is None else None,
                                       self.mat.getSize()[0] > self.coarse_max and row_scaled(self.mat, rows),
                                       self.least)
        self._cycle(rows)
        self.build_ms = sum(self.times.values())       # refresh_ms: the last refresh's, kept across builds

    def _cycle(self, rows):
        """The range check (:mod:`.ranges`) and the V-cycle of the hierarchy, its coarsest factor grounded in each
        component that stands for a null one (a floating Neumann square of contrast 1e6 beside a Dirichlet one, whose
        null pivot rounding hid: CG had stopped with DIVERGED_INDEFINITE_MAT)."""
        self.range, ground = self.ranges.check(rows, self.hierarchy, self.perm)
        with phase("HTPCoarseFactor", self.times, "cycle"):
            self.pc, self.scales = cycle.multigrid(self.hierarchy, self.prefix, self.damping, self.smoother, ground)

    def moved(self, rows, penalty=None) -> bool:
        """False: new values of the pattern call for no new analysis. Where ``rows`` (this rank's) moved away from the
        finest leaves (:mod:`.moved`) by more than keeping them costs, the next numeric step builds the hierarchy anew
        (:attr:`renew`; the analysis kept: the whole-matrix choice and the null components took 15 of 110 ms a frame).
        Unlike the two-level method, whose analysis costs several solves, old leaves are not tried first: with the
        coarser levels made anew they save in set-up what they cost in iterations (inclusions that move every frame,
        901086a against 8afa566: 65 536 rows 19-24 against 17 iterations, 118-132 against 118-168 ms a frame; 1M rows
        20-24 against 20-21, 2 040-2 382 against 2 322-2 549 ms: ``results/seqkeep-20261128``), every level's kept twice
        that (de23174, 1M rows: 44 against 23 iterations, 3.0 against 2.2 s a frame); only where a cost was measured
        (the extra iterations old leaves took, at ms per iteration, or ``penalty``, that cost the last time values
        moved, which the variant keeps: :meth:`..variants.TwoLevel.moved`) does keeping them win when it is the smaller
        (:func:`..twolevel.spacereuse.stale_cost`). This rank's alone: :meth:`numeric` or's it over the ranks."""
        self.renew = False
        if self.weak is None or not self.weak.moved(rows):
            return False
        cost = stale_cost(self.leaf_its, self.ms_per_it)
        cost = penalty if cost is None else cost
        self.renew = cost is None or cost > self.build_ms - self.refresh_ms
        return False

    def mult(self, x, y):
        """y = one V-cycle applied to x (permuted to the leaves' order where reordered); x and y taken off the null
        constants of :attr:`range` that the solved operator annihilates, so that CG stays in the range (a bare Neumann
        square of contrast 1e6, coarsest 200: DIVERGED_INDEFINITE_MAT at 22-23 iterations, now 15-17)."""
        null = self.range if self.range is not None and self.range.k and self.range.active else None
        if null is not None:
            if self.xw is None:
                self.xw = x.duplicate()
            x.copy(self.xw)
            x = null.project(self.xw)
        if self.P is None:
            with cycle.bare(self.mat):
                self.pc.apply(x, y)
        else:
            np.take(x.array_r, self.perm, out=self.xp.array_w)      # no temporary of the permuted vector
            self.pc.apply(self.xp, self.yp)
            y.array_w[self.perm] = self.yp.array_r
        if null is not None:
            null.project(y)

    def presolve(self, ksp, b, x, stale=False):
        """A named error where b holds a part along null constants the row sums show (:mod:`.ranges`); no start."""
        if self.range is not None:
            self.range.check(ksp, b)
        return None

    def solved(self, its, seconds):
        """Keep the first and the last solve's iterations on this hierarchy and ms per iteration."""
        self.its, self.ms_per_it = its, 1e3 * seconds / max(its, 1)
        self.leaf_its = self.leaf_its[:1] + [max([its] + self.leaf_its[1:])]     # the first and the most
        if self.first_its is None:
            self.first_its = its

    def inner_pcs(self) -> dict:
        """The PCMG."""
        return {} if self.pc is None else {"multigrid": self.pc}

    def check(self, probes=0) -> str:
        """Empty when the V-cycle's set-up succeeded."""
        reason = self.pc.getFailedReason()
        return "" if reason == PETSc.PC.FailedReason.NOERROR else f"the multigrid set-up failed ({reason})"

    @property
    def nbytes(self) -> int:
        """Bytes this rank holds besides the operator, 12 per stored entry: the reordered copy (and 8 an entry of its
        values' map), each level's leaf blocks, W and E, the leaf solves' factors and the coarse factor (the band
        counted, PCREDUNDANT's gathered LU not)."""
        mats = [self.P] if self.P is not None else []
        for level in self.hierarchy.levels:
            mats += [m for m in (level.B, level.W) if m is not None]
        mats += self.hierarchy.operators()[1:]
        total = sum(int(m.getInfo()["nz_used"]) for m in mats)
        pcs = [self.pc.getMGSmoother(level).getPC() for level in range(1, self.pc.getMGLevels())]
        pcs = [pc.getBJacobiSubKSP()[0].getPC() if pc.getType() == "bjacobi" else pc for pc in pcs]
        coarse = self.pc.getMGCoarseSolve().getPC()
        band = coarse.getType() == PETSc.PC.Type.PYTHON                  # a band's values: 8 bytes each
        taken = 0 if self.reordered is None or self.reordered.take is None else self.reordered.take.nbytes
        return 12 * (total + sum(held(pc) for pc in pcs)) + (8 if band else 12) * held(coarse) + taken

    def describe(self) -> list:
        """Lines for ``-ksp_view``."""
        h, t = self.hierarchy, self.times
        rows = " -> ".join(str(n) for n in h.rows())
        ratio = ", ".join(f"{level.A.getSize()[0] / level.W.getSize()[1]:.1f}" for level in h.levels)
        return [f"levels: {len(h.rows())}, rows {rows} (the coarsest by {cycle.coarse_text(self.pc)}"
                f"; at most {self.coarse_max} rows unless the levels ran out); "
                f"operator complexity {h.complexity():.2f}",
                f"leaves: aggregation, rows per coarse vector {ratio or 'none'}"
                + ("; each rank's rows taken in their leaves' order" if self.P is not None else "")
                + f"; coarse vectors: the leaf constants{WEIGHTED if h.weighted and h.levels else ''} smoothed by one "
                + "Jacobi step; smoother: " + cycle.described(self.pc, self.scales, self.damping),
                f"setup ms: levels {t.get('levels', 0):.1f}, V-cycle {t.get('cycle', 0):.1f}; options -{self.prefix}*"
                + (f"; finest leaves kept from {self.age} numeric setup{'s' if self.age > 1 else ''} ago ("
                   + ("leaf blocks, " if self.smoother == "leaves" else "")
                   + "smoothed coarse vectors and Galerkin operator of the new values; the coarser levels made anew)"
                   if self.age else f"; leaves made anew for these values: {self.anew}" if self.anew else ""),
                f"memory on this rank: {self.nbytes / max(self.mat.getLocalSize()[0], 1):.0f} bytes per unknown"]

    def _free(self):
        if self.hierarchy is not None:
            self.hierarchy.destroy()
        for obj in (self.pc, self.P, self.order, self.xp, self.yp, self.xw):
            if obj is not None:
                obj.destroy()
        self.pc = self.hierarchy = self.P = self.perm = self.order = self.xp = self.yp = self.xw = self.reordered = None

    def destroy(self):
        """Free the V-cycle and the hierarchy."""
        self._free()
