"""PETSc's ways to the Galerkin product W^T A W of one level (-lev L) of the DMDA matrix's hierarchy, best of two,
on every rank together. From the repository root:
    for run in "1" "2" "2 -matptap_via nonscalable"; do set -- $run; r=$1; shift; echo "ranks $r $*"
        mpiexec -n $r python results/scale-20261128/products.py -n 1024 "$@"; done > results/scale-20261128/products.txt
"""
import sys, time, petsc4py; petsc4py.init(sys.argv)
from petsc4py import PETSc
from petsc_htp.scenes import dmda
from petsc_htp.multilevel import level as L
comm = PETSc.COMM_WORLD
opts = PETSc.Options()
side, dim, lev = opts.getInt("n", 1024), opts.getInt("dim", 2), opts.getInt("lev", 0)
da = dmda.grid(side, dim); A = dmda.operator(da, 1000.0, 0)
for k in range(lev):
    A = L.Level(A, blocks=False).coarse()
lv = L.Level(A, blocks=False); W = lv.W
def T(name, f, rep=2):
    best = 1e9
    for _ in range(rep):
        comm.barrier(); t = time.perf_counter(); out = f(); comm.barrier(); best = min(best, 1e3 * (time.perf_counter() - t))
        if out is not None and rep > 1: out.destroy()
    PETSc.Sys.Print(f"{name}: {best:.1f} ms")
T("ptap", lambda: A.ptap(W))
T("AW then WtAW", lambda: W.transposeMatMult(A.matMult(W)))
def c():
    Wt = W.transpose(PETSc.Mat()); AW = A.matMult(W); C = Wt.matMult(AW); Wt.destroy(); AW.destroy(); return C
T("explicit Wt, Wt*(A*W)", c)
def d():
    Wt = W.transpose(PETSc.Mat()); C = Wt.matMatMult(A, W); Wt.destroy(); return C
T("Wt*A*W (ABC)", d)
def e():
    Wt = W.transpose(PETSc.Mat()); C = A.rart(Wt); Wt.destroy(); return C
T("RARt", e)
