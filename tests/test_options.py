"""Every options file in options/ runs through the example and converges."""
import re
import subprocess
import sys
from pathlib import Path

import pytest

import petsc4py  # noqa: F401,E402  (a missing PETSc fails here, never skips)

from petsc_htp.training import checkpoint  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
EXAMPLE = ROOT / "examples" / "poisson_multiphase.py"
METHODS = sorted(p.stem for p in (ROOT / "options").glob("*.opts") if p.name != "common.opts")


def run_example(*args, timeout=300):
    """Run the example (one torch thread: the test machines are small and busy)."""
    out = subprocess.run([sys.executable, str(EXAMPLE), *map(str, args), "-htp_threads", "1"], cwd=ROOT,
                         capture_output=True, text=True, timeout=timeout)
    return out.returncode, out.stdout + out.stderr


def field(text, name):
    m = re.search(rf"^{re.escape(name)}: (.*)$", text, re.M)
    assert m, f"no '{name}:' line in\n{text}"
    return m.group(1).strip()


def test_expected_method_files_exist():
    assert set(METHODS) >= {"cg_none", "cg_jacobi", "cg_icc", "cg_gamg", "cg_bjacobi",
                            "cg_htp", "cg_paper", "gmres_paper", "bjacobi_paper"}
    for stem in METHODS:
        text = (ROOT / "options" / f"{stem}.opts").read_text()
        assert text.startswith("#"), f"{stem}.opts has no header comment"
        assert "-options_file options/common.opts" in text


@pytest.mark.slow
@pytest.mark.parametrize("method", METHODS)
def test_method_file_converges(method, tiny_ckpt):
    code, out = run_example("-options_file", f"options/{method}.opts", "-n", 1024, "-seed", 7,
                            "-htp_checkpoint", tiny_ckpt)
    assert code == 0, out
    assert field(out, "method").startswith(method)
    assert field(out, "converged reason").startswith("CONVERGED_"), out
    relres = float(field(out, "true relative residual ||b - A x|| / ||b||"))
    assert relres <= 1.01e-8
    assert int(field(out, "iterations")) > 0 or relres <= 1e-12     # a factor of the whole matrix starts on M b
    if method == "cg_bjacobi":
        assert "pc bjacobi/cholesky" in out


def test_petsc_itself_reads_the_nested_common_file():
    """Plain PETSc (no example script) follows the -options_file line inside a method file."""
    code = ("import sys, petsc4py; petsc4py.init(sys.argv); from petsc4py import PETSc; "
            "o = PETSc.Options(); print(o.getString('ksp_type'), o.getString('pc_type'), "
            "o.getReal('ksp_rtol'), o.getString('ksp_norm_type'))")
    out = subprocess.run([sys.executable, "-c", code, "-options_file", "options/cg_jacobi.opts",
                          "-options_left", "0"], cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.splitlines()[0].split() == ["cg", "jacobi", "1e-08", "unpreconditioned"], out.stdout


@pytest.mark.slow
def test_compare_table_and_plot(tiny_ckpt, tmp_path):
    png = tmp_path / "sub" / "demo.png"
    code, out = run_example("-n", 1024, "-compare", "-plot", png, "-htp_checkpoint", tiny_ckpt)
    assert code == 0, out
    assert field(out, "method").startswith("cg_htp")
    table = out[out.index("comparison on N=1024"):]
    for method in METHODS:
        row = re.search(rf"^{method} +(\S+) +(\S+) +(\d+) +(\S+)", table, re.M)
        assert row, (method, table)
        assert row.group(4).startswith("CONVERGED_"), row.group(0)
    assert png.exists() and png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


@pytest.mark.slow
def test_help_lists_htp_options_with_defaults(tiny_ckpt):
    code, out = run_example("-n", 256, "-help", "-htp_checkpoint", tiny_ckpt, "-htp_probe", 2)
    assert code == 0, out
    assert re.search(r"-htp_probe <int> <now 2 : formerly -1>: random Rayleigh", out), out[-3000:]
    for name, default in (("checkpoint", str(checkpoint.DEFAULT)), ("device", "auto"), ("ordering", "auto"),
                          ("shift", "0.0"), ("threads", "1"), ("fallback", "none")):
        assert re.search(rf"-htp_{name} <\w+> <now .* : formerly {re.escape(default)}>: \S", out), (name, out[-3000:])


@pytest.mark.slow
def test_nonconvergence_exits_nonzero(tiny_ckpt):
    code, out = run_example("-options_file", "options/cg_none.opts", "-n", 1024, "-ksp_max_it", 5)
    assert code == 1
    assert field(out, "converged reason") == "DIVERGED_ITS"


def test_options_read_where_set_and_the_defaults_where_none_is():
    """HTPOptions.from_petsc: the defaults, one shared object, where no -<prefix>htp_ option is set (in any case, as
    PETSc matches names); the values set otherwise, validated."""
    from petsc4py import PETSc

    from petsc_htp.pcoptions import HTPOptions

    assert HTPOptions.from_petsc("po_") is HTPOptions.from_petsc("pq_") and HTPOptions.from_petsc("po_") == HTPOptions()
    db = PETSc.Options()
    db.setValue("-PO_htp_Leaf", 16)
    try:
        assert HTPOptions.from_petsc("po_").leaf == 16 and HTPOptions.from_petsc("pq_").leaf == 0
        db.setValue("-po_htp_leaf", 1)
        with pytest.raises(ValueError, match="leaf must be 0"):
            HTPOptions.from_petsc("po_")
    finally:
        db.delValue("-po_htp_leaf")
