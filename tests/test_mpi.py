"""Block Jacobi over MPI ranks with HTP on each rank's block (real mpiexec)."""
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

import petsc4py  # noqa: F401  (a missing PETSc fails here, never skips)


ROOT = Path(__file__).resolve().parent.parent
EXAMPLE = ROOT / "examples" / "poisson_multiphase.py"
MPIEXEC = shutil.which("mpiexec", path=f"{Path(sys.executable).parent}:{__import__('os').environ.get('PATH', '')}")

pytestmark = [pytest.mark.mpi, pytest.mark.slow]
assert MPIEXEC, "mpiexec not found (the Makefile installs MPICH)"



def mpirun(*args, n=2, timeout=300):
    out = subprocess.run([MPIEXEC, "-n", str(n), sys.executable, str(EXAMPLE), *map(str, args)],
                         cwd=ROOT, capture_output=True, text=True, timeout=timeout)
    return out.returncode, out.stdout + out.stderr


def test_bjacobi_paper_on_two_ranks(tiny_ckpt):
    code, out = mpirun("-options_file", "options/bjacobi_paper.opts", "-n", 2048,
                       "-sub_htp_checkpoint", tiny_ckpt, "-ksp_view")
    assert code == 0, out
    assert "ranks=2" in out
    assert re.search(r"^converged reason: CONVERGED_RTOL$", out, re.M), out
    relres = float(re.search(r"\|\| / \|\|b\|\|: (\S+)", out).group(1))
    assert relres <= 1.01e-8
    # each rank's diagonal block (1024 rows, coordinates attached) is preconditioned by HTP
    assert "number of blocks = 2" in out
    assert "HTPPC, variant paper: the paper's Hierarchical Transformer Preconditioner" in out
    assert "N=1024, L=128, K=8 leaves" in out
    assert "ordering: morton (given)" in out


def test_parallel_matrix_without_bjacobi_is_a_clear_error(tiny_ckpt):
    code, out = mpirun("-options_file", "options/cg_paper.opts", "-n", 1024, "-htp_checkpoint", tiny_ckpt)
    assert code != 0
    assert "-pc_type bjacobi -sub_pc_type python -sub_pc_python_type petsc_htp.HTPPC" in out


def test_twolevel_coarse_space_is_global_across_ranks():
    """The PETSc-parts two-level variant on 2 ranks takes the 1-rank iterations (within 10 %)."""
    its, size = {}, {}
    for ranks in (1, 2):
        code, out = mpirun("-options_file", "options/cg_twolevel_eig.opts", "-n", 4096, "-ksp_view", n=ranks)
        assert code == 0, out
        assert re.search(r"^converged reason: CONVERGED_RTOL$", out, re.M), out
        assert "32 in all" in out                                   # 32 leaves over all ranks, one coarse space
        size[ranks] = int(re.search(r"global size (\d+)", out).group(1))
        its[ranks] = int(re.search(r"^iterations: (\d+)$", out, re.M).group(1))
    assert abs(its[2] - its[1]) <= 0.1 * its[1], its
    assert size[1] == size[2] >= 32 * 4 - 1, size                  # the same leaves keep the same vectors


def test_gamg_coarse_solver_on_two_ranks():
    """-htp_coarse_solver gamg: the coarse operator, distributed, gets GAMG on both ranks (in 2-D two V-cycles an
    application; the const space, as in 3-D, where the GAMG coarse solve is the default)."""
    its = {}
    for solver in ("lu", "gamg"):
        code, out = mpirun("-options_file", "options/cg_htp.opts", "-n", 4096, "-htp_coarse", "const",
                           "-htp_coarse_solver", solver, "-ksp_view")
        assert code == 0, out
        assert re.search(r"^converged reason: CONVERGED_RTOL$", out, re.M), out
        its[solver] = int(re.search(r"^iterations: (\d+)$", out, re.M).group(1))
    assert "coarse solve: two GAMG V-cycles" in out
    assert its["lu"] <= its["gamg"] <= its["lu"] + 6, its


def test_3d_bench_on_two_ranks(tmp_path):
    """``mpiexec -n 2 petsc-htp bench --dim 3``: PETSc methods on both ranks, pyamg and AMGCL on rank 0, one
    results folder, peak RSS on every row."""
    import json
    import os

    out = tmp_path / "bench"
    env = {**os.environ, "PETSC_HTP_CACHE": str(tmp_path / "cache"), "OMP_NUM_THREADS": "1"}
    run = subprocess.run([MPIEXEC, "-n", "2", sys.executable, "-m", "petsc_htp.bench", "--quick", "--dim", "3",
                          "--studies", "table", "sequence", "--methods", "cg_htp", "cg_gamg", "cg_icc",
                          "cg_bjacobi_icc", "pyamg", "amgcl", "--scales", "4096", "--frames", "1", "--seq-scales",
                          "4096", "--seq-frames", "2", "--no-progress", "--out", str(out)],
                         cwd=ROOT, env=env, capture_output=True, text=True, timeout=600)
    assert run.returncode == 0, run.stdout + run.stderr
    meta = json.loads((out / "meta.json").read_text())
    assert meta["threads"]["MPI ranks"] == 2 and meta["dim"] == 3
    rows = [json.loads(line) for name in ("table", "sequence") for line in (out / f"{name}.jsonl").open()]
    frames = [r for r in rows if r.get("kind", "frame") == "frame"]
    ok = {r["method"] for r in frames if r["ok"]}
    assert ok >= {"cg_htp", "cg_gamg", "cg_bjacobi_icc", "pyamg"}, frames
    assert not any(r["ok"] for r in frames if r["method"] == "cg_icc")          # PETSc has no parallel ICC
    assert all(r["peak_rss_mb"] > 0 for r in frames)
    htp = [r for r in frames if r["method"] == "cg_htp"]
    assert all(r["iterations"] <= 40 and r["relres"] <= 1.01e-8 for r in htp), htp
    report = (out / "report.md").read_text()
    assert "**2 MPI ranks**" in report and "**3-D scenes**" in report and "Peak RSS" in report


@pytest.mark.parametrize("ranks", [2, 3])
def test_components_across_ranks_are_the_whole_matrix_components(ranks):
    """The two-level analysis on several ranks finds each rank's own components, then joins them by the couplings
    between ranks alone (no rank gathers the graph): the partition is scipy's on the whole matrix, with chains across
    a rank boundary and a coupling between the first and the last rank (tests/components_case.py)."""
    out = subprocess.run([MPIEXEC, "-n", str(ranks), sys.executable, str(ROOT / "tests" / "components_case.py")],
                         cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stdout + out.stderr
    assert f"components ok on {ranks} ranks" in out.stdout


def test_a_randomly_ordered_matrix_on_two_ranks_keeps_a_sparse_coarse_operator():
    """Rows in a random order split into contiguous blocks: most rows couple to the other rank and many stand alone
    in their rank's block, in leaves of one piece per row. Each row of W holds its own piece's column only, so the
    coarse operator stays as sparse as A (it had about 80 entries per row, and a P1 triangle mesh of 65 536 rows
    took 18 s on two ranks against 0.4 s now; tests/shuffled_case.py)."""
    out = subprocess.run([MPIEXEC, "-n", "2", sys.executable, str(ROOT / "tests" / "shuffled_case.py")],
                         cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stdout + out.stderr
    assert "shuffled ok" in out.stdout


def test_pattern_splits_its_entries_like_petsc_coo_on_two_ranks():
    """O's and W's matrix on two ranks is an MPIAIJ on its own diagonal and off-diagonal arrays (a rank with none
    off its diagonal block included): values, products and frames as PETSc's COO assembly gives them."""
    out = subprocess.run([MPIEXEC, "-n", "2", sys.executable, str(ROOT / "tests" / "pattern_case.py")],
                         cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stdout + out.stderr
    assert "pattern ok on 2 ranks" in out.stdout


def test_dominance_lost_on_one_rank_makes_a_new_analysis_on_all():
    """A diagonally dominant matrix on two ranks takes ICC(0) of each rank's block; new values that lose the dominance
    on one rank only make a new analysis on both (the two-level method), whose solve converges
    (tests/dominance_case.py)."""
    out = subprocess.run([MPIEXEC, "-n", "2", sys.executable, str(ROOT / "tests" / "dominance_case.py")],
                         cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stdout + out.stderr
    assert "dominance ok on 2 ranks" in out.stdout
