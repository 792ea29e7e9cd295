"""The wheel in a venv of its own: pip resolves every dependency from the wheel's metadata, nothing is
borrowed from the test environment; the example then runs with the shipped options files."""
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent


def run(*args, cwd=None, timeout=600):
    out = subprocess.run([str(a) for a in args], cwd=cwd, capture_output=True, text=True, timeout=timeout)
    assert out.returncode == 0, out.stdout[-3000:] + out.stderr[-3000:]
    return out.stdout


@pytest.mark.slow
def test_wheel_in_its_own_venv_runs_the_example_with_shipped_options(tmp_path):
    wheels = tmp_path / "wheels"
    run(sys.executable, "-m", "pip", "wheel", "-q", "--no-deps", "--no-build-isolation", "-w", wheels, ROOT)
    wheel = next(wheels.glob("petsc_htp-*.whl"))
    venv = tmp_path / "venv"
    run(sys.executable, "-m", "venv", venv)                 # no --system-site-packages, no .pth into ours
    py = venv / "bin" / "python"
    # the core dependencies only (mpi4py built against the system MPI, as the Makefile does)
    run(py, "-m", "pip", "install", "-q", "--no-binary", "mpi4py", wheel)
    site = run(py, "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])").strip()
    for module in ("petsc_htp", "petsc4py", "mpi4py", "torch", "scipy", "pymetis"):
        where = run(py, "-c", f"import {module}; print({module}.__file__)", cwd=tmp_path).strip()
        assert where.startswith(site), (module, where)
    work = tmp_path / "work"
    work.mkdir()
    example = shutil.copy(ROOT / "examples" / "poisson_multiphase.py", work)
    where = run(py, "-c", "import petsc_htp.methods as m; print(m.OPTIONS_DIR)", cwd=work).strip()
    assert where.startswith(site), where
    for method in (str(Path(where) / "cg_gamg.opts"), "cg_jacobi", "cg_htp"):
        out = run(py, example, "-n", "1024", "-options_file", method, cwd=work)
        assert "converged reason: CONVERGED_RTOL" in out and "true relative residual" in out, out
    # the benchmark extra adds the charts
    run(py, "-m", "pip", "install", "-q", f"{wheel}[bench]")
    run(py, example, "-n", "1024", "-options_file", "cg_htp", "-plot", "demo.png", cwd=work)
    assert (work / "demo.png").stat().st_size > 1000
