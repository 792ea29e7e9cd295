"""What a matrix numbered at random costs: the foreign study's 2-D matrices at about 64k rows in their program's
order (grid rows) and symmetrically permuted at random, each solved once from zero (setup + solve ms, CG to rtol
1e-8 on the true residual, one thread) by HTPPC as it comes, GAMG tuned (options/cg_gamg.opts) and AMGCL at its
default coarse size; natural and permuted runs and the methods take turns, REPEATS rounds, medians printed.

    OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 python results/numbering-20261126/run.py [REPEATS] \
        > results/numbering-20261126/out.txt
"""
import subprocess
import sys
import time
from pathlib import Path

import petsc4py

petsc4py.init(["numbering"])
import numpy as np  # noqa: E402
import scipy.sparse as sp  # noqa: E402
from petsc4py import PETSc  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))
from petsc_htp.bench import external  # noqa: E402
from petsc_htp.bench.foreigncases import CASES  # noqa: E402
from petsc_htp.bench.studies.foreign import bare_frame  # noqa: E402
from petsc_htp.petscmat import frame_mat, frame_vec  # noqa: E402

OPTIONS = {"htppc": {"pc_type": "python", "pc_python_type": "petsc_htp.HTPPC"},
           "gamg": {"pc_type": "gamg", "pc_gamg_type": "agg", "pc_gamg_agg_nsmooths": 1, "pc_gamg_threshold": 0.02,
                    "pc_gamg_aggressive_coarsening": 1, "mg_levels_ksp_type": "chebyshev",
                    "mg_levels_pc_type": "jacobi", "mg_levels_ksp_max_it": 3}}


def petsc_solve(method, A, b, case):
    """Setup + solve ms and iterations of one fresh KSP (the method's options under its own prefix)."""
    frame = bare_frame(A, b, case)
    mat = frame_mat(frame, PETSc.COMM_SELF)
    rhs = frame_vec(frame, mat)
    db = PETSc.Options(method + "_")
    for k, v in {"ksp_type": "cg", "ksp_rtol": 1e-8, "ksp_norm_type": "unpreconditioned", **OPTIONS[method]}.items():
        db.setValue(k, v)
    ksp = PETSc.KSP().create(PETSc.COMM_SELF)
    ksp.setOptionsPrefix(method + "_")
    ksp.setOperators(mat, mat)
    ksp.setFromOptions()
    x = rhs.duplicate()
    x.set(0.0)
    t = time.perf_counter()
    ksp.setUp()
    ksp.solve(rhs, x)
    ms = 1e3 * (time.perf_counter() - t)
    assert ksp.getConvergedReason() > 0, (method, case, ksp.getConvergedReason())
    its = ksp.getIterationNumber()
    ksp.destroy()
    mat.destroy()
    return ms, its


def solve(method, A, b, case):
    if method == "amgcl":
        out = external.solve("amgcl", A, b, 1e-8, 1000)
        return out["setup_ms"] + out["solve_ms"], out["iterations"]
    return petsc_solve(method, A, b, case)


def main():
    reps = int(sys.argv[1]) if len(sys.argv) > 1 else 3
    commit = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "--short", "HEAD"], capture_output=True, text=True)
    print(f"# {time.strftime('%Y-%m-%d')}, commit {commit.stdout.strip()}, setup + solve ms (iterations), median of "
          f"{reps}")
    for case in ("dmda2d", "free_surface", "lognormal"):
        A, b = CASES[case](65536, 0)
        p = np.random.default_rng(0).permutation(A.shape[0])
        Ap = sp.csr_matrix(A[p][:, p])
        Ap.sort_indices()
        orders = {"natural": (A, b), "random": (Ap, b[p])}
        for method in ("htppc", "gamg", "amgcl"):
            solve(method, A, b, case)                                   # warm-up
        out = {}
        for _ in range(reps):
            for order, (M, rhs) in orders.items():
                for method in ("htppc", "gamg", "amgcl"):
                    out.setdefault((order, method), []).append(solve(method, M, rhs, case))
        for method in ("htppc", "gamg", "amgcl"):
            nat, rnd = (np.median([ms for ms, _ in out[(o, method)]]) for o in orders)
            print(f"{case} N={A.shape[0]} {method}: natural {nat:.1f} ({out[('natural', method)][-1][1]}) "
                  f"random {rnd:.1f} ({out[('random', method)][-1][1]}) ratio {rnd / nat:.2f}", flush=True)


main()
