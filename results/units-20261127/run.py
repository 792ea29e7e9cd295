"""Matrices in other units: the foreign study's matrices times s (1, 1e-12, 1e-20) and scaled to a unit diagonal,
(D A D, D = |diag A|^-1/2, right-hand side D b: the same system in other unknowns), solved once each by CG + HTPPC (as it comes) and CG + GAMG (PETSc's defaults), fresh Mat and KSP, rtol 1e-8 in
the unpreconditioned norm; setup + solve ms and iterations, the true relative residual. Runs on any number of
ranks (PETSc's row split); every rank builds the whole matrix.

    OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 [mpiexec -n 2] python results/units-20261127/run.py [N] [case ...]
"""
import sys
import time

import petsc4py

petsc4py.init(sys.argv[:1])
import numpy as np  # noqa: E402
import scipy.sparse as sp  # noqa: E402
from petsc4py import PETSc  # noqa: E402

import petsc_htp  # noqa: E402
from petsc_htp.bench.foreigncases import CASES  # noqa: E402

COMM = PETSc.COMM_WORLD
METHODS = {"htppc": {"pc_type": "python", "pc_python_type": "petsc_htp.HTPPC"}, "gamg": {"pc_type": "gamg"}}


def mat(A):
    """A distributed AIJ copy of scipy ``A`` (PETSc's row split), MAT_SYMMETRIC set."""
    M = PETSc.Mat().create(COMM)
    M.setSizes(((PETSc.DECIDE, A.shape[0]), (PETSc.DECIDE, A.shape[0])))
    M.setType("aij")
    lo, hi = M.getOwnershipRange()
    local = A[lo:hi]
    M.setPreallocationCSR((local.indptr, local.indices))
    M.setValuesCSR(local.indptr, local.indices, local.data)
    M.assemble()
    M.setOption(PETSc.Mat.Option.SYMMETRIC, True)
    return M


def solve(A, b, method):
    """(ms, iterations, true relative residual, PETSc's reason) of one solve from a fresh Mat and KSP."""
    M = mat(A)
    db = PETSc.Options("u_")
    for k, v in {"ksp_type": "cg", "ksp_norm_type": "unpreconditioned", "ksp_rtol": 1e-8, "ksp_max_it": 2000,
                 **METHODS[method]}.items():
        db[k] = v
    ksp = PETSc.KSP().create(COMM)
    ksp.setOptionsPrefix("u_")
    ksp.setOperators(M)
    ksp.setFromOptions()
    x, rhs = M.createVecs()
    lo, hi = rhs.getOwnershipRange()
    rhs.array[:] = b[lo:hi]
    COMM.barrier()
    t = time.perf_counter()
    ksp.solve(rhs, x)
    ms = 1e3 * (time.perf_counter() - t)
    r = rhs.duplicate()
    M.mult(x, r)
    r.aypx(-1.0, rhs)
    out = ms, ksp.getIterationNumber(), r.norm() / rhs.norm(), ksp.getConvergedReason()
    for obj in (ksp, M, x, rhs, r):
        obj.destroy()
    for k in list(db.getAll()):
        db.delValue(k)
    return out


def table(variants, default_cases):
    """One line per case of the command line's (N, then case names; default 65536 and ``default_cases``) and method:
    ms (iterations) [true relres] of each of ``variants(A, b)``'s {name: (matrix, rhs)} after a warm-up solve."""
    n = int(sys.argv[1]) if len(sys.argv) > 1 else 65536
    cases = sys.argv[2:] or default_cases
    PETSc.Sys.Print(f"# {COMM.getSize()} rank(s), N about {n}; ms (iterations) [true relres], PETSc's reason where not "
                    f"converged; petsc_htp {petsc_htp.__file__}", comm=COMM)
    for case in cases:
        A, b = CASES[case](n, 0)[:2]
        A = sp.csr_matrix(A)
        for method in METHODS:
            solve(A, b, method)                                   # warm-up
            cells = []
            for name, (M, rhs) in variants(A, b).items():
                ms, its, rel, reason = solve(M, rhs, method)
                cells.append(f"{name}: {ms:.0f} ({its}) [{rel:.1e}]" + ("" if reason > 0 else f" reason {reason}"))
            PETSc.Sys.Print(f"{case} {A.shape[0]} {method}: " + "; ".join(cells), comm=COMM)


def units(A, b):
    """A in other units and at a unit diagonal."""
    d = np.abs(A.diagonal())
    D = sp.diags(1 / np.sqrt(np.where(d > 0, d, 1)))
    return {"A": (A, b), "1e-12 A": (1e-12 * A, b), "1e-20 A": (1e-20 * A, b),
            "unit diagonal": ((D @ A @ D).tocsr(), D @ b)}


if __name__ == "__main__":
    table(units, ["dmda2d", "dmda3d", "free_surface", "fem_tet", "lognormal", "neumann"])
