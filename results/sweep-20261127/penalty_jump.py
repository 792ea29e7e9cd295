"""A penalty's Dirichlet rows beside a coefficient jump (a new user's sweep, 2026-11-27): P1 triangles on a jittered
m x m grid (scipy's Delaunay), a checkerboard of conductivities 1 and 1e4 (8 x 8 squares), the boundary nodes held
by a penalty a_ii + 1e10, or zeroed as MatZeroRowsColumns does (diagonal 1); CG to rtol 1e-8 in the unpreconditioned
norm with HTPPC as it comes or PETSc's GAMG at its defaults, a fresh KSP, random b. Prints setup + solve ms,
iterations, the true relative residual and HTPPC's -ksp_view line on the pieces' vectors, after a warm-up solve
of each method at each size.

    OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 [mpiexec -n 2] python results/sweep-20261127/penalty_jump.py [m ...]
"""
import sys
import time

import petsc4py

petsc4py.init(sys.argv[:1])
import numpy as np  # noqa: E402
import scipy.sparse as sp  # noqa: E402
from petsc4py import PETSc  # noqa: E402
from scipy.spatial import Delaunay  # noqa: E402

import petsc_htp  # noqa: E402

COMM = PETSc.COMM_WORLD


def stiffness(m):
    """(K, boundary nodes): the P1 Laplacian of the checkerboard on an m x m jittered grid."""
    g = np.linspace(0, 1, m)
    pts = np.stack(np.meshgrid(g, g), -1).reshape(-1, 2)
    inner = np.all((pts > 0) & (pts < 1), axis=1)
    pts[inner] += np.random.default_rng(0).uniform(-0.3, 0.3, (inner.sum(), 2)) / (m - 1)
    tri = Delaunay(pts).simplices
    T = np.stack([pts[tri[:, 1]] - pts[tri[:, 0]], pts[tri[:, 2]] - pts[tri[:, 0]]], axis=1)
    Ti = np.linalg.inv(T)
    G = np.concatenate([-Ti.sum(axis=1, keepdims=True), Ti], axis=1)
    c = pts[tri].mean(axis=1)
    kappa = np.where(((c[:, 0] * 8).astype(int) + (c[:, 1] * 8).astype(int)) % 2 == 0, 1e4, 1.0)
    K = np.einsum("eik,ejk->eij", G, G) * (np.abs(np.linalg.det(T)) / 2 * kappa)[:, None, None]
    n = len(pts)
    S = sp.csr_matrix((K.ravel(), (np.repeat(tri, 3, axis=1).ravel(), np.tile(tri, (1, 3)).ravel())), shape=(n, n))
    S.sum_duplicates()
    return S, np.flatnonzero(~inner)


def run(S, bnd, bc, pc):
    """(ms, iterations, true relres, the pieces' line of -ksp_view) of one solve."""
    n = S.shape[0]
    if bc == "penalty":
        S = (S + sp.csr_matrix((np.full(len(bnd), 1e10), (bnd, bnd)), shape=(n, n))).tocsr()
    A = PETSc.Mat().createAIJ((n, n), comm=COMM)
    A.setPreallocationNNZ(20)
    lo, hi = A.getOwnershipRange()
    local = S[lo:hi]
    A.setValuesCSR(local.indptr, local.indices, local.data)
    A.assemble()
    if bc == "zeroed":
        A.zeroRowsColumns(bnd[(bnd >= lo) & (bnd < hi)].astype(PETSc.IntType), diag=1.0)
    b = A.createVecLeft()
    b.setArray(np.random.default_rng(1).standard_normal(n)[lo:hi])
    x = A.createVecRight()
    ksp = PETSc.KSP().create(COMM)
    ksp.setOperators(A)
    ksp.setType("cg")
    ksp.setNormType(PETSc.KSP.NormType.UNPRECONDITIONED)
    ksp.setTolerances(rtol=1e-8, max_it=5000)
    if pc == "htp":
        ksp.getPC().setType("python")
        ksp.getPC().setPythonContext(petsc_htp.HTPPC())
    else:
        ksp.getPC().setType(pc)
    COMM.barrier()
    t = time.perf_counter()
    ksp.solve(b, x)
    ms = 1e3 * (time.perf_counter() - t)
    r = b.duplicate()
    A.mult(x, r)
    r.aypx(-1.0, b)
    line = ""
    if pc == "htp":
        setup = ksp.getPC().getPythonContext().setup
        line = next((s.strip() for s in getattr(setup, "describe", lambda: [])() if "coarse:" in s), "")
        line = line[line.find("global size"):] if "global size" in line else line
    out = ms, ksp.getIterationNumber(), r.norm() / b.norm(), line
    for obj in (ksp, A, b, x, r):
        obj.destroy()
    return out


if __name__ == "__main__":
    PETSc.Sys.Print(f"# {COMM.getSize()} rank(s); ms (iterations) [true relres]; petsc_htp {petsc_htp.__file__}")
    for m in map(int, sys.argv[1:] or ["200", "400"]):
        S, bnd = stiffness(m)
        for pc in ("htp", "gamg"):
            run(S, bnd, "penalty", pc)                            # warm-up at this size
        for bc in ("penalty", "zeroed"):
            for pc in ("htp", "gamg"):
                ms, its, rel, line = run(S, bnd, bc, pc)
                PETSc.Sys.Print(f"{m * m} rows, {bc}, {pc}: {ms:.0f} ({its}) [{rel:.1e}] {line}")
