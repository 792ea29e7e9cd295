"""The coarse solve E^-1 of the two-level method: a PETSc PC on the Galerkin operator under ``<prefix>cs_``.

By default (:func:`.sizing.coarse_solver`, :func:`.sizing.coarse_options`) a sparse LU (PCREDUNDANT on more than
one rank), or above :data:`.sizing.COARSE_DIRECT_MAX` rows (in 2-D on several ranks above
:data:`.sizing.COARSE_REDUNDANT_MAX`) one GAMG V-cycle, in the balanced form where it is not exact enough for the
deflated one (:attr:`CoarseSolve.exact`), whose near null space is W^T 1 (the constant's coarse coefficients;
with it, 120 outer CG iterations against 141 under a plain V-cycle on the foreign study's dmda3d case at 64^3).
Any PETSc PC can replace it through its options.
"""
from __future__ import annotations

from petsc4py import PETSc

from . import inner, sizing


class CoarseSolve:
    """The coarse solver of a :class:`~.structure.Structure`; made at the first :meth:`setup`."""

    def __init__(self, st, solver, prefix):
        self.st, self.prefix, self.pc, self.rest = st, prefix, None, {}
        self.solver = solver if solver != "auto" else sizing.coarse_solver(st.dim, st.m, st.coll.size)
        self.chosen = solver == "auto"
        self.exact = sizing.coarse_exact(st.dim, self.solver, st.leaves.kind)   # else the balanced form (Forms)
        self.g = self.c = self.c2 = None

    def setup(self, ops):
        """Set up the solver on the new values of the coarse operator of ``ops`` (made on first use; an LU, also
        PCREDUNDANT's, takes it as BAIJ where W's columns come in equal blocks)."""
        if self.pc is None:
            st, E = self.st, ops.E
            defaults = sizing.coarse_options(st.dim, st.coll.size > 1, self.solver, st.leaves.kind, st.m, st.ordered)
            if st.col_block > 1:                      # block factors shift only within the diagonal blocks
                defaults = {k: "inblocks" if k.endswith("shift_type") else v for k, v in defaults.items()}
            self.pc, self.rest = inner.configured_pc(E.getComm(), E, self.prefix, defaults)
            if st.col_block > 1 and self.pc.getType() in ("lu", "redundant"):   # PCREDUNDANT's inner: LU
                self.pc.setOperators(ops.blocked(), ops.blocked())
            self.g, self.c, self.c2 = (E.createVecLeft() for _ in range(3))
        if inner.multigrid(self.pc):
            self._near_null(ops)
        with inner.scoped(self.prefix, self.rest):      # PCREDUNDANT's inner solver reads its defaults now
            self.pc.setUp()
            if self.pc.getType() == "redundant":         # it factors at its first apply: do that here
                self.g.set(0.0)
                self.pc.apply(self.g, self.c)

    def _near_null(self, ops):
        """E's near null space for GAMG: W^T 1, the coarse coefficients of the constant (W's columns are orthonormal
        per leaf), in place of GAMG's default, the constant vector."""
        one, z = ops.W.createVecLeft(), ops.E.createVecLeft()
        one.set(1.0)
        ops.W.multTranspose(one, z)
        z.normalize()
        nsp = PETSc.NullSpace().create(vectors=[z], comm=ops.E.getComm())
        ops.E.setNearNullSpace(nsp)
        for obj in (one, z, nsp):
            obj.destroy()

    def apply(self, g, c):
        """c = E^-1 g."""
        self.pc.apply(g, c)

    def describe(self) -> str:
        """The coarse solver, and why it was chosen."""
        why = ""
        if self.chosen:
            st = self.st
            limit = sizing.COARSE_DIRECT_MAX[st.dim]
            direct = f"direct up to {limit}"
            if st.dim == 2 and st.coll.size > 1:
                direct = f"direct up to {sizing.COARSE_REDUNDANT_MAX} on several ranks"
            why = f" (by the problem: {st.m} rows; {direct} in {st.dim}-D)"
        order = "; coarse columns in METIS's nested-dissection order of the leaf graph" if self.st.ordered else ""
        return f"coarse solve: {inner.text(self.pc)}{why}{order}; options -{self.prefix}*"

    def nnz(self) -> int:
        """Values the solver holds besides the operator."""
        return inner.held(self.pc) if self.pc is not None else 0

    def destroy(self):
        """Free the PETSc objects."""
        for name in ("pc", "g", "c", "c2"):
            obj = getattr(self, name)
            if obj is not None:
                obj.destroy()
                setattr(self, name, None)
