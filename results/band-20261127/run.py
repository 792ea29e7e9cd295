"""Small and mid-sized matrices, strips and chains: HTPPC as it comes (one banded Cholesky factor, LAPACK's, in
reverse Cuthill-McKee order where the bandwidth is at most sizing.BAND_WIDTH, one rank), HTPPC's two-level method
(-htp_direct_max 0), PETSc's sparse Cholesky in nested-dissection order and ICC(0), CG to rtol 1e-8 in the
unpreconditioned norm, one thread. Single solves: a fresh Mat and KSP each, setup + solve ms, median of 5 after a
warm-up solve (iterations). Sequence mode (``mid``): frames 1-5 of the case's values on one Mat and KSP, median ms
per frame of frames 2-5 (iterations). $HTP_SRC: a checkout whose petsc_htp is measured instead of the installed one
(the code before, a git worktree).

    OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 [HTP_SRC=/tmp/old] [METHODS=htppc,cholesky] \\
        python results/band-20261127/run.py small|mid|strips [N ...]
"""
import os
import sys
import time

if os.environ.get("HTP_SRC"):
    sys.meta_path[:] = [f for f in sys.meta_path if "editable" not in type(f).__name__.lower()
                        and "editable" not in getattr(f, "__module__", "")]
    sys.path.insert(0, os.environ["HTP_SRC"])

import petsc4py  # noqa: E402

petsc4py.init(sys.argv[:1])
import numpy as np  # noqa: E402
import scipy.sparse as sp  # noqa: E402
from petsc4py import PETSc  # noqa: E402

import petsc_htp  # noqa: E402
from petsc_htp.bench.foreigncases import CASES, pyamg_cases  # noqa: E402

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "units-20261127"))
import run as units  # noqa: E402

HTPPC = {"pc_type": "python", "pc_python_type": "petsc_htp.HTPPC"}
units.METHODS.clear()
units.METHODS.update({"htppc": HTPPC, "two-level": {**HTPPC, "htp_direct_max": 0},
                      "cholesky": {"pc_type": "cholesky", "pc_factor_mat_ordering_type": "nd"},
                      "icc": {"pc_type": "icc"}})
if os.environ.get("METHODS"):
    for name in [m for m in list(units.METHODS) if m not in os.environ["METHODS"].split(",")]:
        del units.METHODS[name]
SMALL = ["dmda2d", "dmda3d", "free_surface", "aniso_e0.01_a30", "fem_tri", "fem_tet", "lognormal", "neumann"]
MID = ["dmda2d", "free_surface", "lognormal", "neumann"]


def line(n):
    """The 1-D Laplacian of n rows (Dirichlet ends)."""
    return sp.diags([-np.ones(n - 1), 2.0 * np.ones(n), -np.ones(n - 1)], [-1, 0, 1])


STRIPS = {"strip8": lambda n: sp.kronsum(line(8), line(n // 8)).tocsr(),
          "strip16": lambda n: sp.kronsum(line(16), line(n // 16)).tocsr(),
          "strip64": lambda n: sp.kronsum(line(64), line(n // 64)).tocsr(),
          "chain": lambda n: line(n).tocsr()}


def single(A, b):
    """'ms (its)' of each method: median of 5 single solves after a warm-up."""
    cells = []
    for method in units.METHODS:
        units.solve(A, b, method)
        ms, its, rel, reason = sorted(units.solve(A, b, method) for _ in range(5))[2]
        cells.append(f"{method} {ms:.2f} ({its})" + ("" if reason > 0 and rel <= 1.01e-8 else f" [{rel:.1e} {reason}]"))
    return "; ".join(cells)


def sequence(case, n, method):
    """Median ms per frame (iterations) of frames 2-5 of ``case`` on one Mat and KSP."""
    db = PETSc.Options("q_")
    for k, v in {"ksp_type": "cg", "ksp_norm_type": "unpreconditioned", "ksp_rtol": 1e-8, "ksp_max_it": 2000,
                 **units.METHODS[method]}.items():
        db[k] = v
    M = units.mat(sp.csr_matrix(CASES[case](n, 0)[0]))
    ksp = PETSc.KSP().create()
    ksp.setOptionsPrefix("q_")
    ksp.setOperators(M)
    ksp.setFromOptions()
    ms, its = [], []
    for k in range(1, 6):
        A, b = CASES[case](n, k)[:2]
        A = sp.csr_matrix(A)
        M.setValuesCSR(A.indptr, A.indices, A.data)
        M.assemble()
        ksp.setOperators(M)
        x, r = M.createVecs()
        r.array[:] = b
        t = time.perf_counter()
        ksp.solve(r, x)
        ms.append(1e3 * (time.perf_counter() - t))
        its.append(ksp.getIterationNumber())
    for k in list(db.getAll()):
        db.delValue(k)
    ksp.destroy()
    M.destroy()
    return f"{method} {np.median(ms[1:]):.1f} ({int(np.median(its[1:]))})"


def main():
    mode, sizes = sys.argv[1], [int(v) for v in sys.argv[2:]]
    print(f"# {mode}; petsc_htp {petsc_htp.__file__}; methods {list(units.METHODS)}", flush=True)
    if mode == "small":
        for name, (A, b) in pyamg_cases().items():
            print(f"{name} {A.shape[0]}: {single(sp.csr_matrix(A), b)}", flush=True)
    for n in sizes:
        if mode == "strips":
            for name, make in STRIPS.items():
                A = make(n)
                print(f"{name} {A.shape[0]}: {single(A, np.ones(A.shape[0]))}", flush=True)
            continue
        for case in (SMALL if mode == "small" else MID):
            A, b = CASES[case](n, 0)[:2]
            A = sp.csr_matrix(A)
            print(f"{case} {A.shape[0]}: {single(A, b)}", flush=True)
            if mode == "mid" and case != "free_surface":            # a new pattern every frame: single solves
                print(f"{case} {A.shape[0]} seq: " + "; ".join(sequence(case, n, m) for m in units.METHODS),
                      flush=True)


if __name__ == "__main__":
    main()
