"""Every KSP PETSc has, from a fresh KSP with HTPPC (or ``-ref=PC``), on the foreign study's matrices at ``-sizes=``
(500 and 1 500 rows, with PyAMG's examples, by default): prints the solves that did not converge or converged at a
true relative residual above 1e-6, then the count. ``-attach`` attaches the constant null space to singular
matrices; ``-only=CASE`` and ``-ksp=TYPE`` (repeatable) narrow it down.

    OMP_NUM_THREADS=1 [mpiexec -n 2] python results/ksps-20261127/sweep.py [-attach] [-sizes=16384]
"""
import sys, petsc4py; petsc4py.init(sys.argv)
from petsc4py import PETSc
import numpy as np, scipy.sparse as sp
from petsc_htp import HTPPC
from petsc_htp.bench.foreigncases import CASES, pyamg_cases
comm = PETSc.COMM_WORLD; size = comm.getSize()
KSPS = ['cg','minres','gmres','fgmres','bcgs','cr','symmlq','cgs','tfqmr','richardson','chebyshev','pipecg','groppcg','lgmres','gcr','bicg','fcg','pipefcg','ibcgs','qmrcgs','tcqmr','cgne','lsqr','pipecr','pgmres','dgmres','bcgsl','fbcgs','pipegcr']
SIZES = [int(a[7:]) for a in sys.argv if a.startswith('-sizes=')] or (500, 1500)
def cases():
    for name in CASES:
        for n in SIZES:
            yield f"{name}_{n}", CASES[name](n, 0)
    if 500 in SIZES:
        for name, (A, b) in pyamg_cases().items():
            yield name, (A, b)
def mk(A, b):
    A = sp.csr_matrix(A); M = PETSc.Mat().create(comm); M.setSizes(A.shape); M.setType('aij'); M.setUp()
    lo, hi = M.getOwnershipRange(); L = A[lo:hi]; L.sort_indices()
    M.setPreallocationCSR((L.indptr, L.indices)); M.setValuesCSR(L.indptr, L.indices, L.data); M.assemble()
    singular = np.abs(np.asarray(A.sum(axis=1)).ravel()).max() <= 1e-10 * np.abs(A.diagonal()).max()
    if singular and '-attach' in sys.argv:
        ns = PETSc.NullSpace().create(constant=True, comm=comm); M.setNullSpace(ns)
    x, bv = M.createVecs(); bv.setArray(np.asarray(b)[lo:hi])
    return M, bv, x
bad = 0; total = 0
REF = ([a[5:] for a in sys.argv if a.startswith('-ref=')] or [None])[0]
only = [a[6:] for a in sys.argv if a.startswith('-only=')]
for name, (A, b) in cases():
    if only and name not in only: continue
    M, bv, x = mk(A, b)
    for k in ([a[5:] for a in sys.argv if a.startswith('-ksp=')] or KSPS):
        if (name, k) == ('pyamg_bar', 'chebyshev'): continue   # PETSc: NaN then SEGV in KSPDestroy with any PC
        ksp = PETSc.KSP().create(comm); ksp.setOperators(M); ksp.setType(k); ksp.setTolerances(rtol=1e-8, max_it=2000)
        pass
        pc = ksp.getPC()
        if REF: pc.setType(REF)
        else: pc.setType('python'); pc.setPythonContext(HTPPC())
        x.set(0)
        try:
            ksp.solve(bv, x); r = bv.duplicate(); M.mult(x, r); r.aypx(-1, bv)
            rel = r.norm() / bv.norm(); reason = ksp.getConvergedReason(); its = ksp.getIterationNumber()
            msg = None
            if reason <= 0: msg = f'reason {reason}'
            elif rel > 1e-6: msg = f'converged {reason} but true relres {rel:.1e}'
        except Exception as e:
            msg = 'ERROR ' + str(e.__cause__ or e).splitlines()[0][:150]; its = -1; rel = float('nan')
        total += 1
        if '-v' in sys.argv: PETSc.Sys.Print(name, k, its, flush=True)
        if msg:
            bad += 1; PETSc.Sys.Print(f'{name:40s} {k:10s} its {its:5d} relres {rel:.1e} {msg}')
        ksp.destroy()
    M.destroy()
PETSc.Sys.Print(f'{bad} of {total} failed on {size} ranks')
