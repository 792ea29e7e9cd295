"""The two forms of the two-level preconditioner, applied with PETSc's operators (Q = W E^-1 W^T, B the leaf
solve):

    M = Q + (I - QA) B (I - AQ)  (balanced, symmetric)   or   M = Q + (I - QA) B  (deflated).

With exact leaves D B = I, so W^T A B x = W^T x + C^T B x and the deflated form is y = v - W E^-1 C^T v with
v = B x: one leaf solve, one coarse solve and two thin products. Started so that W^T r0 = 0
(:meth:`Forms.presolve`), CG with it takes the iterations of the balanced form, which costs a second coarse
solve and three more thin products and serves KSPs that need a symmetric M. Inexact leaves go through A W.
A coarse PC that is neither a factor nor GAMG's V-cycle (``-htp_cs_pc_type ...``) is taken by the balanced form
as written, with A's own products in place of the shortcuts that assume E c = W^T x: M is then symmetric
positive definite for any symmetric positive definite coarse PC (an HTPPC nested there is one only with
``-htp_cs_htp_form balanced``: applied outside a KSP solve, it gets no start for the deflated form).
"""
from __future__ import annotations

import numpy as np
from petsc4py import PETSc

from ..events import event
from .exactstart import advance, residual

# Krylov methods that take the deflated form with its start (x0 += Q r0): checked on the foreign study's 2-D DMDA
# matrix, each to rtol 1e-8 in the true residual. Any other takes the balanced form, a fixed SPD operator: those that
# need a symmetric M (MINRES, CR, ...), and those whose right-preconditioned start went wrong (TFQMR, CGS and IBCGS
# reported convergence at a true relative residual of 2.4e3).
START_TOL = 0.1         # V-cycles: the start's W^T r0 is refined below this times the KSP's tolerance (the deflated
# form takes W^T r0 = 0: a smooth solution, A u = b for u = 1 on a Laplacian of 250 000 rows, took 97 CG iterations
# after one start of two V-cycles, none after ten refinements; a random b 27 either way) ...
START_STEPS = 10        # ... in at most this many steps (two V-cycles each) ...
START_CUT = 0.5         # ... where the first left it below this times W^T b, and while each step halves it (with
# coefficient jumps two V-cycles left it at 5.5 ||b|| and refining it cost 3 more CG iterations: 2-D DMDA, 262 144
# rows on 2 ranks, 41 against 44)
DEFLATED_KSPS = ("cg", "pipecg", "groppcg", "fcg", "pipefcg", "gcr", "gmres", "fgmres", "lgmres", "dgmres", "pgmres",
                 "bcgs", "qmrcgs", "bicg", "richardson", "chebyshev")
FACTOR_ONLY_KSPS = ("pipecg",)   # of those, the ones that take the deflated form only where the coarse solve is a
# factor: under two GAMG V-cycles PIPECG, whose recurrences carry M w in place of M r, stalled on PETSc's ksp ex45
# (a constant right-hand side, 49^3: relative residual 5e-3 at 200 iterations; 16 in the balanced form, 13 with the
# coarse LU); CG, GROPPCG, PIPEFCG and the others of the list took 10-16 there, Richardson 35


class Forms:
    """Applications of M for the parts ``ops`` (:class:`~.operators.Operators`), ``leafsolver`` and ``coarse``
    (:class:`~.coarsesolve.CoarseSolve`) on ``mat``; ``form`` is the configured one (auto, deflated, balanced)."""

    def __init__(self, mat, ops, leafsolver, coarse, form):
        self.mat, self.ops, self.B, self.coarse, self.configured = mat, ops, leafsolver, coarse, form
        self.auto, self.forced = "deflated" if self._deflatable() else "balanced", None
        self.started = False          # inside a KSPSolve whose presolve made the deflated start
        self.v, self.t = mat.createVecLeft(), mat.createVecLeft()
        self._leaf_ev, self._coarse_ev = event("HTPLeafSolve"), event("HTPCoarseSolve")

    def form(self, ksp_type=None) -> str:
        """The form in use: forced, configured, or for 'auto' the one the last :meth:`presolve` chose (deflated
        unless ``ksp_type`` is not one of :data:`DEFLATED_KSPS`, the coarse solve is one V-cycle or refined, or it is
        no factor under :data:`FACTOR_ONLY_KSPS`)."""
        if self.forced or self.configured != "auto":
            return self.forced or self.configured
        return "balanced" if ksp_type is not None and ksp_type not in DEFLATED_KSPS else self.auto

    def settle(self):
        """After the coarse solver's setup: the 'auto' form it calls for (until a presolve decides), and no F where
        the form as written has no use for it (it was made before the coarse PC's type was known)."""
        self.auto = "deflated" if self._deflatable() else "balanced"
        if self.coarse.general:
            self.ops.drop_F()

    def _deflatable(self) -> bool:
        """Whether the coarse solve suits the deflated form (:attr:`.coarsesolve.CoarseSolve.deflatable`), and for
        overlapping leaves is a factor: their B A reaches about the overlap count, and a V-cycle's error grown by it
        took CG from 34 iterations (LU) to none that converged (P1 tets, 27 000 rows, ``-htp_overlap 1``; 38 in the
        balanced form)."""
        return self.coarse.deflatable and (self.coarse.direct or not self.B.summed)

    def needs_F(self) -> bool:
        """Whether the form in use needs F = W^T C."""
        return self.form() == "balanced" and self.B.exact and not self.coarse.general

    def _leaf(self, x, v):
        self._leaf_ev.begin()
        try:
            self.B.apply(x, v)
        finally:
            self._leaf_ev.end()

    def _coarse(self, g, c):
        self._coarse_ev.begin()
        try:
            self.coarse.apply(g, c)
        finally:
            self._coarse_ev.end()

    def mult(self, x, y):
        """y = M x in the form in use; the deflated form only inside a solve its :meth:`presolve` started (any
        other caller, a PCApply of its own or an outer Krylov method around a PREONLY, gets the balanced form: the
        deflated one without its start, under PCFIELDSPLIT's outer CG, took it to 10 000 iterations and a relative
        residual of 11)."""
        ops, cs, v, t = self.ops, self.coarse, self.v, self.t
        g, c, c2 = cs.g, cs.c, cs.c2
        if self.form() == "deflated" and self.started:
            self._leaf(x, v)                                   # v = B x
            if self.B.exact:
                ops.CT.mult(v, g)                              # g = C^T v = (A W)^T B x - W^T x
                g.scale(-1.0)
            else:
                ops.W.multTranspose(x, g)
                g.scale(-1.0)
                ops.AW.multTransposeAdd(v, g, g)
                g.scale(-1.0)                                  # g = W^T x - (A W)^T B x
            self._coarse(g, c)
            ops.W.multAdd(c, v, y)                             # y = v + W E^-1 (W^T x - (A W)^T v)
            return
        ops.W.multTranspose(x, g)
        self._coarse(g, c)                                     # c1 = E^-1 W^T x
        if self.coarse.general:
            self._general(x, y)
            return
        if not self.B.exact:
            ops.AW.mult(c, t)
            t.aypx(-1.0, x)                                    # u = x - A W c1
            self._leaf(t, v)                                   # v = B u
            ops.AW.multTranspose(v, g)
            self._coarse(g, c2)
            c2.aypx(-1.0, c)
            ops.W.multAdd(c2, v, y)                            # y = v + W (c1 - E^-1 (A W)^T v)
            return
        if ops.F is None:
            ops.need_F()
        ops.C.mult(c, t)
        t.aypx(-1.0, x)                                        # x - C c1
        self._leaf(t, v)                                       # s = B (x - C c1)
        ops.CT.mult(v, g)
        ops.F.mult(c, c2)
        g.axpy(-1.0, c2)                                       # C^T s - W^T C c1
        self._coarse(g, c2)
        c2.scale(-1.0)
        ops.W.multAdd(c2, v, y)                                # y = s - W E^-1 (C^T s - W^T C c1)

    def _general(self, x, y):
        """The balanced form with A's products, after c1 = V W^T x: y = W c1 + s - W V W^T A s, s = B (x - A W c1)."""
        ops, cs, v, t = self.ops, self.coarse, self.v, self.t
        ops.W.mult(cs.c, y)                                    # y = W c1 (for now)
        self.mat.mult(y, t)
        t.aypx(-1.0, x)                                        # x - A W c1
        self._leaf(t, v)                                       # s = B (x - A W c1)
        self.mat.mult(v, t)
        ops.W.multTranspose(t, cs.g)
        self._coarse(cs.g, cs.c2)                              # c2 = V W^T A s
        cs.c2.aypx(-1.0, cs.c)
        ops.W.multAdd(cs.c2, v, y)                             # y = s + W (c1 - c2)

    def presolve(self, ksp, b, x, stale=False):
        """Start the deflated form on W^T r0 = 0: x0 += Q (b - A x0). Returns the KSP settings this changed, to give
        back after the solve ({'guess': its initial-guess flag, 'divtol': its divergence tolerance}), else None. The
        start minimises the error's energy, not the residual: where a KSP that tests the unpreconditioned norm sees
        the start grow the residual (a row scaling far from constant, a long chain), its divergence tolerance grows
        alike for the solve, as PETSc's test at iteration 0 compares with ||b|| (D A D, D in 1e-3 .. 1e3: 2.2e4
        ||b||, DIVERGED_DTOL before the first iteration; CG then converges in 42; the preconditioned norms barely
        grow). Under 'auto' the solve takes the balanced form when the KSP is not one of :data:`DEFLATED_KSPS`
        (PREONLY included: an outer method applies M), the preconditioner is ``stale`` (reused on new values, or made
        from a Pmat other than the KSP's Amat: D B = I no longer holds for A; the deflated start then left a Pmat +
        0.3 diag solve at a residual of 1e5 and a Pmat + 0.01 diag CG solve stalled), or the coarse solve does not
        suit it (:meth:`_deflatable`: not exact, :func:`.sizing.coarse_exact`; needing refinement, :mod:`.coarsesolve`:
        a contrast of 1e6 at 262 144 rows, where the deflated form still broke down on 3 of 4 frames and the balanced
        one on none; V-cycles under overlapping leaves; any but a factor under :data:`FACTOR_ONLY_KSPS`)."""
        kind = ksp.getType()
        if self.configured == "auto":
            inexact = (kind not in DEFLATED_KSPS or stale or not self._deflatable()
                       or (kind in FACTOR_ONLY_KSPS and not self.coarse.direct))
            self.auto = "balanced" if inexact else "deflated"
            if self.needs_F():
                self.ops.need_F()
        if self.form(kind) != "deflated" or kind == PETSc.KSP.Type.PREONLY:
            return None
        t, cs = self.t, self.coarse
        amat = ksp.getOperators()[0]    # not stale: the matrix M was made from, or A without the Dirichlet rows'
        nonzero = residual(ksp, b, x, t)   # columns (:mod:`petsc_htp.keptcolumns`), whose x0 there is then exact
        before = t.norm()
        self.ops.W.multTranspose(t, cs.g)
        rtol, atol = ksp.getTolerances()[:2]
        self._coarse_ev.begin()         # c = E^-1 g, V-cycles refined (:data:`START_TOL`)
        try:
            cs.solve_to(cs.g, cs.c, START_TOL * max(rtol * before, atol), START_CUT, START_STEPS)
        finally:
            self._coarse_ev.end()
        self.ops.W.mult(cs.c, self.v)
        changed = advance(ksp, x, self.v, nonzero)    # no null component (CG from zero keeps none: a Neumann
        self.started, divtol = True, ksp.getTolerances()[2]   # solution had kept an offset of 0.27)
        if ksp.getNormType() == PETSc.KSP.NormType.UNPRECONDITIONED and divtol > 0 and before > 0:
            self.ops.W.mult(cs.c, self.v)
            self.v.scale(-1.0)
            amat.multAdd(self.v, t, t)                         # r0 = r - A W c
            grown = t.norm() / before
            if grown > 1.0:
                changed["divtol"] = divtol
                ksp.setTolerances(divtol=divtol * grown)
        return changed

    def min_rayleigh(self, probes) -> float:
        """Smallest x^T M x / x^T x of the balanced (symmetric) M over ``probes`` random x (collective)."""
        if self.B.exact and not self.coarse.general:
            self.ops.need_F()
        x, y = self.mat.createVecs()
        rng = PETSc.Random().create(self.mat.getComm())
        self.forced = "balanced"
        quotients = []
        try:
            for _ in range(probes):
                x.setRandom(rng)
                self.mult(x, y)
                quotients.append(x.dot(y) / x.dot(x))
        finally:
            self.forced = None
            for obj in (x, y, rng):
                obj.destroy()
        return float(np.min(quotients))

    def destroy(self):
        """Free the work vectors."""
        for obj in (self.v, self.t):
            obj.destroy()
        self.v = self.t = None

