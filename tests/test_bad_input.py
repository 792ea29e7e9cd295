"""Bad input to HTPPC on 1 and 2 MPI ranks (3 for a rank coupled to no other): each case ends in a named error or a correct solve, on every rank.

The cases live in ``tests/bad_input_cases.py``, run under real ``mpiexec`` with a timeout (a hang fails).
"""
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

import petsc4py  # noqa: F401  (a missing PETSc fails here, never skips)

HERE = Path(__file__).resolve().parent
MPIEXEC = shutil.which("mpiexec", path=f"{Path(sys.executable).parent}:{__import__('os').environ.get('PATH', '')}")
TIMEOUT = 300
CONVERGED = r"converged \d+ (\d\.\de[-+]\d\d) (\d+) (\d+)"

INCONSISTENT = (r"error: the matrix is singular \(its row sums vanish on 1 connected component\(s\), and no "
                r"MatNullSpace is attached\) and the right-hand side is not in its range: its part along those "
                r"components' constants is \d\.\de-\d\d of its norm, above the KSP's tolerance \(rtol 1e-08, "
                r"atol 1e-50\), .*")
# case -> expected outcome (a regex matched against the whole line) on 1 rank and on 2 ranks
EXPECTED = {
    "nan": r"error: the matrix has NaN or Inf entries in 1 row\(s\), the first global row 1023;.*",
    "inf": r"error: the matrix has NaN or Inf entries in 1 row\(s\), the first global row 1023;.*",
    "empty_row": r"error: the matrix has empty rows in 1 row\(s\), the first global row 1023;.*",
    "zero_diagonal": r"error: the matrix has missing or zero diagonal entries in 1 row\(s\), the first global row 1022;.*",
    "negative_diagonal": r"error: the matrix has negative diagonal entries in 1 row\(s\), the first global row 1022;.*",
    "nonsymmetric": r"error: the matrix is not symmetric \(random probe .*MAT_SYMMETRIC.*",
    "indefinite": {1: r"error: HTPPC needs a symmetric positive \(semi\)definite matrix, but its (banded )?Cholesky "
                      r"factor has (\d+ negative pivot\(s\)|a negative pivot) in 1024 rows: the matrix is "
                      r"indefinite",      # one factor: its inertia
                   2: r"diverged DIVERGED_INDEFINITE_(MAT|PC)"},
    "indefinite_rich": r"diverged DIVERGED_INDEFINITE_(MAT|PC)",          # ICC(0) on one rank: CG names it
    "decoupled_rank": CONVERGED,
    "nonsquare": r"error: HTPPC needs a square matrix, got 1024 x 1025 \(non-square\)",
    "empty_matrix": r"error: HTPPC got an empty matrix \(1024 x 1024 with no nonzeros\)",
    "rank_without_rows": CONVERGED,                    # on 2 ranks one factor of the whole matrix, gathered
    "rank_without_rows_large": CONVERGED,               # on 2 ranks HTPPC on the one that owns rows (PCTELESCOPE)
    "rank_without_rows_twolevel": {1: CONVERGED + r" twolevel", 2: CONVERGED + r" telescope"},
    "rank_without_rows_indefinite": (r"error: HTPPC needs a symmetric positive \(semi\)definite matrix, but its "
                                     r"banded Cholesky factor has a negative pivot in 9216 rows: the matrix is "
                                     r"indefinite"),      # on 2 ranks from the rank that owns the rows, on both
    "fewer_rows_than_ranks": CONVERGED,
    "explicit_zeros": CONVERGED,
    "null_components_attached": CONVERGED,
    "null_components_detected": CONVERGED,
    "pattern_change": CONVERGED,
    "values_only": CONVERGED,
    "rescaled_values": CONVERGED,
    "chain": CONVERGED,
    "tiny_entries": CONVERGED,
    "penalty_rows": CONVERGED,
    "singular_scaled": CONVERGED,
    "null_vector_attached": CONVERGED,
    "inconsistent_factor": INCONSISTENT,
    "inconsistent_twolevel": INCONSISTENT,
    "inconsistent_multilevel": INCONSISTENT,
    "inconsistent_multilevel_components": INCONSISTENT,
    "shifted_to_rounding": INCONSISTENT[:-2] + r".*\(rows that sum to at most 1e-12 of their entries count as summing "
                                                r"to zero: .*",
    "vector_layout": {1: r"error: the right-hand side vector's layout differs from the matrix's on 1 rank\(s\) \(rank 0: "
                         r"1029 local entries against 1024 rows\): make the vectors with Mat.createVecs\(\)",
                      2: r"error: the right-hand side vector's layout differs from the matrix's on 2 rank\(s\) \(rank 0: "
                         r"517 local entries against 512 rows\): make the vectors with Mat.createVecs\(\)"},
    "singular_then_regular": CONVERGED,
    "inconsistent_then_attached": CONVERGED,
    "inconsistent_three_times": CONVERGED,
    "gathered_lu_asked": CONVERGED,
    "dirichlet_columns": CONVERGED,
    "inconsistent_components": (r"error: the matrix is singular \(its row sums vanish on 3 connected component\(s\), "
                                r"and no MatNullSpace is attached\) .* attach the null space \(Mat.setNullSpace\("
                                r"NullSpace\(\).create\(vectors=...\)\) with 3 orthonormal vectors, each constant on "
                                r"one component and zero elsewhere: the constant alone is not its null space, .*"),
    "coordinates_on_some_ranks": {1: CONVERGED,
                                  2: r"error: coordinates are attached on 1 of the 2 ranks only: call petsc_htp.attach "
                                     r"on every rank of a parallel matrix"},
    "shuffled_coordinates": (r"converged \d+ \d\.\de-(09|1\d) 1 1; coordinates ignored: coupled rows lie "
                             r"\d\.\d\d as far apart in them as rows at random \(medians\), so they do not follow "
                             r"the rows; the leaves come from the matrix"),
    "null_space_split": {1: CONVERGED,
                         2: r"error: the matrix's attached null space or near null space holds vectors whose "
                            r"entries are split over the ranks unlike the matrix's rows \(2 local part\(s\) differ\); "
                            r"make them with Mat.createVecRight\(\)"},
    "singular_pmat": CONVERGED,
    "singular_pmat_multilevel": CONVERGED,
    "second_set_from_options": CONVERGED,
    "jumps3d": CONVERGED,
    "loose_coarse_cycles": CONVERGED,
    "penalty_rows_last": CONVERGED,
    "missing_checkpoint": r"error: checkpoint /nonexistent/model.pt does not exist or cannot be read",
    "corrupt_checkpoint": r"error: petsc_htp checkpoint .*corrupt.pt is corrupt or unreadable: torch.load failed.*",
    "unknown_form": r"error: -htp_form 'banana' unknown; use one of auto, deflated, balanced",
    "unknown_coarse": r"error: -htp_coarse 'fancy' unknown; use one of auto, const, eig, learned",
    "unknown_coarse_solver": r"error: -htp_coarse_solver 'mumps' unknown; use one of auto, lu, gamg",
    "unknown_aggregation": r"error: -htp_aggregation 'triples' unknown; use one of auto, standard, pairs",
}
# setups after the case's last solve: (analyses, numeric steps) of the one PC it reused
SETUPS = {"pattern_change": ("2", "2"), "values_only": ("1", "2"), "rescaled_values": ("1", "3"),
          "singular_then_regular": ("1", "2")}
# the most iterations a converged case may take (none: no bound)
MAX_ITS = {"rescaled_values": 40, "chain": 40, "tiny_entries": 40, "penalty_rows": 40, "jumps3d": 40,
           "null_vector_attached": 40, "loose_coarse_cycles": 120,
           "penalty_rows_last": 40}

pytestmark = [pytest.mark.mpi, pytest.mark.slow]
assert MPIEXEC, "mpiexec not found (the Makefile installs MPICH)"


def run_cases(python, script, n, workdir, cwd=None, cases=()) -> dict:
    """{(case, rank): outcome} of one run of ``cases`` (default: every case) of ``script`` by ``python`` on ``n``
    ranks."""
    proc = subprocess.run([MPIEXEC, "-n", str(n), str(python), str(script), str(workdir), *cases],
                          capture_output=True, text=True, timeout=TIMEOUT, cwd=cwd)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    # ranks print whole lines, but two ranks' lines may meet without a newline between them
    found = re.findall(r"CASE (\w+) rank (\d+): (.*?)\s*(?=CASE |\Z)", proc.stdout, re.S)
    got = {(case, int(rank)): text for case, rank, text in found}
    assert len(got) == len(found), "a case printed twice"
    return got


def check_outcome(got, n, case, expected=EXPECTED):
    """The case ended as ``expected`` says on every one of the ``n`` ranks, alike."""
    want = expected[case] if isinstance(expected[case], str) else expected[case][n]
    texts = [got[(case, r)] for r in range(n)]
    for r, text in enumerate(texts):
        assert re.fullmatch(want, text), (case, r, text)
    assert len(set(texts)) == 1, texts                    # every rank tells the same story
    if want == CONVERGED:
        its = int(texts[0].split()[1])
        assert its <= MAX_ITS.get(case, its), (case, its)
        relres, analyses, numeric = re.fullmatch(CONVERGED, texts[0]).groups()
        assert float(relres) <= 1.01e-8                   # the true residual, null space removed
        assert (analyses, numeric) == SETUPS.get(case, ("1", "1"))


@pytest.fixture(scope="module", params=[1, 2])
def outcomes(request, tmp_path_factory):
    """{(case, rank): outcome} of one run of every case on ``n`` ranks, and ``n``."""
    n = request.param
    return run_cases(sys.executable, HERE / "bad_input_cases.py", n, tmp_path_factory.mktemp(f"bad{n}")), n


def test_at_least_15_cases_each_on_every_rank(outcomes):
    got, n = outcomes
    assert len(EXPECTED) >= 15
    assert set(got) == {(case, r) for case in EXPECTED for r in range(n)}


@pytest.mark.parametrize("case", sorted(EXPECTED))
def test_outcome(outcomes, case):
    got, n = outcomes
    check_outcome(got, n, case)


def test_rank_without_couplings_to_others(tmp_path):
    """3 ranks, the last one's rows decoupled from the rest: the analysis's collectives run on every rank (a
    rank that skipped the ghost scatter used to hang the others)."""
    got = run_cases(sys.executable, HERE / "bad_input_cases.py", 3, tmp_path, cases=["decoupled_rank"])
    check_outcome(got, 3, "decoupled_rank", {"decoupled_rank": CONVERGED})


def test_ranks_without_rows_on_three_ranks(tmp_path):
    """3 ranks, the first owning every row: HTPPC on the subcommunicator PCTELESCOPE makes converges, and its setup's
    error reaches the two ranks outside it (they had gone on into the solve and hung)."""
    cases = ["rank_without_rows_twolevel", "rank_without_rows_indefinite"]
    got = run_cases(sys.executable, HERE / "bad_input_cases.py", 3, tmp_path, cases=cases)
    check_outcome(got, 3, cases[0], {cases[0]: CONVERGED + r" telescope"})
    check_outcome(got, 3, cases[1])
