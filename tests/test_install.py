"""A non-editable install into a fresh venv finds its shipped options files and writes into the cwd."""
import shutil
import subprocess
import sys
import sysconfig
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent


@pytest.mark.slow
def test_wheel_in_fresh_venv_runs_the_example_with_shipped_options(tmp_path):
    wheels = tmp_path / "wheels"
    subprocess.run([sys.executable, "-m", "pip", "wheel", "-q", "--no-deps", "--no-build-isolation",
                    "-w", str(wheels), str(ROOT)], check=True, timeout=300)
    venv = tmp_path / "venv"
    subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True, timeout=120)
    py = venv / "bin" / "python"
    site = Path(subprocess.run([str(py), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
                               check=True, capture_output=True, text=True).stdout.strip())
    # numpy, scipy, torch, petsc4py, pymetis come from the test environment (a plain path entry: its
    # .pth files, such as the editable install of this checkout, are not run).
    (site / "deps.pth").write_text(sysconfig.get_paths()["purelib"] + "\n")
    subprocess.run([str(py), "-m", "pip", "install", "-q", "--no-deps", "--no-index",
                    *map(str, wheels.glob("petsc_htp-*.whl"))], check=True, timeout=300)
    work = tmp_path / "work"
    work.mkdir()
    example = shutil.copy(ROOT / "examples" / "poisson_multiphase.py", work)
    where = subprocess.run([str(py), "-c", "import petsc_htp.methods as m; print(m.OPTIONS_DIR)"], cwd=work,
                           check=True, capture_output=True, text=True).stdout.strip()
    assert where.startswith(str(site)), where
    shipped = Path(where) / "cg_gamg.opts"
    for method in (str(shipped), "cg_jacobi", "cg_htp"):
        out = subprocess.run([str(py), example, "-n", "1024", "-options_file", method, "-plot", "demo.png"],
                             cwd=work, capture_output=True, text=True, timeout=300)
        assert out.returncode == 0, out.stdout + out.stderr
        assert "converged reason: CONVERGED_RTOL" in out.stdout
        assert "true relative residual" in out.stdout
    assert (work / "demo.png").stat().st_size > 1000
