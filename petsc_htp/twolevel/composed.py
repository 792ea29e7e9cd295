"""The two-level variant inside HTPPC, composed from PETSc parts, on any number of ranks.

    M = Q + (I - QA) B (I - AQ)  (balanced)   or   M = Q + (I - QA) B  (deflated),   Q = W (W^T A W)^-1 W^T

B = D^-1 solves the leaves (D, A's leaf blocks, one sparse matrix and one PETSc factor per rank), W holds every
leaf's coarse vectors and E = W^T A W is solved by the coarse solver. The parts, each one job:

- :mod:`.structure`: the analysis of a pattern (leaves, components, W's columns), numpy;
- :mod:`.leafsolvers`: B, the leaf factor (``<prefix>leaf_``);
- :mod:`.space`: W's values (the coarse vectors, null components left out);
- :mod:`.operators`: O = A - D, W, C = O W, E and their products with PETSc's reuse;
- :mod:`.coarsesolve`: E^-1 (``<prefix>cs_``);
- :mod:`.forms`: the deflated and balanced forms (apply and the start before a solve).

:class:`TwoLevelPC` puts them together: construction is the analysis (every matrix with its final pattern,
symbolic factorisations and products), :meth:`TwoLevelPC.numeric` only moves values. Each phase is a PETSc
log event (:mod:`petsc_htp.events`).
"""
from __future__ import annotations

import numpy as np
from petsc4py import PETSc

from . import dominance, inner, nearnull, nullspace, scaling, sizing
from ..checks import rayleigh_reason
from ..events import phase
from ..petscmat import diagonal_block
from .aggregation import THETA
from .coarsesolve import CoarseSolve
from .config import COARSE_TEXT
from .forms import Forms
from .leafsolvers import ExactLeaves, OverlappingLeaves
from .operators import Operators
from .space import CoarseSpace
from .spacereuse import keeps_leaves
from .structure import Structure


class TwoLevelPC:
    """The two-level preconditioner of one matrix pattern; :meth:`numeric` takes each frame's values.

    Parameters
    ----------
    mat : petsc4py.PETSc.Mat
        The operator (AIJ, any number of ranks); products with it are reused frame after frame.
    rows : scipy.sparse.csr_matrix
        This rank's rows of ``mat`` (global columns, sorted).
    coords : numpy.ndarray (n, d), optional
        This rank's row coordinates (Morton leaves).
    cfg : Config
    prefix : str
        Options prefix of the inner solvers: ``<prefix>leaf_`` (leaf factor) and ``<prefix>cs_`` (coarse).
    net : CoarseNet, optional
        The coarse network (``cfg.coarse == 'learned'``).
    """

    def __init__(self, mat, rows, coords, cfg, prefix="htp_", net=None):
        self.leafsolver = self.space = self.ops = self.coarse = self.forms = None
        self.times, self.numeric_count, self.quotients, self.its = {}, 0, None, []   # its: first, last solve with this W
        self.leaf_its, self.ms_per_it = [], 0.0      # first, most since these leaves; the last's ms/iteration
        try:
            self._analyse(mat, rows, coords, cfg, prefix, net)
        except Exception:
            self.destroy()                       # what was built so far
            raise

    def _analyse(self, mat, rows, coords, cfg, prefix, net):
        times = {}
        with phase("HTPAnalysis", times, "analysis"):
            self.mat, self.net, self.coords = mat, net, coords
            self.st = st = Structure(mat, rows, coords, cfg, net.cfg.rank if net is not None else None)
            self.cfg, lay = st.cfg, st.lay
            self.torch_analysis = None
            if st.cfg.coarse == "learned":                            # the network's layout: pattern only
                from .batched import analyse

                self.torch_analysis = analyse(st.block, st.leaves)
            self.d_values = np.zeros(lay.d_src.size)
            opts = sizing.leaf_factor(st.dim, lay.leaves.kind)
            factor = lambda m: inner.configured_pc(PETSc.COMM_SELF, m, prefix + "leaf_", opts)[0]    # noqa: E731
            if st.cfg.overlap:
                self.leafsolver = OverlappingLeaves(lay, rows, st.cfg.overlap, factor)
            else:
                self.leafsolver = ExactLeaves(lay, self.d_values, factor, lay.d_in_a_order and st.coll.size == 1)
            self.space = CoarseSpace(st, factor, None if st.cfg.overlap else self.leafsolver.f)
            self.ops = Operators(mat, rows, st)
            self.coarse = CoarseSolve(st, st.cfg.solver, prefix + "cs_")
            self.forms = Forms(mat, self.ops, self.leafsolver, self.coarse, st.cfg.form)
        self.analysis_ms = times["analysis"]

    def moved(self, rows, penalty=None) -> bool:
        """Whether new values ``rows`` call for new leaves: the operator's near null space has a new number of
        vectors (W's pattern), or the couplings moved away from the leaves (:meth:`.structure.Structure.moved`) and
        either a severe jump moved into them (:meth:`.structure.Structure.jumped`) or new ones would pay
        (:func:`.spacereuse.keeps_leaves`; ``penalty``: what old leaves cost the last time values moved)."""
        if self.st.fixed != nearnull.count(self.mat, self.st.bs):
            return True
        self.coarse.renew = self.st.moved(rows)             # kept leaves then get their coarse AMG anew
        if not self.coarse.renew:
            return False
        return self.st.jumped(rows) or not keeps_leaves(self.analysis_ms, self.leaf_its, self.ms_per_it, penalty)

    def numeric(self, rows, density=None, keep_space=False):
        """New values (``rows``: this rank's rows, the analysed pattern); ``keep_space`` keeps W's values."""
        lay, T, data = self.st.lay, {}, rows.data
        solved, ratios = dominance.pinned(rows, lay.start, self.st.coll)      # rows their diagonal decides
        with phase("HTPLeafFactor", T, "leaf"):
            o_values = self.ops.couplings(data)
            ground = self.space.null(self.mat, rows)
            np.take(data, lay.d_src, out=self.d_values)
            if ground.any():
                nullspace.ground(self.d_values, lay.d_diag, nullspace.first_rows(lay.pieces.label, ground))
            new_space = not (keep_space and self.space.kept is not None and not self.space.watch.rescaled(self.d_values))
            if not (new_space and self.space.shared):        # else the space borrows the factor first
                self.leafsolver.numeric(data)
        with phase("HTPCoarseSpace", T, "coarse_space"):
            try:
                if new_space:
                    self.its, weights = [], None
                    if self.space.flat:                         # a null constant stays, an attached vector serves
                        with diagonal_block(self.mat, rows) as block:
                            weights, self.quotients = scaling.weights(rows, lay.start, self.st.coll, block, solved,
                                                                      self.mat if self.space.null_components else None)
                    self.space.compute(self.d_values, o_values, self.ops.o_perm_rows,
                                       self._seeds(rows, density), nearnull.vectors(self.mat, self.st.bs), weights)
                else:
                    self.space.age += 1
            finally:
                if new_space and self.space.shared:           # the borrowed factor gets D back, also on errors
                    with phase("HTPLeafFactor", T, "leaf"):
                        self.leafsolver.numeric(data)
        left = dominance.left_out(solved, ratios, self.space.weights is not None)
        with phase("HTPProducts", T, "products"):
            self.ops.products(self.space.finish(*left), self.leafsolver.exact, self.forms.needs_F())
        with phase("HTPCoarseFactor", T, "coarse_factor"):
            self.coarse.setup(self.ops)
            self.forms.settle()
        self.times, self.numeric_count = T, self.numeric_count + 1

    def _seeds(self, rows, density):
        """The learned space's seeds (the coarse network's vectors), else None (smooth seeds)."""
        if self.cfg.coarse != "learned" or not self.st.seeded:
            return None
        from .coarsenet import learned_seeds

        return learned_seeds(self.net, self.torch_analysis, rows, self.st, self.coords, density, self.space.seeds)

    def mult(self, x, y):
        """y = M x in the form in use."""
        self.forms.mult(x, y)

    def presolve(self, ksp, b, x, stale=False):
        """The form's start before a solve (:meth:`.forms.Forms.presolve`), once b is in the range."""
        if self.space.range is not None:
            self.space.range.check(ksp, b)
        return self.forms.presolve(ksp, b, x, stale)

    def solved(self, its, seconds):
        """A KSPSolve took ``its`` iterations in ``seconds``: kept as the first and the last since the coarse space
        was made (:func:`.spacereuse.keeps`), and the first and the most since the leaves were (the last let two value
        sets in turn keep leaves that cost one of them 500 iterations: :func:`.spacereuse.keeps_leaves`)."""
        self.its, self.leaf_its = self.its[:1] + [its], self.leaf_its[:1] + [max([its] + self.leaf_its[1:])]
        self.ms_per_it = 1e3 * seconds / max(its, 1)
        self.forms.started = False

    def check(self, probes=0) -> str:
        """Empty when every factorisation succeeded, the coarse space is finite and ``probes`` random Rayleigh
        quotients of the balanced M are positive, else why not (collective)."""
        bad, ok = [], PETSc.PC.FailedReason.NOERROR
        reasons = (("leaf", self.leafsolver.pc.getFailedReason()), ("Neumann", self.space.failed),
                   ("coarse", self.coarse.pc.getFailedReason() if self.coarse.pc is not None else ok))
        for name, reason in reasons:
            if reason != ok:
                bad.append(f"{name} factorisation failed ({reason})")
        if not np.all(np.isfinite(self.space.values)):
            bad.append("the coarse space is not finite")
        if self.st.coll.any(bad) and not bad:
            bad.append("a factorisation failed on another rank")
        if bad or not probes:
            return "; ".join(bad)
        return rayleigh_reason(self.forms.min_rayleigh(probes), "two-level")

    @property
    def nbytes(self) -> int:
        """Bytes held on this rank: D and its factor, S and its, W, C, C^T, E and the coarse solver's (8 a value)."""
        return int(8 * (self.ops.nnz() + self.space.nnz() + self.leafsolver.nnz() + self.coarse.nnz()))

    def inner_pcs(self) -> dict:
        """The inner PETSc solvers: leaf factor and coarse solver."""
        return {"leaf solver": self.leafsolver.pc, "coarse solver": self.coarse.pc}

    def describe(self) -> list:
        """Short lines for ``-ksp_view``."""
        st, t, cfg, sp = self.st, self.times, self.cfg, self.space
        lay, lv = st.lay, st.leaves
        kept = sp.kept if sp.kept is not None else st.ncols
        q = (f"{kept.min()}-{kept.max()} per leaf (mean {kept.mean():.2f})" if kept.min() != kept.max()
             else f"{kept.min()} per leaf")
        names = [name for name in st.auto if name != "aggregation" or lv.kind == "aggregation"]
        names = ", ".join(names[:-1]) + " and " + names[-1] if len(names) > 1 else "".join(names)
        auto = f" ({names} by the problem: {st.dim}-D)" if names else ""
        wide = lv.kind == "aggregation" and st.theta != THETA
        strength = f", strong couplings from {st.theta:.3g} (wide rows)" if wide else ""
        size = (f"mean {lv.sizes.mean():.1f} rows, second pass {cfg.aggregation}" if lv.kind == "aggregation"
                else f"L={cfg.leaf}")
        lone = st.coll.sum(int(lay.decoupled.sum()))
        shape = [f"{st.shape.describe()} (this rank's rows)"] if st.shape is not None else []
        form = self.forms.form()
        return shape + [
                f"leaves: {lv.kind}, {size}{auto}{strength}, {st.coll.sum(lv.n_leaves)} in all "
                f"({lv.n_leaves} on this rank), "
                f"sizes {lv.sizes.min()}-{lv.max_size}; {st.n_pieces} pieces"
                + (f", {lone} of them decoupled rows (no coarse vector)" if lone else "")
                + f"; {self.leafsolver.describe()}",
                f"coarse: {cfg.coarse} ({COARSE_TEXT[cfg.coarse]}), {q}"
                + (f", from {st.fixed} near null vector(s) per leaf "
                   + ("spanning the piece constants" if st.covered else "beside the piece constants")
                   + f" ({nearnull.describe(self.mat, st.bs, st.bs_source)})" if st.fixed else "")
                + (f" (up to {st.extra} more where Ritz values are at most {cfg.tol:g} x the mean diagonal)"
                   if st.extra else "")
                + f"; global size {st.m}, {sp.null_components} null component(s) left out"
                + (f"; space kept from {sp.age} numeric setup{'s' if sp.age > 1 else ''} ago" if sp.age else "")
                + sp.notes(self.quotients),
                self.coarse.describe(),
                f"form: {form} (" + ("y = v - W E^-1 C^T v, v = B x; started so that W^T r0 = 0"
                                     if form == "deflated" else "symmetric balanced form") + ")",
                f"setup ms: analysis {self.analysis_ms:.1f} (once per pattern; leaves {lv.build_ms:.1f}); "
                + ", ".join(f"{k.replace('_', ' ')} {v:.1f}" for k, v in t.items()),
                "apply: float64 in PETSc (a linear operator to working precision: any KSP, any rtol)",
                f"memory on this rank: {self.nbytes / max(st.N // st.coll.size, 1):.0f} bytes per unknown"]

    def destroy(self):
        """Free every PETSc object (also of a construction that failed part of the way)."""
        for name in ("forms", "coarse", "ops", "space", "leafsolver"):
            part = getattr(self, name)
            if part is not None:
                part.destroy()
                setattr(self, name, None)
