"""Each level's Level() (leaves, coarse space, smoothed W) and Galerkin product (Level.coarse: MatPtAP) of the DMDA
matrix's hierarchy, timed on every rank together. From the repository root:
    for r in 1 2; do mpiexec -n $r python results/scale-20261128/levels.py -n 1024; done > results/scale-20261128/levels.txt
"""
import sys, time, petsc4py; petsc4py.init(sys.argv)
from petsc4py import PETSc
from petsc_htp.scenes import dmda
from petsc_htp.multilevel import level as L
from petsc_htp.petscmat import local_rows
comm = PETSc.COMM_WORLD
opts = PETSc.Options()
side, dim = opts.getInt("n", 1024), opts.getInt("dim", 2)
da = dmda.grid(side, dim); A = dmda.operator(da, 1000.0, 0)
def T(f):
    comm.barrier(); t = time.perf_counter(); out = f(); comm.barrier(); return out, 1e3 * (time.perf_counter() - t)
cur = A
for k in range(5):
    lev, t_level = T(lambda: L.Level(cur, blocks=False))
    C, t_ptap = T(lambda: lev.coarse())
    info = C.getInfo(PETSc.Mat.InfoType.GLOBAL_SUM)
    winfo = lev.W.getInfo(PETSc.Mat.InfoType.GLOBAL_SUM)
    PETSc.Sys.Print(f"level {k}: rows {cur.getSize()[0]} nnz/row {cur.getInfo(PETSc.Mat.InfoType.GLOBAL_SUM)['nz_used']/cur.getSize()[0]:.1f} W nnz/row {winfo['nz_used']/cur.getSize()[0]:.2f} -> {C.getSize()[0]}: Level {t_level:.1f} ms, PtAP {t_ptap:.1f} ms")
    if C.getSize()[0] <= 1000: break
    cur = C
