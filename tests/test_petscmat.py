"""The PETSc adapter: frames as distributed Mat/Vec (real PETSc, real MPI)."""
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import petsc4py  # noqa: F401,E402  (a missing PETSc fails here, never skips)
from petsc_htp.petscmat import frame_mat, frame_vec  # noqa: E402
from petsc_htp.scenes.generator import make_frame  # noqa: E402


def test_petsc_mat_matches_scipy():
    from petsc4py import PETSc

    frame = make_frame(300, seed=5)
    mat = frame_mat(frame)
    assert mat.getSize() == (300, 300)
    indptr, indices, data = mat.getValuesCSR()
    np.testing.assert_array_equal(indptr, frame.A.indptr)
    np.testing.assert_array_equal(indices, frame.A.indices)
    np.testing.assert_array_equal(data, frame.A.data)
    nullspace = mat.getNullSpace()
    assert nullspace is not None and nullspace.hasConstant()
    assert nullspace.test(mat)
    ones, product = mat.createVecs()
    ones.set(1.0)
    mat.mult(ones, product)
    assert product.norm(PETSc.NormType.INFINITY) <= 1e-10 * frame.A.diagonal().max()
    assert mat.isSymmetricKnown() == (True, True)
    np.testing.assert_array_equal(frame_vec(frame, mat).getArray(), frame.b)
    assert frame_mat(frame, PETSc.COMM_SELF).equal(mat)


MPI_SCRIPT = """
import numpy as np
from petsc_htp.petscmat import frame_mat, frame_vec
from petsc_htp.scenes.generator import make_frame
frame = make_frame(301, seed=3)
mat = frame_mat(frame)
start, end = mat.getOwnershipRange()
local = frame.A[start:end]
indptr, indices, data = mat.getValuesCSR()
assert 0 < end - start < frame.n
assert np.array_equal(indptr, local.indptr) and np.array_equal(indices, local.indices)
assert np.array_equal(data, local.data)
assert np.array_equal(frame_vec(frame, mat).getArray(), frame.b[start:end])
ones, product = mat.createVecs()
ones.set(1.0)
mat.mult(ones, product)
assert product.norm() <= 1e-10 * frame.A.diagonal().max()
from petsc4py import PETSc
PETSc.Sys.syncPrint("rank ok", mat.getComm().getRank())   # ordered output, no interleaving
PETSc.Sys.syncFlush()
"""


@pytest.mark.mpi
def test_petsc_mat_distributed_over_two_ranks():
    mpiexec = shutil.which("mpiexec", path=f"{Path(sys.executable).parent}:{os.environ.get('PATH', '')}")
    assert mpiexec, "mpiexec not found (the Makefile installs MPICH)"
    root = str(Path(__file__).resolve().parents[1])
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(p for p in (root, env.get("PYTHONPATH")) if p)
    result = subprocess.run([mpiexec, "-n", "2", sys.executable, "-c", MPI_SCRIPT],
                            capture_output=True, text=True, timeout=120, env=env)
    assert result.returncode == 0, result.stderr
    assert result.stdout.splitlines() == ["rank ok 0", "rank ok 1"]


def test_the_symmetry_probe_is_the_same_vector_on_any_split():
    """validation.probe_values hashes each global index: any split of the rows gives the same probe, so a matrix near
    the asymmetry threshold gets one answer on any number of ranks (PETSc's random vectors differ with the split);
    its entries spread over [-0.5, 0.5) as uniform ones do, and the two salts differ."""
    from petsc_htp.validation import probe_values

    whole = probe_values(0, 100000, 1)
    parts = np.concatenate([probe_values(a, b, 1) for a, b in ((0, 333), (333, 50001), (50001, 100000))])
    assert np.array_equal(whole, parts)
    assert abs(whole.mean()) < 0.01 and abs(whole.std() - 12 ** -0.5) < 0.01 and whole.min() >= -0.5 and whole.max() < 0.5
    assert abs(np.corrcoef(whole, probe_values(0, 100000, 2))[0, 1]) < 0.02
    pair = probe_values(333, 50001, (1, 2))                      # several salts: one row each, as made apart
    assert pair.shape == (2, 49668) and np.array_equal(pair[0], whole[333:50001])
    assert np.array_equal(pair[1], probe_values(333, 50001, 2))
