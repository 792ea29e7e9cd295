"""Dirichlet rows whose couplings the other rows keep (PETSc's MatZeroRows, its DMDA tutorials): HTPPC preconditions
the operator without those columns and starts the solve on the known values there (real mpiexec)."""
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

CASE = Path(__file__).resolve().parent / "keptcolumns_case.py"
MPIEXEC = shutil.which("mpiexec", path=f"{Path(sys.executable).parent}:{__import__('os').environ.get('PATH', '')}")
pytestmark = pytest.mark.mpi


@pytest.mark.parametrize("ranks", [1, 2])
def test_matzerorows_dirichlet_rows_solve_as_matzerorowscolumns_ones(ranks):
    """On 1 and 2 ranks, under CG, GMRES, BiCG, PREONLY and right-preconditioned CGS (which mishandles a start: not
    started), by the whole-matrix factor and by the two-level method, the matrix MatZeroRows left (not symmetric)
    takes the iterations of the one MatZeroRowsColumns made and reaches its tolerance on the true residual, its error
    as small; M outside a KSPSolve is A^-1 with the factor (and its transpose A^-T), also after a solve that raised
    mid-way, the two-level M^T is M's adjoint; -ksp_view says what was done; new values keep the analysis; a
    preconditioner reused on new Dirichlet diagonals starts on them; a refused new operator leaves the previous M
    whole; MAT_SYMMETRIC kept through MatZeroRows does not hide those rows; an Amat other than the Pmat whose rows
    there hold just that diagonal is started too (also the MatZeroRows form beside the MatZeroRowsColumns one as
    Pmat, AIJ or BAIJ, whose rows are read in HTPPC's AIJ copy: no MatConvert in the solve), and one whose product
    raises leaves HTPPC usable; nothing lands in
    PETSc's garbage."""
    out = subprocess.run([MPIEXEC, "-n", str(ranks), sys.executable, str(CASE)], capture_output=True, text=True,
                         timeout=600)
    text = out.stdout + out.stderr
    assert out.returncode == 0, text
    assert "WARNING! There are options you set that were not used" not in text, text
    solves = {m[0]: (int(m[1]), int(m[2]), float(m[3]), float(m[4])) for m in
              re.findall(r"^solve (\S+) \S+ its (\d+) reason (-?\d+) relres (\S+) error (\S+)$", text, re.M)}
    assert len(solves) == 26, text
    for name, (its, reason, relres, error) in solves.items():
        assert reason > 0, name
        assert relres <= 1e-8 and error <= 1e-7, (name, relres, error)
        if name.startswith("rows_"):
            twin = solves["rowscols_" + name[5:]]
            assert abs(its - twin[0]) <= 1, (name, its, twin)
            assert error <= 2 * twin[3] + 1e-13, (name, error, twin)
    assert solves["rows_direct_cg"][0] <= 1 and 10 <= solves["rows_twolevel_cg"][0] <= 30, solves
    apply, transpose = map(float, re.search(r"^apply (\S+) transpose (\S+)$", text, re.M).groups())
    assert apply <= 1e-12 and transpose <= 1e-12, text
    assert float(re.search(r"^adjoint (\S+)$", text, re.M).group(1)) <= 1e-12, text
    assert ("188 row(s) hold just their diagonal (Dirichlet rows), other rows keep couplings to some of them "
            "(MatZeroRows)") in text
    again = re.search(r"^again its (\d+) reason (\d+) error (\S+) analyses (\d+) numeric (\d+)$", text, re.M)
    assert again and float(again.group(3)) <= 1e-7 and again.group(4, 5) == ("1", "2"), text
    reused = re.search(r"^reused its (\d+) reason (\d+) error (\S+)$", text, re.M)
    assert reused and int(reused.group(1)) <= 25 and float(reused.group(3)) <= 1e-7, text
    assert float(re.search(r"^after abort (\S+)$", text, re.M).group(1)) <= 1e-12, text
    assert float(re.search(r"^refused yes, previous M (\S+)$", text, re.M).group(1)) <= 1e-12, text
    assert re.findall(r"Total entries: (\d+)", text) == ["0"] * ranks, text
    pmat = re.findall(r"^pmat (\S+) its (\d+) reason (\d+) error (\S+) copies (\d+)$", text, re.M)
    assert [m[0] for m in pmat] == ["amatcopy", "amatsym", "pmatsym", "pmatbaij"], text
    assert all(int(m[1]) <= 25 and float(m[3]) <= 1e-7 and m[4] == "0" for m in pmat), pmat
    failing = re.search(r"^after a failing Amat its (\d+) reason (\d+) PCApply (\S+)$", text, re.M)
    assert failing and int(failing.group(1)) <= 25 and float(failing.group(3)) <= 1.0, text


@pytest.mark.parametrize("ranks", [1, 2])
def test_pipecg_on_ex45_takes_the_balanced_form_under_coarse_v_cycles(ranks):
    """PETSc's ksp ex45 system at 49^3 (its solution 1 on the Dirichlet rows, smooth inside) under the two-level
    method (the coarse solve two GAMG V-cycles): CG keeps the deflated form, PIPECG, which stalled there (relative
    residual 2e-3 at 200 iterations), takes the balanced one; as it comes HTPPC takes the multilevel V-cycles
    there (a 3-D graph without positive couplings); each reaches rtol 1e-8 in the true residual within 25
    iterations."""
    for opts, forms in (("-htp_variant twolevel", ("deflated", "balanced")), ("", ("vcycles", "vcycles"))):
        out = subprocess.run([MPIEXEC, "-n", str(ranks), sys.executable, str(CASE.parent / "pipelined_case.py"), "49",
                              *opts.split()], capture_output=True, text=True, timeout=600)
        text = out.stdout + out.stderr
        assert out.returncode == 0, text
        runs = {m[0]: (int(m[1]), int(m[2]), float(m[3]), m[4]) for m in
                re.findall(r"^(\w+) its (\d+) reason (-?\d+) relres (\S+) form (\w+)$", text, re.M)}
        assert set(runs) == {"cg", "pipecg"}, text
        assert (runs["cg"][3], runs["pipecg"][3]) == forms, runs
        assert all(its <= 25 and reason > 0 and relres <= 1e-8 for its, reason, relres, _ in runs.values()), runs
