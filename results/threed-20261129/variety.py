"""Bare 3-D matrices of other kinds than the foreign study's: random cubes of contrast 1e6, grid-aligned anisotropy
(the z couplings times 0.3, 0.1, 0.01), uncorrelated log-normal cell conductivities (sigma 1, 2), no-flux walls with
balls of contrast 1e3 (singular, the constant attached), and the 3-D DMDA matrix numbered at random; SIDE^3 cells,
a fresh Mat and KSP each, CG to 1e-8 in the unpreconditioned norm, one thread; each line: the case, the option set,
setup + solve ms of the second of two solves (iterations). Option sets: 'default' (HTPPC as it comes), 'twolevel'
(-htp_variant twolevel), 'gamg' (options/cg_gamg.opts). From the repository root:
  python results/threed-20261129/variety.py SIDE SET..."""
import sys

import numpy as np
import petsc4py
import scipy.sparse as sp

petsc4py.init(sys.argv[:1])
from petsc4py import PETSc  # noqa: E402

from petsc_htp.onesolve import timed_solve  # noqa: E402
from petsc_htp.scenes import foreign  # noqa: E402
from petsc_htp.scenes.gallery import balls  # noqa: E402

HTP = "-ksp_type cg -ksp_rtol 1e-8 -ksp_norm_type unpreconditioned -pc_type python -pc_python_type petsc_htp.HTPPC"
SETS = {"default": HTP, "twolevel": HTP + " -htp_variant twolevel",
        "gamg": "-ksp_norm_type unpreconditioned -ksp_rtol 1e-8 -options_file options/cg_gamg.opts"}


def aniso(side, eps):
    """7-point Laplacian on side^3 nodes, Dirichlet eliminated, the z couplings times ``eps``."""
    e = np.ones(side)
    T, eye = sp.diags([-e[:-1], 2 * e, -e[:-1]], [-1, 0, 1]), sp.identity(side)
    return (sp.kron(sp.kron(T, eye), eye) + sp.kron(sp.kron(eye, T), eye) + eps * sp.kron(sp.kron(eye, eye), T))


def cases(side):
    rng = np.random.default_rng(0)
    out = {f"aniso_z{eps}": aniso(side, eps) for eps in (0.3, 0.1, 0.01)}
    out.update({f"lognormal_s{s}": foreign.cells(np.exp(s * rng.standard_normal((side,) * 3))) for s in (1, 2)})
    out["cubes1e6"] = foreign.cubes(side)[0]
    out["neumann3d"] = foreign.cells(balls((side,) * 3, 1e3, 0), walls=False)
    p = rng.permutation(side ** 3)
    out["dmda3d_random"] = foreign.dmda(3, side, 1e3, 0)[0][p][:, p]
    return out


def solve(A, b, opts, null):
    db = PETSc.Options()
    for key in list(db.getAll()):
        db.delValue(key)
    PETSc.Options().insertString(opts)
    mat = PETSc.Mat().createAIJ(A.shape, csr=(A.indptr.astype(PETSc.IntType), A.indices.astype(PETSc.IntType), A.data))
    if null:
        mat.setNullSpace(PETSc.NullSpace().create(constant=True))
    rhs = mat.createVecLeft()
    rhs.array[:] = b
    x = rhs.duplicate()
    ksp = PETSc.KSP().create()
    ksp.setOperators(mat)
    ksp.setFromOptions()
    its, reason, setup, solve_ms, relres = timed_solve(ksp, rhs, x)
    ksp.destroy()
    mat.destroy()
    return its, reason, setup + solve_ms, relres


side = int(sys.argv[1])
for name, A in cases(side).items():
    A = A.tocsr()
    A.sort_indices()
    b = np.random.default_rng(1).standard_normal(A.shape[0])
    b = b - b.mean() if name == "neumann3d" else A @ b
    for which in sys.argv[2:]:
        solve(A, b, SETS[which], name == "neumann3d")
        its, reason, ms, relres = solve(A, b, SETS[which], name == "neumann3d")
        print(f"{name} {A.shape[0]} {which}: {ms:.0f} ms ({its}; reason {reason}, true relres {relres:.1e})", flush=True)
