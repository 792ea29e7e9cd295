"""The coarse solve E^-1 of the two-level method: a PETSc PC on the Galerkin operator under ``<prefix>cs_``.

By default (:func:`.sizing.coarse_solver`, :func:`.sizing.coarse_options`) a sparse LU (PCREDUNDANT on more than
one rank), or above :data:`.sizing.COARSE_DIRECT_MAX` rows (in 2-D on several ranks above
:data:`.sizing.COARSE_REDUNDANT_MAX`, in 3-D above :data:`.sizing.COARSE_PAIRED_DIRECT_MAX_3D` for paired aggregation
leaves) one GAMG V-cycle (two in 2-D and on 3-D paired leaves), in the balanced form where
it is not exact enough for the deflated one (:attr:`CoarseSolve.exact`), whose near null space is W^T 1 (the constant's
coarse coefficients; with it, 120 outer CG iterations against 141 under a plain V-cycle on the foreign study's
dmda3d case at 64^3).
Any PETSc PC can replace it through its options; the PC that was made decides (a direct one is exact and
probed, below; V-cycles are taken as :func:`.sizing.coarse_exact` says, and those taken as exact are probed too:
above :data:`CYCLE_TOL` they take the balanced form; any other takes the balanced form). GAMG keeps its
interpolation for new values of E, as PETSc's does, but where the couplings moved away from kept leaves it is made
anew (:attr:`CoarseSolve.renew`).

An exact (LU) coarse solve is as accurate as E is conditioned: at a density contrast of 1e6, E's eigenvalues span
1e11 and the LU's forward error on a probe is 4e-5 (5e-10 at 1e3), which the deflated form, whose start and
shortcuts assume E c = g, turns into a residual that stalls near 1e-8 and a CG breakdown (DIVERGED_INDEFINITE_PC).
Each setup measures that error once (E c0 = g for a random c0) and, above :data:`REFINE_TOL`, applies the LU with
the fewest steps of iterative refinement (c += E^-1 (g - E c), at most :data:`REFINE_MAX`) that bring it below
:data:`REFINE_TARGET` (one step alone left that frame's CG stopping at 212 iterations).
"""
from __future__ import annotations

import math

from petsc4py import PETSc

from . import inner, nearnull, sizing
from ..petscmat import local_rows
from .spread import global_growth

REFINE_TOL = 1e-8       # forward error of the coarse LU on a probe above which refinement steps are added
REFINE_TARGET = 1e-12   # ... as many as bring it below this
REFINE_MAX = 3          # the most refinement steps
CYCLE_TOL = 0.4         # forward error on a probe above which V-cycles taken as exact go to the balanced form (the
# defaults' two V-cycles 0.05-0.08 on the foreign study's 3-D cases at 64k and 262k rows and the 2-D DMDA at 1M on
# two ranks, 0.19 on its 3-D DMDA at 22k rows on two; -htp_cs_pc_gamg_threshold 0.3, one level: 0.6-0.8, and the
# deflated form ran to DIVERGED_ITS on 2-4 ranks)
MESH_GROWTH = {2: 2.1, 3: 3.0}     # E's ball growth above which the LU chosen for a mesh's coarse operator gives way to
# GAMG: a 2-D grid of 100 000 rows with 1 % of its nodes joined at random (shortcuts) made E of 8 978 rows grow as
# 2.47 and its LU fill 118 x (7.9 s against 0.3 s); 2-D coarse operators of the foreign study 1.68-1.81 (the P1
# triangles numbered at random 1.92 on 2 ranks), 3-D 2.5-2.6. Milder shortcuts stay below: 0.3 % of the nodes, 1.89,
# an LU of fill 60 (1.5 s). Aggregation leaves only: Morton leaves' coarse graph grows faster (the own frames at
# 128^2: 2.31) and its LU serves (GAMG there: 32 CG iterations and 39.6 ms a frame against 28 and 22.6)
GROWTH_SEEDS = 32        # ... from this many seeds' balls (8 put the foreign study's P1 triangles at 1.88 on 2 ranks)
DIRECT = ("lu", "cholesky", "svd")         # PC types that solve E (also inside PCREDUNDANT: :meth:`CoarseSolve._direct`)


class CoarseSolve:
    """The coarse solver of a :class:`~.structure.Structure`; made at the first :meth:`setup`."""

    def __init__(self, st, solver, prefix):
        self.st, self.prefix, self.pc, self.rest = st, prefix, None, {}
        self.solver = solver if solver != "auto" else sizing.coarse_solver(st.dim, st.m, st.coll.size,
                                                                           st.leaves.kind, st.fixed, st.linear,
                                                                           st.dense)
        self.chosen = solver == "auto"
        self.exact = sizing.coarse_exact(st.dim, self.solver, st.leaves.kind, near=st.fixed)   # else balanced (Forms)
        self.g = self.c = self.c2 = self.E = self._res = self._dc = None
        self.refine, self.error, self.direct, self.general, self.cycles, self.loose = 0, 0.0, False, False, 1, False
        self.growth = math.nan                  # E's ball growth, where the LU was chosen (:meth:`_no_mesh`)
        self.renew = False      # set where the couplings moved away from kept leaves: a V-cycle made for the old
        # values' E then served poorly (DMDA 3-D, 64 000 rows, new inclusions: 116 CG iterations against 56 anew); the
        # PC is made anew (PCReset kept the level count GAMG had built last as its most: fewer levels each time)
        self.defaults = {}

    def setup(self, ops):
        """Set up the solver on the new values of the coarse operator of ``ops`` (made on first use; an LU, also
        PCREDUNDANT's, takes it as BAIJ where W's columns come in equal blocks)."""
        if self.pc is None:
            st, E = self.st, ops.E
            if self.chosen and self.solver == "lu" and st.leaves.kind == "aggregation" and not (
                    st.linear or st.dense or st.fixed) and self._no_mesh(E):
                self.solver = "gamg"
            defaults = sizing.coarse_options(st.dim, st.coll.size > 1, self.solver, st.leaves.kind, st.ordered,
                                             st.fixed)
            if st.col_block > 1:                      # block factors shift only within the diagonal blocks
                defaults = {k: "inblocks" if k.endswith("shift_type") else v for k, v in defaults.items()}
            self.pc, self.rest = inner.configured_pc(E.getComm(), E, self.prefix, defaults)
            self.defaults = defaults
            self.cycles = PETSc.Options(self.prefix).getInt("pc_mg_multiplicative_cycles",
                                                            int(defaults.get("pc_mg_multiplicative_cycles", 1)))
            if st.col_block > 1 and self.pc.getType() in ("lu", "redundant"):   # PCREDUNDANT's inner: LU
                self.pc.setOperators(ops.blocked(), ops.blocked())
            self.g, self.c, self.c2, self._res, self._dc = (E.createVecLeft() for _ in range(5))
            self.direct = self._direct()                       # the PC the options made, not the solver's name
            self.exact = self.direct or (self.pc.getType() == "gamg"
                                         and sizing.coarse_exact(st.dim, "gamg", st.leaves.kind, self.cycles, st.fixed))
            self.general = not self.direct and self.pc.getType() != "gamg"   # the balanced form as written
        self.E = ops.E
        if inner.multigrid(self.pc):
            if self.st.coll.any(self.renew):          # GAMG keeps its interpolation for new values (PETSc's
                old, self.pc = self.pc, None          # default); where the couplings moved under kept leaves on
                old.destroy()                         # any rank it is made anew (:attr:`renew`)
                self.pc, self.rest = inner.configured_pc(ops.E.getComm(), ops.E, self.prefix, self.defaults)
            self._near_null(ops)
        self.renew = False
        inner.set_up(self.pc, self.prefix, self.rest)
        if self.direct:
            self._refinement()
        elif self.exact:                              # V-cycles taken as exact: the probe tells (:data:`CYCLE_TOL`)
            self.loose = self._probe() > CYCLE_TOL

    @property
    def deflatable(self) -> bool:
        """Whether the deflated form may take this solve: exact, and exact without refinement, and V-cycles that
        met :data:`CYCLE_TOL` on the probe."""
        return self.exact and not self.refine and not self.loose

    def _no_mesh(self, E) -> bool:
        """Whether E's whole graph grows faster than a mesh's of the problem's dimension (:data:`MESH_GROWTH`; kept
        as :attr:`growth`; collective), which the matrix's sampled balls missed: its LU would fill."""
        with local_rows(E, copy=True) as rows:
            self.growth = global_growth(E, rows, self.st.coll, samples=GROWTH_SEEDS)
        return self.growth > MESH_GROWTH.get(self.st.dim, math.inf)

    def _direct(self) -> bool:
        """Whether the PC made solves E: a factor, or PCREDUNDANT around one (its inner type from the options, LU
        unless set)."""
        kind = self.pc.getType()
        if kind == "redundant":
            kind = PETSc.Options(self.prefix).getString("redundant_pc_type", "lu")
        return kind in DIRECT

    def _probe(self) -> float:
        """The solve's forward error ||c - c0|| / ||c0|| on E c0 = g for a random c0 (collective), kept as
        :attr:`error`."""
        c0, rng = self._dc.duplicate(), PETSc.Random().create(self.E.getComm())
        try:
            c0.setRandom(rng)
            self.E.mult(c0, self.g)
            self.apply(self.g, self.c)
            self.c.axpy(-1.0, c0)
            norm = c0.norm()
            self.error = self.c.norm() / norm if norm > 0 else 0.0
        finally:
            c0.destroy()
            rng.destroy()
        return self.error

    def _refinement(self):
        """Measure the solve's forward error on a random probe (:meth:`_probe`) and set :attr:`refine`: none up to
        :data:`REFINE_TOL`, else the fewest steps that take an error e to e^(steps + 1) <= :data:`REFINE_TARGET`, at
        most :data:`REFINE_MAX`."""
        self.refine = 0
        self._probe()
        e = min(self.error, 0.5)
        if self.error > REFINE_TOL:
            self.refine = min(REFINE_MAX, math.ceil(math.log(REFINE_TARGET) / math.log(e)) - 1)

    def _near_null(self, ops):
        """E's near null space for GAMG: W^T 1 and, in 3-D, W^T z for every near null vector z of A (:mod:`.nearnull`),
        made orthonormal: the coarse coefficients of what W holds exactly, in place of GAMG's default, the constant
        (3-D elasticity on paired leaves: 26 CG iterations against 102 with W^T 1 alone). In 2-D the two V-cycles of
        :data:`.sizing.COARSE_AMG_2D` told W^T z took 51 iterations on 2-D elasticity at 320 000 rows on two ranks and
        then, on new values, stopped with DIVERGED_INDEFINITE_PC (190 iterations with W^T 1 alone): not there."""
        near = nearnull.vectors(ops.mat, self.st.bs) if self.st.dim == 3 else None
        columns = [None] + ([] if near is None else list(near.T))          # None: the constant
        fine, vecs = ops.W.createVecLeft(), []
        for column in columns:
            fine.getArray()[:] = 1.0 if column is None else column
            z = ops.E.createVecLeft()
            ops.W.multTranspose(fine, z)
            size = z.norm()
            for q in vecs + vecs:                                        # Gram-Schmidt, twice
                z.axpy(-q.dot(z), q)
            norm = z.norm()
            if norm > 1e-8 * size:                                       # not (nearly) in the span of the others
                z.scale(1.0 / norm)
                vecs.append(z)
            else:
                z.destroy()
        nsp = PETSc.NullSpace().create(vectors=vecs, comm=ops.E.getComm())
        ops.E.setNearNullSpace(nsp)
        for obj in [fine, nsp] + vecs:
            obj.destroy()

    def apply(self, g, c):
        """c = E^-1 g, refined :attr:`refine` times."""
        self.pc.apply(g, c)
        for _ in range(self.refine):
            self._residual(g, c)
            self._correct(c)

    def solve_to(self, g, c, target, cut, steps):
        """c = E^-1 g (:meth:`apply`), then where the solve is not a factor refined until ||g - E c|| <= ``target``,
        where the first left it below ``cut`` times ||g|| and while each step halves it, at most ``steps`` times
        (the deflated form's start: :meth:`.forms.Forms.presolve`)."""
        self.apply(g, c)
        if self.direct:
            return
        last = cut * g.norm()
        for _ in range(steps):
            now = self._residual(g, c)
            if now <= target or now > last:
                return
            last = 0.5 * now
            self._correct(c)

    def _residual(self, g, c) -> float:
        """g - E c into the work vector; its norm."""
        self.E.mult(c, self._res)
        self._res.aypx(-1.0, g)
        return self._res.norm()

    def _correct(self, c):
        """c += the solve of the work vector's residual."""
        self.pc.apply(self._res, self._dc)
        c.axpy(1.0, self._dc)

    def describe(self) -> str:
        """The coarse solver, and why it was chosen."""
        why = ""
        if self.chosen:
            st = self.st
            limit = sizing.direct_limit(st.dim, st.coll.size, st.leaves.kind, st.fixed)
            several = " on several ranks" if st.dim == 2 and st.coll.size > 1 else ""
            why = (f"direct up to {limit}{several} in {st.dim}-D" if not (st.linear or st.dense and st.m > limit) else
                   "direct at any size " + ("on a chain, whose LU does not fill" if st.linear else "with a dense row"))
            if self.growth > MESH_GROWTH.get(st.dim, math.inf):
                why = f"its graph grows as {self.growth:.2f}, no {st.dim}-D mesh's: an LU would fill"
            why = f" (by the problem: {st.m} rows; {why})"
        order = "; coarse columns in METIS's nested-dissection order of the leaf graph" if self.st.ordered else ""
        loose = f"; forward error {self.error:.2g} on a probe, above {CYCLE_TOL}: too loose for the deflated form"
        refine = (f"; {self.refine} refinement step(s) (forward error {self.error:.1e} on a probe)" if self.refine
                  else loose if self.loose else "")
        return f"coarse solve: {inner.text(self.pc, self.cycles)}{why}{order}{refine}; options -{self.prefix}*"

    def nnz(self) -> int:
        """Values the solver holds besides the operator."""
        return inner.held(self.pc) if self.pc is not None else 0

    def destroy(self):
        """Free the PETSc objects."""
        self.E = None                                    # the operators' own
        for name in ("pc", "g", "c", "c2", "_res", "_dc"):
            obj = getattr(self, name)
            if obj is not None:
                obj.destroy()
                setattr(self, name, None)
