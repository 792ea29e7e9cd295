"""A foreign study case's frame 0 (a fresh KSP: analysis included) and FRAMES more with new values of the pattern on
the same KSP, HTPPC under the options given after the case (CG to 1e-8 in the unpreconditioned norm, one thread);
prints the package's root, frame 0's setup + solve ms and iterations, and the later frames' median. From the
repository root:  python results/bound-20261128/frames.py N FRAMES CASE [PETSc options]"""
import statistics
import sys

import petsc4py

petsc4py.init([sys.argv[0]] + sys.argv[4:])
from petsc4py import PETSc  # noqa: E402

import petsc_htp  # noqa: E402
from petsc_htp.bench.foreigncases import CASES  # noqa: E402
from petsc_htp.onesolve import timed_solve  # noqa: E402

n, frames, case = int(sys.argv[1]), int(sys.argv[2]), sys.argv[3]
db = PETSc.Options()
for k, v in {"ksp_type": "cg", "ksp_norm_type": "unpreconditioned", "ksp_rtol": 1e-8, "pc_type": "python",
             "pc_python_type": "petsc_htp.HTPPC"}.items():
    db[k] = v


def csr(A):
    A = A.tocsr()
    A.sort_indices()
    return A.indptr.astype(PETSc.IntType), A.indices.astype(PETSc.IntType), A.data


A, b = CASES[case](n, 0)
mat = PETSc.Mat().createAIJ(A.shape, csr=csr(A))
rhs = mat.createVecLeft()
rhs.array[:] = b
x = rhs.duplicate()
ksp = PETSc.KSP().create()
ksp.setOperators(mat, mat)
ksp.setFromOptions()
out = []
for k in range(frames + 1):
    if k:
        mat.setValuesCSR(*csr(CASES[case](n, k)[0]))
        mat.assemble()
    x.set(0.0)
    its, reason, setup, solve, relres = timed_solve(ksp, rhs, x)
    out.append((setup, solve, its))
later = out[1:]
print(f"{petsc_htp.__file__.rsplit('/', 2)[0].rsplit('/', 1)[-1]}: frame 0 {out[0][0]:.0f} + {out[0][1]:.0f} ms "
      f"({out[0][2]}); later frames median {statistics.median(s for s, _, _ in later):.0f} + "
      f"{statistics.median(v for _, v, _ in later):.0f} ms ({[i for _, _, i in later]})")
