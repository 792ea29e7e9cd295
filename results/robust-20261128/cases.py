"""Matrices that had defeated HTPPC's V-cycles, single solves (CG to 1e-8 in the unpreconditioned norm, one thread),
HTPPC as it comes (the V-cycles at these sizes). From the repository root:
  python results/robust-20261128/cases.py make DIR        (this tree's generators: DIR/CASE.npz)
  python results/robust-20261128/cases.py solve DIR/CASE.npz [name=value ...]   (the package on PYTHONPATH)
CASE: pockets16 / pockets100 (:func:`petsc_htp.scenes.foreign.pockets`, 256^2 cells, 16 / 100 sealed 3x3 pockets,
handed over bare), dmda2d (the foreign study's at 40 000 rows), scaled1e200 / scaled1e-200 (it times 1e200 / 1e-200).
``solve`` prints the iterations, PETSc's reason and the true relative residual."""
import sys
from pathlib import Path

import numpy as np
import scipy.sparse as sp
import petsc4py

petsc4py.init(sys.argv[:1])
from petsc4py import PETSc  # noqa: E402

if sys.argv[1] == "make":
    from petsc_htp.bench.foreigncases import CASES
    from petsc_htp.scenes.foreign import pockets

    out = Path(sys.argv[2])
    A, b = CASES["dmda2d"](40000, 0)
    cases = {"pockets16": pockets(256, 60), "pockets100": pockets(256, 24), "dmda2d": (A, b),
             "scaled1e200": (A * 1e200, b), "scaled1e-200": (A * 1e-200, b)}
    for name, (A, b) in cases.items():
        A = sp.csr_matrix(A)
        A.sort_indices()
        np.savez(out / f"{name}.npz", data=A.data, indices=A.indices, indptr=A.indptr, b=b)
    sys.exit(0)

from petsc_htp.onesolve import solve_once  # noqa: E402

db = PETSc.Options()
for name, value in [("ksp_type", "cg"), ("ksp_norm_type", "unpreconditioned"), ("ksp_rtol", "1e-8"),
                    ("ksp_max_it", "1000"), ("pc_type", "python"), ("pc_python_type", "petsc_htp.HTPPC")] + \
        [arg.split("=") for arg in sys.argv[3:]]:
    db[name] = value
f = np.load(sys.argv[2])
n = f["indptr"].size - 1
mat = PETSc.Mat().createAIJ((n, n), csr=(f["indptr"], f["indices"], f["data"]))
mat.setOption(PETSc.Mat.Option.SYMMETRIC, True)
rhs = mat.createVecLeft()
rhs.array[:] = f["b"]
its, reason, setup, solve, relres = solve_once(mat, rhs)
print(f"{Path(sys.argv[2]).stem}: {its} iterations, reason {reason}, true relres {relres:.1e}")
