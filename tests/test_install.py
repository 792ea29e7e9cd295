"""The wheel in a venv of its own, without torch: pip resolves the core dependencies from the wheel's metadata,
nothing is borrowed from the test environment; HTPPC's default then runs the example with the shipped options
files and the whole bad-input suite on 1 and 2 ranks, and asking for the paper's network names the extra."""
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from test_bad_input import EXPECTED, check_outcome, run_cases

ROOT = Path(__file__).resolve().parent.parent
TORCH = r"error: .*-htp_variant paper \(the paper's network\) runs torch, which is not installed: " \
        r"pip install 'petsc_htp\[learned\]' \[ModuleNotFoundError\]"
WITHOUT_TORCH = {**EXPECTED, "missing_checkpoint": TORCH, "corrupt_checkpoint": TORCH}


def run(*args, cwd=None, timeout=600, ok=True):
    out = subprocess.run([str(a) for a in args], cwd=cwd, capture_output=True, text=True, timeout=timeout)
    assert (out.returncode == 0) == ok, out.stdout[-3000:] + out.stderr[-3000:]
    return out.stdout + out.stderr


@pytest.mark.slow
def test_wheel_without_torch_runs_the_default_and_the_bad_input_suite(tmp_path):
    wheels = tmp_path / "wheels"
    run(sys.executable, "-m", "pip", "wheel", "-q", "--no-deps", "--no-build-isolation", "-w", wheels, ROOT)
    wheel = next(wheels.glob("petsc_htp-*.whl"))
    venv = tmp_path / "venv"
    run(sys.executable, "-m", "venv", venv)                 # no --system-site-packages, no .pth into ours
    py = venv / "bin" / "python"
    # the core dependencies only (mpi4py built against the system MPI, as the Makefile does)
    run(py, "-m", "pip", "install", "-q", "--no-binary", "mpi4py", wheel)
    site = run(py, "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])").strip()
    for module in ("petsc_htp", "petsc4py", "mpi4py", "scipy", "pymetis", "pyamg"):
        where = run(py, "-c", f"import {module}; print({module}.__file__)", cwd=tmp_path).strip()
        assert where.startswith(site), (module, where)
    assert "No module named 'torch'" in run(py, "-c", "import torch", ok=False)
    run(py, "-c", "import sys, petsc4py; petsc4py.init(); from petsc4py import PETSc; import petsc_htp; "
                  "from petsc_htp import HTPPC; sys.exit('torch' in sys.modules)", cwd=tmp_path)
    work = tmp_path / "work"
    work.mkdir()
    example = shutil.copy(ROOT / "examples" / "poisson_multiphase.py", work)
    where = run(py, "-c", "import petsc_htp.bench.harness as m; print(m.OPTIONS_DIR)", cwd=work).strip()
    assert where.startswith(site), where
    for method in (str(Path(where) / "cg_gamg.opts"), "cg_jacobi", "cg_htp"):
        out = run(py, example, "-n", "1024", "-options_file", method, cwd=work)
        assert "converged reason: CONVERGED_RTOL" in out and "true relative residual" in out, out
    assert "petsc_htp[learned]" in run(py, example, "-n", "1024", "-options_file", "cg_paper", cwd=work, ok=False)
    # the bad-input suite on the installed package (the script's own folder holds no petsc_htp)
    script = shutil.copy(ROOT / "tests" / "bad_input_cases.py", work)
    for n in (1, 2):
        (tmp_path / f"bad{n}").mkdir()
        got = run_cases(py, script, n, tmp_path / f"bad{n}", cwd=work)
        assert set(got) == {(case, r) for case in WITHOUT_TORCH for r in range(n)}
        for case in sorted(WITHOUT_TORCH):
            check_outcome(got, n, case, WITHOUT_TORCH)
    # the benchmark extra adds the charts
    run(py, "-m", "pip", "install", "-q", f"{wheel}[bench]")
    run(py, example, "-n", "1024", "-options_file", "cg_htp", "-plot", "demo.png", cwd=work)
    assert (work / "demo.png").stat().st_size > 1000
