"""A dense row: the foreign study's DMDA-style matrix (side^2 rows, coefficient jumps 1e3) bordered by one row and
column coupled to every row (v_i in -0.5 .. 0, the DMDA rows' diagonals raised by |v_i|, the new diagonal sum |v| +
1: SPD). One solve from zero each (CG to rtol 1e-8 on the true residual, one thread, fresh KSP, setup included),
after one warm-up: HTPPC as it comes, and PETSc's ICC(0). Prints "N method: setup ms, solve ms, iterations".

    OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 python results/denserow-20261126/run.py SIDE [SIDE ...] [--no-icc]

(``PYTHONPATH`` set to another checkout runs its code: the script reads ``petsc_htp`` from there.)
"""
import subprocess
import sys
import time

import petsc4py

petsc4py.init(["denserow"])
import numpy as np  # noqa: E402
import scipy.sparse as sp  # noqa: E402
from petsc4py import PETSc  # noqa: E402

import petsc_htp  # noqa: E402
from petsc_htp.scenes import foreign  # noqa: E402


def arrow(side) -> tuple:
    """(A, b): the bordered DMDA matrix and a random right-hand side."""
    K = foreign.dmda(2, side, 1e3, 0)[0].tocsr()
    v = -0.5 * np.random.default_rng(0).random(K.shape[0])
    A = sp.bmat([[K + sp.diags(np.abs(v)), v[:, None]], [v[None, :], np.array([[np.abs(v).sum() + 1.0]])]]).tocsr()
    A.sort_indices()
    return A, np.random.default_rng(1).standard_normal(A.shape[0])


def solve(mat, b, pc):
    """(setup ms, solve ms, iterations) of one fresh KSP with HTPPC (``pc`` 'htppc') or PETSc's PC ``pc``."""
    ksp = PETSc.KSP().create(PETSc.COMM_SELF)
    ksp.setOperators(mat, mat)
    ksp.setType("cg")
    ksp.setTolerances(rtol=1e-8)
    ksp.setNormType(PETSc.KSP.NormType.UNPRECONDITIONED)
    if pc == "htppc":
        ksp.getPC().setType("python")
        ksp.getPC().setPythonContext(petsc_htp.HTPPC())
    else:
        ksp.getPC().setType(pc)
    rhs = mat.createVecLeft()
    rhs.array[:] = b
    x = rhs.duplicate()
    t = time.perf_counter()
    ksp.setUp()
    t1 = time.perf_counter()
    ksp.solve(rhs, x)
    out = 1e3 * (t1 - t), 1e3 * (time.perf_counter() - t1), ksp.getIterationNumber(), ksp.getConvergedReason()
    ksp.destroy()
    return out


def main():
    sides = [int(a) for a in sys.argv[1:] if not a.startswith("--")]
    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=petsc_htp.__path__[0], capture_output=True,
                            text=True).stdout.strip()
    print(f"# {time.strftime('%Y-%m-%d')}, petsc_htp of commit {commit}; setup ms, solve ms, iterations")
    for side in sides:
        A, b = arrow(side)
        mat = PETSc.Mat().createAIJ(A.shape, csr=(A.indptr.astype(PETSc.IntType), A.indices.astype(PETSc.IntType),
                                                  A.data), comm=PETSc.COMM_SELF)
        mat.setOption(PETSc.Mat.Option.SYMMETRIC, True)
        for pc in ("htppc",) + (() if "--no-icc" in sys.argv else ("icc",)):
            solve(mat, b, pc)
            setup, solve_ms, its, reason = solve(mat, b, pc)
            print(f"{A.shape[0]} {pc}: {setup:.1f}, {solve_ms:.1f}, {its}{'' if reason > 0 else f' (reason {reason})'}",
                  flush=True)
        mat.destroy()


if __name__ == "__main__":
    main()
