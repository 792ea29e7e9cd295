"""HTPPC feels like PETSc: -ksp_view shows the inner solvers, -log_view an event per phase, a setup leaves the
options database as it found it, and the default neither imports nor runs torch."""
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from petsc_htp.events import EVENTS

HERE = Path(__file__).resolve().parent


def run(ranks, *args):
    """tests/native_case.py on ``ranks`` ranks with PETSc options ``args``; its output."""
    mpiexec = shutil.which("mpiexec", path=f"{Path(sys.executable).parent}:/usr/bin:/usr/local/bin")
    assert mpiexec, "mpiexec not found (the Makefile installs MPICH)"
    proc = subprocess.run([mpiexec, "-n", str(ranks), sys.executable, str(HERE / "native_case.py"), *args],
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    return proc.stdout


@pytest.mark.mpi
@pytest.mark.parametrize("ranks", [1, 2])
def test_ksp_view_shows_the_inner_solvers_and_log_view_an_event_per_phase(ranks):
    out = run(ranks, "-ksp_view", "-log_view")
    assert re.search(r"reason [1-9]\d* iterations (\d+)", out), out[-2000:]
    pcs = re.findall(r"PC Object: ?(\(\w+\))? \d+ MPI process", out)
    assert len(pcs) >= 3 and "(htp_leaf_)" in pcs and "(htp_cs_)" in pcs, pcs
    assert "leaf solver:" in out and "coarse solver:" in out and "variant twolevel: two-level preconditioner" in out
    events = {line.split()[0] for line in out.splitlines() if line.split() and line.split()[0] in EVENTS}
    assert len(events) >= 6 and {"HTPSetup", "HTPApply", "HTPLeafSolve", "HTPCoarseSolve"} <= events, events
    assert "inner: {'leaf solver': 'htp_leaf_ cholesky', 'coarse solver': 'htp_cs_ " in out
    assert "leaf htp_leaf_; coarse htp_cs_" in out and "torch loaded: False" in out
    assert "BLAS threads: [1]" in out and "BLAS, OpenMP threads: 1" in out     # -htp_threads 1, one per rank


@pytest.mark.mpi
@pytest.mark.parametrize("ranks, args", [(1, ()), (2, ()),                     # LU; PCREDUNDANT on 2 ranks
                                         (1, ("-htp_coarse_solver", "gamg")),  # GAMG V-cycles
                                         (2, ("-case", "dmda3d", "-n", "8000", "-htp_direct_max", "0"))])
def test_a_setup_leaves_the_options_database_as_it_found_it(ranks, args):
    out = run(ranks, *args)
    assert "options unchanged: True []" in out, out[-2000:]
    assert re.search(r"reason [1-9]", out), out[-2000:]


@pytest.mark.mpi
def test_user_options_win_over_the_inner_defaults():
    out = run(1, "-htp_leaf_pc_type", "lu", "-htp_cs_pc_type", "cholesky")
    assert "'leaf solver': 'htp_leaf_ lu', 'coarse solver': 'htp_cs_ cholesky'" in out, out[-2000:]
    assert "options unchanged: True []" in out


def test_import_leaves_torch_out():
    code = ("import sys, petsc4py; petsc4py.init(); from petsc4py import PETSc; import petsc_htp; "
            "from petsc_htp import HTPPC; import petsc_htp.variants, petsc_htp.twolevel.composed; "
            "sys.exit('torch' in sys.modules)")
    assert subprocess.run([sys.executable, "-c", code]).returncode == 0


def test_a_first_multilevel_solve_leaves_scipy_csgraph_out():
    """HTPPC's import and a first multilevel solve (the coarsest level's band in reverse Cuthill-McKee order:
    twolevel/cuthill.py) load no scipy.sparse.csgraph, whose import pulls in scipy.sparse.linalg (about 90 ms of a
    fresh process's import of petsc_htp.pc)."""
    code = ("import sys, petsc4py; petsc4py.init(); from petsc4py import PETSc\n"
            "import petsc_htp.pc\n"
            "assert 'scipy.sparse.csgraph' not in sys.modules\n"
            "from petsc_htp.scenes import foreign\n"
            "A, b = foreign.dmda(2, 200, 1e3, 0)\n"
            "M = PETSc.Mat().createAIJ(A.shape, csr=(A.indptr, A.indices, A.data), comm=PETSc.COMM_SELF)\n"
            "rhs, x = M.createVecs(); rhs.getArray()[:] = b\n"
            "ksp = PETSc.KSP().create(PETSc.COMM_SELF); ksp.setOperators(M, M); ksp.setType('cg')\n"
            "ksp.getPC().setType('python'); ksp.getPC().setPythonContext(petsc_htp.pc.HTPPC())\n"
            "ksp.setTolerances(rtol=1e-8); ksp.solve(rhs, x)\n"
            "assert ksp.getConvergedReason() > 0 and 'multilevel' in ksp.getPC().getPythonContext().setup.title\n"
            "sys.exit('scipy.sparse.csgraph' in sys.modules)\n")
    assert subprocess.run([sys.executable, "-c", code]).returncode == 0


def test_aggregation_loads_pyamg_kernels_without_pyamg_package():
    """The leaves' PyAMG kernels load without ``pyamg/__init__`` (its gallery and solvers: about 40 ms of a first
    setup); PyAMG imported afterwards finds the same modules and works."""
    code = ("import sys, numpy as np, scipy.sparse as sp\n"
            "from petsc_htp.twolevel.aggregation import aggregates\n"
            "A = sp.diags([-1.0, 2.0, -1.0], [-1, 0, 1], (400, 400)).tocsr()\n"
            "part = aggregates(A, second='pairs')\n"
            "assert 'pyamg' not in sys.modules and part.max() < 200, sorted(m for m in sys.modules if 'pyamg' in m)\n"
            "from petsc_htp.twolevel.amgkernels import kernels\n"
            "import pyamg\n"
            "assert pyamg.amg_core.smoothed_aggregation is kernels('smoothed_aggregation')\n"
            "print(len(pyamg.smoothed_aggregation_solver(A).levels) > 1)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0 and out.stdout.strip() == "True", out.stderr[-2000:]


def test_thread_pools_are_read_again_only_when_a_shared_object_was_loaded():
    """The BLAS and OpenMP pools are looked up again only when the process loaded a shared object: a pure-Python
    import keeps the pools found, an extension module's import (a library that may bring a pool) reads them
    again (reading /proc/self/maps at every setup cost about 1-2 ms, a small matrix's whole solve)."""
    import subprocess
    import sys

    code = ("import sys, numpy; from petsc_htp.threads import thread_pools\n"
            "first = thread_pools()\n"
            "assert 'colorsys' not in sys.modules and 'xxlimited' not in sys.modules\n"
            "import colorsys\n"
            "kept = thread_pools()\n"
            "import xxlimited\n"
            "again = thread_pools()\n"
            "print(kept is first, again is not kept, sorted(map(str, again)) == sorted(map(str, first)), len(first))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    kept, fresh, same, found = out.stdout.split()
    assert (kept, fresh, same) == ("True", "True", "True") and int(found) > 0, out.stdout


def test_set_threads_reaches_scipys_own_openblas():
    """SciPy's wheel brings an OpenBLAS of its own (``scipy_openblas_*`` symbols, beside NumPy's ``..64_``), which
    scipy.linalg's LAPACK runs, the banded Cholesky factor's included: -htp_threads reaches it too (left at a thread
    per core, a band of 12 100 rows and width 110 took 11.7 s, against 35 ms, on this 2-core machine under load)."""
    code = ("import ctypes, scipy.linalg.lapack\n"
            "from petsc_htp.threads import set_threads, thread_pools, loaded_objects\n"
            "lib = [n for n in loaded_objects() if 'libscipy_openblas-' in n]\n"
            "get = ctypes.CDLL(lib[0]).scipy_openblas_get_num_threads\n"
            "set_threads(1)\n"
            "print(len(lib), get())")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120,
                         env={**os.environ, "OPENBLAS_NUM_THREADS": "2"})
    assert out.returncode == 0 and out.stdout.split() == ["1", "1"], out.stdout + out.stderr
