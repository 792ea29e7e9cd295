"""The DMDA problem's operator (:mod:`petsc_htp.scenes.dmda`, examples/dmda_poisson.py) on every rank against the
discs' 5-point (2-D: :func:`petsc_htp.scenes.gallery.variable_poisson`) or the balls' 7-point stencil (3-D) in
natural order, also after new values of another seed; run by tests/test_foreign.py under mpiexec with the dimension
as argument: prints "same operator" on each rank whose rows match both times."""
import sys

import numpy as np
import petsc4py

petsc4py.init(sys.argv[:1])
from petsc4py import PETSc  # noqa: E402
import scipy.sparse as sp  # noqa: E402

from petsc_htp.scenes import dmda  # noqa: E402
from petsc_htp.scenes.gallery import balls, face_weights, variable_poisson  # noqa: E402


def reference(n, dim, contrast, seed):
    """The operator in natural (x fastest) order, assembled from the faces."""
    if dim == 2:
        return variable_poisson(n, n, contrast, seed)[0]
    wx, wy, wz, edge = face_weights(balls((n, n, n), contrast, seed))
    idx = np.arange(n ** 3).reshape(n, n, n)
    i = np.concatenate([idx[:, :, :-1].ravel(), idx[:, :-1, :].ravel(), idx[:-1].ravel()])
    j = np.concatenate([idx[:, :, 1:].ravel(), idx[:, 1:, :].ravel(), idx[1:].ravel()])
    w = np.concatenate([wx.ravel(), wy.ravel(), wz.ravel()])
    d = np.bincount(i, w, n ** 3) + np.bincount(j, w, n ** 3) + edge.ravel()
    return sp.csr_matrix((np.concatenate([-w, -w, d]), (np.concatenate([i, j, idx.ravel()]),
                                                         np.concatenate([j, i, idx.ravel()]))), shape=(n ** 3,) * 2)


def same(A, da, n, dim, seed) -> bool:
    """Whether ``A``'s product with a random vector matches the reference's on this rank's rows."""
    natural = da.getAO().petsc2app(np.arange(*A.getOwnershipRange(), dtype=PETSc.IntType))
    v = np.random.default_rng(0).standard_normal(n ** dim)
    x, y = A.createVecs()
    x.setArray(v[natural])
    A.mult(x, y)
    return np.allclose(y.getArray(), (reference(n, dim, 1000.0, seed) @ v)[natural])


def main():
    dim = int(sys.argv[1])
    n = 9 if dim == 3 else 23
    da = dmda.grid(n, dim)
    A = dmda.operator(da, 1000.0, 0)
    first = same(A, da, n, dim, 0)
    dmda.operator(da, 1000.0, 5, mat=A)
    if first and same(A, da, n, dim, 5) and A.isSymmetricKnown() == (True, True):
        print("same operator", flush=True)


if __name__ == "__main__":
    main()
