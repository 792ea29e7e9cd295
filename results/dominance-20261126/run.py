"""Diagonally dominant matrices, one solve from zero each (CG to rtol 1e-8 on the true residual, one thread, fresh
KSP, setup included): A = K + c diag(sum_j |k_ij|, j != i) for the foreign study's matrices K (a mass matrix plus a
time step's stiffness has this shape), every coupled row dominant by the margin c. HTPPC as it comes (ICC(0) of the
whole matrix from c = dominance.MARGIN), its two-level method (-htp_direct_max 0, what it did before), PETSc's
ICC(0), Jacobi and GAMG (options/cg_gamg.opts' settings). Median of 3 solves per method after one warm-up, methods
interleaved. Prints "case N c method: ms iterations".

    OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 python results/dominance-20261126/run.py [N [CASE ...]] \\
        >> results/dominance-20261126/out.txt

(N 65 536 and every case below by default; GAMG is left out above 300 000 rows.)
"""
import statistics
import subprocess
import sys
import time
from pathlib import Path

import petsc4py

petsc4py.init(["dominance"])
import numpy as np  # noqa: E402
import scipy.sparse as sp  # noqa: E402
from petsc4py import PETSc  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))
from petsc_htp.bench.foreigncases import CASES  # noqa: E402

METHODS = {"htppc": {"pc_type": "python", "pc_python_type": "petsc_htp.HTPPC"},
           "two-level": {"pc_type": "python", "pc_python_type": "petsc_htp.HTPPC", "htp_direct_max": "0"},
           "icc": {"pc_type": "icc"},
           "jacobi": {"pc_type": "jacobi"},
           "gamg": {"pc_type": "gamg", "pc_gamg_threshold": "0.02", "pc_gamg_aggressive_coarsening": "0"}}
_count = iter(range(10 ** 6))


def dominant(K, c) -> sp.csr_matrix:
    """K + c diag(sum_j |k_ij|, j != i), K's pattern kept."""
    off = np.asarray(abs(K).sum(axis=1)).ravel() - np.abs(K.diagonal())
    A = sp.csr_matrix(K, copy=True)
    A.setdiag(K.diagonal() + c * off)
    return A


def solve(mat, b, opts):
    """(ms, iterations) of one fresh KSP with ``opts`` under a prefix of its own."""
    prefix = f"m{next(_count)}_"
    db = PETSc.Options(prefix)
    for k, v in {"ksp_type": "cg", "ksp_rtol": "1e-8", "ksp_norm_type": "unpreconditioned", **opts}.items():
        db.setValue(k, v)
    ksp = PETSc.KSP().create(PETSc.COMM_SELF)
    ksp.setOptionsPrefix(prefix)
    ksp.setOperators(mat, mat)
    ksp.setFromOptions()
    rhs = mat.createVecLeft()
    rhs.array[:] = b
    x = rhs.duplicate()
    t = time.perf_counter()
    ksp.solve(rhs, x)
    ms = 1e3 * (time.perf_counter() - t)
    its, reason = ksp.getIterationNumber(), ksp.getConvergedReason()
    ksp.destroy()
    return (ms if reason > 0 else float("nan")), its


def main():
    n = int(sys.argv[1]) if len(sys.argv) > 1 else 65536
    cases = sys.argv[2:] or ["dmda2d", "dmda3d", "free_surface", "lognormal", "fem_tri", "fem_tet"]
    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, capture_output=True,
                            text=True).stdout.strip()
    print(f"# {time.strftime('%Y-%m-%d')}, commit {commit}; median ms of 3 (iterations)")
    for case in cases:
        K = CASES[case](n, 0)[0].tocsr()
        b = np.random.default_rng(1).standard_normal(K.shape[0])
        for c in (0.001, 0.003, 0.01, 0.1):
            A = dominant(K, c)
            mat = PETSc.Mat().createAIJ(A.shape, csr=(A.indptr.astype(PETSc.IntType),
                                                      A.indices.astype(PETSc.IntType), A.data),
                                        comm=PETSc.COMM_SELF)
            mat.setOption(PETSc.Mat.Option.SYMMETRIC, True)
            runs = {m: [] for m in METHODS}
            for rnd in range(4):
                for m, opts in METHODS.items():
                    if m == "gamg" and K.shape[0] > 300000:
                        continue
                    ms, its = solve(mat, b, opts)
                    if rnd:
                        runs[m].append((ms, its))
            for m, r in runs.items():
                if r:
                    print(f"{case} {K.shape[0]} {c} {m}: {statistics.median(x[0] for x in r):.1f} "
                          f"({r[0][1]})", flush=True)
            mat.destroy()


if __name__ == "__main__":
    main()
