"""The project's own held-out frames at N in sequence mode (one persistent Mat and KSP, HTPPC as it comes, CG to 1e-8
in the unpreconditioned norm, one thread): prints the package's root, then the median over frames 2-11 of the frame's
setup + solve ms, of the solve ms, and the mean iterations, then the least of 10 solves of the last frame again (its
preconditioner as it is: no setup); and, with ``micro``, the microseconds of one g = C^T v by
MatMultTranspose of C and by MatMult of the C^T the numeric step keeps (the two-level method's operators after the
last frame). From the repository root:  python results/ctrans-20261129/frames.py N [micro]"""
import sys
import time

import petsc4py

petsc4py.init(sys.argv[:1])
import numpy as np  # noqa: E402
from petsc4py import PETSc  # noqa: E402
from scipy.sparse.csgraph import connected_components  # noqa: E402

import petsc_htp  # noqa: E402
from petsc_htp.scenes.dataset import load_dataset  # noqa: E402
from petsc_htp.sim.simulation import PressureSolver  # noqa: E402

n = int(sys.argv[1])
frames = load_dataset(n, "test")[:12]
db = PETSc.Options()
for k, v in {"ksp_type": "cg", "ksp_norm_type": "unpreconditioned", "ksp_rtol": 1e-8, "pc_type": "python",
             "pc_python_type": "petsc_htp.HTPPC"}.items():
    db[k] = v
solver = PressureSolver(frames[0].A, connected_components(frames[0].A, directed=False)[1], "", warm=False)
out = [solver.solve(f.A, f.b, f.coords, f.rho, rebuild=True) for f in frames]
later = out[2:]
print(f"{petsc_htp.__file__.rsplit('/', 2)[0].rsplit('/', 1)[-1]}: frame "
      f"{np.median([o['setup_ms'] + o['solve_ms'] for o in later]):.1f} ms, solve "
      f"{np.median([o['solve_ms'] for o in later]):.1f} ms, {np.mean([o['its'] for o in later]):.1f} iterations")
A = solver.ksp.getOperators()[0]
rhs, x = A.createVecLeft(), A.createVecRight()
rhs.array[:] = frames[-1].b
if A.getNullSpace().handle:
    A.getNullSpace().remove(rhs)
again = []
for _ in range(10):
    x.set(0.0)
    t0 = time.perf_counter()
    solver.ksp.solve(rhs, x)
    again.append(1e3 * (time.perf_counter() - t0))
print(f"  the last frame solved again: least of 10 {min(again):.2f} ms ({solver.ksp.getIterationNumber()} iterations)")
if sys.argv[2:] == ["micro"]:
    ops = solver.ksp.getPC().getPythonContext().setup.forms.ops
    v, g = ops.C.createVecs()[1], ops.C.createVecs()[0]
    v.setRandom()

    def us(f, reps=300):
        """Microseconds of one call of ``f`` (after 20 warm-up calls)."""
        for _ in range(20):
            f()
        t0 = time.perf_counter()
        for _ in range(reps):
            f()
        return 1e6 * (time.perf_counter() - t0) / reps

    print(f"C^T v: MatMultTranspose of C {us(lambda: ops.C.multTranspose(v, g)):.1f} us, MatMult of C^T "
          f"{us(lambda: ops.CT.mult(v, g)):.1f} us ({ops.C.getSize()[0]} x {ops.C.getSize()[1]}, "
          f"{int(ops.C.getInfo()['nz_used'])} entries)")
