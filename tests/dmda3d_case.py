"""The 3-D DMDA example's operator on every rank against the balls' 7-point stencil in natural order, run by
tests/test_foreign.py under mpiexec: prints "same operator" on each rank whose rows match."""
import sys
from pathlib import Path

import numpy as np
import petsc4py

petsc4py.init(sys.argv)
from petsc4py import PETSc  # noqa: E402
import scipy.sparse as sp  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "examples"))
import dmda_poisson  # noqa: E402
from petsc_htp.scenes.gallery import balls, face_weights  # noqa: E402


def reference(n, contrast, seed):
    """The operator in natural (x fastest) order, assembled from the faces."""
    wx, wy, wz, edge = face_weights(balls((n, n, n), contrast, seed))
    idx = np.arange(n ** 3).reshape(n, n, n)
    i = np.concatenate([idx[:, :, :-1].ravel(), idx[:, :-1, :].ravel(), idx[:-1].ravel()])
    j = np.concatenate([idx[:, :, 1:].ravel(), idx[:, 1:, :].ravel(), idx[1:].ravel()])
    w = np.concatenate([wx.ravel(), wy.ravel(), wz.ravel()])
    d = np.bincount(i, w, n ** 3) + np.bincount(j, w, n ** 3) + edge.ravel()
    return sp.csr_matrix((np.concatenate([-w, -w, d]), (np.concatenate([i, j, idx.ravel()]),
                                                         np.concatenate([j, i, idx.ravel()]))), shape=(n ** 3,) * 2)


def main():
    n = 9
    da = PETSc.DMDA().create([n] * 3, stencil_width=1, stencil_type=PETSc.DMDA.StencilType.STAR)
    da.setUp()
    A = dmda_poisson.assemble_3d(da, 1000.0, 0)
    natural = da.getAO().petsc2app(np.arange(*A.getOwnershipRange(), dtype=PETSc.IntType))
    v = np.random.default_rng(0).standard_normal(n ** 3)
    x, y = A.createVecs()
    x.setArray(v[natural])
    A.mult(x, y)
    if np.allclose(y.getArray(), (reference(n, 1000.0, 0) @ v)[natural]):
        print("same operator", flush=True)


if __name__ == "__main__":
    main()
