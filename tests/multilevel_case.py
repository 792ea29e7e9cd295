"""Run under ``mpiexec -n 2`` by tests/test_multilevel.py: HTPPC as it comes takes the V-cycles for a 2-D DMDA matrix
(40 000 rows, above MIN_ROWS), then new values change the nonzero mask on rank 0 only (one coupling set to an
explicit zero there): rank 0 sees a new pattern, rank 1 new values. Every rank must make a new analysis and take
the same method (the choice is collective: this had hung). Prints ``first <setup type> <its>`` and
``second <setup type> <its> <relres>`` on rank 0; then the matrix times 2 (a refresh of the kept hierarchy on both
ranks): ``third <setup type> <its> <relres> <age>``. Last, the same under ``-htp_ml_reorder 1`` (each rank's rows in
their leaves' order: a copy MatCreateSubMatrix makes, and makes again for the values times 2): ``reordered <its>
<relres> <age> <whether the copy is MatCreateSubMatrix's of the values>``."""
import sys
from pathlib import Path

import petsc4py

petsc4py.init(sys.argv[:1])
from petsc4py import PETSc  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
from petsc_htp.scenes.foreign import dmda  # noqa: E402
from bad_input_cases import dist, htp_ksp, rhs  # noqa: E402

A, b = dmda(2, 200, 1e3, 0)
mat = dist(A)
ksp = htp_ksp("mc_")
ksp.setOperators(mat, mat)
ksp.setFromOptions()
bv = rhs(mat, b)
x = bv.duplicate()
ksp.solve(bv, x)
PETSc.Sys.Print("first", type(ksp.getPC().getPythonContext().setup).__name__, ksp.getIterationNumber())
i = 200 * 50 + 100                                        # an interior row of rank 0's
j = i + 1
if mat.getOwnershipRange()[0] <= i < mat.getOwnershipRange()[1]:
    mat.setValues([i], [j], [0.0])
    mat.setValues([j], [i], [0.0])
mat.assemble()
x.set(0.0)
ksp.solve(bv, x)
r = bv.duplicate()
mat.mult(x, r)
r.aypx(-1.0, bv)
PETSc.Sys.Print("second", type(ksp.getPC().getPythonContext().setup).__name__, ksp.getIterationNumber(),
                f"{r.norm() / bv.norm():.1e}")
mat.scale(2.0)                                            # new values on every rank, the pattern kept: a refresh
x.set(0.0)
ksp.solve(bv, x)
mat.mult(x, r)
r.aypx(-1.0, bv)
setup = ksp.getPC().getPythonContext().setup
PETSc.Sys.Print("third", type(setup).__name__, ksp.getIterationNumber(), f"{r.norm() / bv.norm():.1e}", setup.age)
mat.scale(0.5)
ksp2 = htp_ksp("mr_")
PETSc.Options("mr_").setValue("htp_ml_reorder", 1)
ksp2.setOperators(mat, mat)
ksp2.setFromOptions()
for _ in range(2):                                        # then the matrix times 2: a refresh of the copy
    x.set(0.0)
    ksp2.solve(bv, x)
    mat.scale(2.0)
mat.scale(0.5)
mat.mult(x, r)
r.aypx(-1.0, bv)
setup = ksp2.getPC().getPythonContext().setup
fresh = mat.createSubMatrix(setup.order, setup.order)
PETSc.Sys.Print("reordered", ksp2.getIterationNumber(), f"{r.norm() / bv.norm():.1e}", setup.age,
                setup.reordered.take is None and fresh.equal(setup.P))
fresh.destroy()
