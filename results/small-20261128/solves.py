"""Single solves of small matrices (PyAMG's examples; foreign study cases at about 1 000 and 2 000 rows), a fresh Mat and
KSP each (CG to 1e-8 in the unpreconditioned norm, one thread), by HTPPC as it comes and by ICC(0) alone; prints each
case's median setup + solve ms of REPS after one warm-up, and the iterations. From the repository root:
  python results/small-20261128/solves.py REPS CASE...      (CASE: pyamg_<name>, or <foreign case>_<N>)"""
import statistics
import sys
import time

import petsc4py

petsc4py.init(sys.argv[:1])
from petsc4py import PETSc  # noqa: E402

import petsc_htp  # noqa: E402
from petsc_htp.bench.foreigncases import CASES, pyamg_cases  # noqa: E402


def case(name):
    if name.startswith("pyamg_"):
        return pyamg_cases()[name]
    family, n = name.rsplit("_", 1)
    return CASES[family](int(n), 0)


def run(A, b, pc_type, reps):
    times, its = [], 0
    for _ in range(reps + 1):
        A = A.tocsr()
        mat = PETSc.Mat().createAIJ(A.shape, csr=(A.indptr.astype(PETSc.IntType), A.indices.astype(PETSc.IntType),
                                                  A.data), comm=PETSc.COMM_SELF)
        x, rhs = mat.createVecs()
        rhs.setArray(b)
        t0 = time.perf_counter()
        ksp = PETSc.KSP().create(PETSc.COMM_SELF)
        ksp.setOperators(mat)
        ksp.setType("cg")
        ksp.setTolerances(rtol=1e-8)
        ksp.setNormType(PETSc.KSP.NormType.UNPRECONDITIONED)
        if pc_type == "htp":
            ksp.getPC().setType("python")
            ksp.getPC().setPythonContext(petsc_htp.HTPPC())
        else:
            ksp.getPC().setType(pc_type)
        ksp.setUp()
        ksp.solve(rhs, x)
        times.append(1e3 * (time.perf_counter() - t0))
        its = ksp.getIterationNumber()
        ksp.destroy()
        mat.destroy()
    return statistics.median(times[1:]), its


reps = int(sys.argv[1])
for name in sys.argv[2:]:
    A, b = case(name)
    (htp, its), (icc, icc_its) = run(A, b, "htp", reps), run(A, b, "icc", reps)
    print(f"{name} {A.shape[0]} rows: HTPPC {htp:.2f} ms ({its}), ICC(0) {icc:.2f} ms ({icc_its})")
