"""Tests for the torch-only fast-path PCG (CUDA Graph replay on GPU, eager on CPU)."""
import json
import subprocess
import sys

import numpy as np
import pytest
import scipy.sparse as sp
import torch

from petsc_htp.fastpath import (
    METHODS,
    GraphPCG,
    Preconditioner,
    apply_microbench,
    capture_inference,
    main,
    make_preconditioner,
    run_fastpath,
)
from petsc_htp.paper.inference import HTP
from petsc_htp.paper.model import HTPConfig, HTPNet
from petsc_htp.training.pcg import jacobi, pcg
from petsc_htp.scenes.generator import make_frame

requires_cuda = pytest.mark.skipif(not torch.cuda.is_available(), reason="needs a CUDA device")
SIZES = (256, 300)   # a multiple of the 128 block and one that is not


@pytest.fixture(scope="module", autouse=True)
def one_thread():
    """The kernels are tiny: one thread is fastest and immune to a busy machine."""
    old = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(old)


@pytest.fixture(scope="module")
def frames():
    return {n: make_frame(n, seed=0) for n in SIZES}


@pytest.fixture(scope="module")
def references(frames):
    """Minimum-norm (hence mean-zero) float64 solutions."""
    return {n: np.linalg.lstsq(f.A.toarray(), f.b, rcond=None)[0] for n, f in frames.items()}


def small_htp(device):
    torch.manual_seed(0)
    return HTP(HTPNet(HTPConfig(d=32, n_layers=1, leaf=32, p_off=4, heads=4)), device=device)


@pytest.fixture(scope="module")
def htp():
    return small_htp("cpu")


def solve(method, frame, htp=None, device="cpu", **kw):
    pc = make_preconditioner(method, frame.A, htp, frame.coords, frame.rho, device=device)
    return GraphPCG(frame.A, pc, **kw).solve(frame.b)


class Scaled(Preconditioner):
    """z = s r, for breakdown tests."""

    def __init__(self, A, s):
        super().__init__(A, device="cpu")
        self.s = s

    def apply_(self, r, z):
        torch.mul(r, self.s, out=z)


@pytest.mark.parametrize("n", SIZES)
@pytest.mark.parametrize("method", METHODS)
def test_converges_to_reference_solution(method, n, frames, references, htp):
    f, ref = frames[n], references[n]
    res = solve(method, f, htp)
    assert res.reason == "converged" and res.iterations > 0 and not res.graphed
    assert res.history[-1] <= 1e-8 * res.history[0]
    if method == "bjacobi" or method.startswith("twolevel"):   # not the identity: fewer iterations
        assert res.iterations < solve("jacobi", f).iterations
    # x is float32 inside: ||A dx|| ~ eps ||A|| ||x|| bounds the true residual near 1e-5.
    assert np.linalg.norm(f.A @ res.x - f.b) <= 1e-4 * np.linalg.norm(f.b)
    x = res.x - res.x.mean()
    assert np.linalg.norm(x - ref) <= 1e-5 * np.linalg.norm(ref)


@pytest.mark.parametrize("n", SIZES)
def test_jacobi_iterations_match_float64_pcg(n, frames):
    f = frames[n]
    assert abs(solve("jacobi", f).iterations - pcg(f.A, f.b, jacobi(f.A)).iterations) <= 2


@pytest.mark.parametrize("n", SIZES)
def test_unpreconditioned_iterations_match_float64_pcg(n, frames):
    # On the raw frame float32 vectors lose orthogonality (~20% more iterations, as a
    # float32 NumPy CG does too); on the diagonally scaled, shifted operator they do not.
    f = frames[n]
    half = sp.diags(f.A.diagonal() ** -0.5)
    A = (half @ f.A @ half + 0.01 * sp.identity(n)).tocsr()
    b = half @ f.b
    res = GraphPCG(A, make_preconditioner("none", A, device="cpu")).solve(b)
    assert res.reason == "converged"
    assert abs(res.iterations - pcg(A, b).iterations) <= 2


def test_check_every_keeps_iterations_exact(frames):
    f = frames[300]
    runs = [solve("jacobi", f, check_every=k) for k in (1, 5, 8)]
    assert runs[0].iterations == runs[1].iterations == runs[2].iterations
    assert runs[0].iterations % 8 and runs[0].iterations % 5   # not rounded up to a check
    for other in runs[1:]:
        np.testing.assert_array_equal(other.x, runs[0].x)
    assert len(runs[2].history) == -(-runs[2].iterations // 8) + 1


def test_maxiter_stops_exactly(frames):
    f = frames[300]
    cut = solve("jacobi", f, check_every=8, maxiter=13)
    step = solve("jacobi", f, check_every=1, maxiter=13)
    assert (cut.reason, cut.iterations) == ("max_it", 13)
    np.testing.assert_array_equal(cut.x, step.x)


def test_block_jacobi_beats_jacobi(frames):
    for f in frames.values():
        assert solve("bjacobi", f).iterations < solve("jacobi", f).iterations


@pytest.mark.parametrize("n", [64, 100])
def test_block_jacobi_single_singular_block(n):
    f = make_frame(n, seed=0)
    res = solve("bjacobi", f)
    assert res.reason == "converged" and res.iterations <= 3   # exact on mean-zero vectors


@pytest.mark.parametrize("s, reason", [(-1.0, "indefinite_pc"), (float("nan"), "nan")])
def test_breakdown_is_reported(s, reason, frames):
    f = frames[300]
    res = GraphPCG(f.A, Scaled(f.A, s)).solve(f.b)
    assert (res.reason, res.iterations) == (reason, 0)
    assert np.all(res.x == 0)


def test_solver_refreshes_for_a_new_frame(htp):
    f0, f1 = make_frame(300, seed=0), make_frame(300, seed=1)
    for method in ("bjacobi", "htp"):
        pc = make_preconditioner(method, f0.A, htp, f0.coords, f0.rho, device="cpu")
        solver = GraphPCG(f0.A, pc)
        solver.solve(f0.b)
        csr = solver.A
        pc.setup(f1.A, f1.coords, f1.rho)
        solver.set_matrix(f1.A)
        assert solver.A is csr   # same pattern: values copied into the bound buffers
        again, fresh = solver.solve(f1.b), solve(method, f1, htp)
        assert again.iterations == fresh.iterations
        np.testing.assert_allclose(again.x, fresh.x, rtol=0, atol=1e-6 * np.abs(fresh.x).max())


def test_inference_refresh_matches_setup(htp):
    f0, f1 = make_frame(300, seed=0), make_frame(300, seed=1)
    infer = capture_inference(htp, f0.A, f0.coords, f0.rho)
    packed = infer(f1.A, f1.rho)
    ref = htp.setup(f1.A, f1.coords, f1.rho)
    assert not infer.graphed
    np.testing.assert_array_equal(infer.perm, ref.perm)
    torch.testing.assert_close(packed, ref.op.packed, rtol=1e-5, atol=1e-6)


class Ticking(Preconditioner):
    """z = r, each apply moving the fast path's clock on by ``ms`` (a counted clock, not the wall)."""

    def __init__(self, A, ms):
        super().__init__(A, device="cpu")
        self.ms, self.calls, self.now = ms, 0, 0.0

    def clock(self):
        return self.now

    def apply_(self, r, z):
        self.calls += 1
        self.now += self.ms / 1e3
        z.copy_(r)


def test_apply_microbench_times_one_apply(frames, monkeypatch):
    import petsc_htp.fastpath.timing as timing

    pc = Ticking(frames[256].A, 5.0)
    monkeypatch.setattr(timing.time, "perf_counter", pc.clock)
    us = apply_microbench(pc, n_apply=5)
    assert pc.calls == 6                   # one warm-up, then the five timed applies
    assert us == pytest.approx(5000.0)     # per apply, not the total of five (25 ms)


def test_run_fastpath_rows(htp):
    frames = [make_frame(300, seed=s) for s in (0, 1)]
    rows = run_fastpath(frames, METHODS + ("bogus",), htp=htp, device="cpu")
    assert len(rows) == 2 * (len(METHODS) + 1)
    for seed in (0, 1):
        got = {r["method"]: r for r in rows if r["seed"] == seed}
        assert set(got) == set(METHODS) | {"bogus"}
        for m in METHODS:
            r = got[m]
            assert r["reason"] == "converged" and r["iterations"] > 0, r
            assert r["total_ms"] == pytest.approx(r["setup_ms"] + r["solve_ms"])
            assert (r["device"], r["torch"], r["n"], r["graphed"]) == ("cpu", torch.__version__, 300, False)
        assert got["htp"]["inference_graphed"] is False
        assert got["twolevel_eig"]["iterations"] < got["jacobi"]["iterations"]
        assert got["bogus"]["reason"].startswith("error: ValueError")
    missing = run_fastpath(frames[:1], ("jacobi", "htp"), htp=None, device="cpu")
    assert missing[0]["reason"] == "converged" and missing[1]["reason"].startswith("error:")


def test_main_writes_jsonl_and_skips_a_missing_checkpoint(tmp_path, capsys):
    out = tmp_path / "rows.jsonl"
    assert main(["--n", "200", "--frames", "1", "--methods", "jacobi", "htp", "--device", "cpu",
                 "--checkpoint", str(tmp_path / "missing.pt"), "--out", str(out)]) == 0
    rows = [json.loads(line) for line in out.read_text().splitlines()]
    assert [(r["method"], r["n"], r["reason"]) for r in rows] == [("jacobi", 200, "converged")]
    assert "skipping htp" in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == [out]   # no temporary file left behind


@pytest.mark.slow
def test_imports_without_petsc():
    code = "import sys, petsc_htp.fastpath; sys.exit('petsc4py' in sys.modules)"
    assert subprocess.run([sys.executable, "-c", code]).returncode == 0


@requires_cuda
@pytest.mark.parametrize("method", METHODS)
def test_graph_replay_matches_eager(method):
    f = make_frame(300, seed=0)
    htp = small_htp("cuda") if method == "htp" else None
    pc = make_preconditioner(method, f.A, htp, f.coords, f.rho, device="cuda")
    eager = GraphPCG(f.A, pc, use_graph=False).solve(f.b)
    graph = GraphPCG(f.A, pc).solve(f.b)
    assert graph.graphed and not eager.graphed
    assert graph.reason == eager.reason == "converged"
    assert graph.iterations == eager.iterations
    assert np.linalg.norm(graph.x - eager.x) <= 1e-6 * np.linalg.norm(eager.x)


@requires_cuda
def test_inference_graph_matches_eager_forward():
    htp = small_htp("cuda")
    f0, f1 = make_frame(300, seed=0), make_frame(300, seed=1)
    infer = capture_inference(htp, f0.A, f0.coords, f0.rho)
    assert infer.graphed and infer.error is None, infer.error
    packed = infer(f1.A, f1.rho)
    torch.testing.assert_close(packed, htp.setup(f1.A, f1.coords, f1.rho).op.packed, rtol=1e-4, atol=1e-5)


@pytest.mark.parametrize("method", ["twolevel_eig", "twolevel_const"])
def test_twolevel_fastpath_matches_the_pc_and_refreshes_in_place(method):
    from petsc_htp.fastpath.preconditioners import SETTINGS, make_preconditioner
    from petsc_htp.twolevel.leaves import choose_leaves
    from petsc_htp.twolevel.batched import analyse, factor

    f0, f1 = make_frame(1024, seed=1), make_frame(1024, seed=2)
    pc = make_preconditioner(method, f0.A, coords=f0.coords, device="cpu")
    pc.setup()
    op = pc.op
    pc.setup(f1.A, f1.coords)                         # same pattern: factors land in the same buffers
    assert pc.op is op
    coarse = method.split("_")[1]
    leaf, rank = SETTINGS[coarse]
    ref = factor(analyse(f1.A, choose_leaves(f1.A, f1.coords, leaf=leaf)), f1.A, coarse, rank)
    r = torch.randn(1024, dtype=torch.float32)
    z = torch.empty_like(r)
    pc.apply_(r[pc.perm], z)
    expect = ref.apply(r.double().numpy())[pc.perm]
    np.testing.assert_allclose(z.numpy(), expect, rtol=1e-4, atol=1e-4 * np.abs(expect).max())
    res = GraphPCG(f1.A, pc, "cpu", 8, 1e-8, 500).solve(f1.b)
    assert res.reason == "converged" and res.iterations <= {"eig": 35, "const": 50}[coarse]


def test_dense_coarse_limit_on_the_cpu(monkeypatch):
    from petsc_htp.twolevel import batched
    from petsc_htp.twolevel.leaves import choose_leaves

    assert batched.max_coarse(torch.device("cpu")) == batched.MAX_COARSE == 8192
    f = make_frame(1024, seed=0)
    analysis = batched.analyse(f.A, choose_leaves(f.A, f.coords, leaf=16))
    monkeypatch.setattr(batched, "MAX_COARSE", 32)
    with pytest.raises(ValueError, match="coarse size K r = 64 x 1 exceeds 32"):
        batched.factor(analysis, f.A, "const")


@requires_cuda
def test_twolevel_on_the_gpu_past_the_cpu_coarse_limit():
    from petsc_htp.twolevel.batched import MAX_COARSE, max_coarse

    assert max_coarse(torch.device("cuda")) > 2 * MAX_COARSE
    f = make_frame(384 * 384, seed=0)                 # 9 216 leaves of 16 rows: a coarse operator past 8 192
    res = solve("twolevel_const", f, device="cuda")
    assert res.reason == "converged" and res.iterations <= 40
