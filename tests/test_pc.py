"""HTPPC inside real PETSc KSPs (petsc4py, no mocks)."""
import itertools
import re
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
import pytest
import scipy.sparse as sp

import petsc4py  # noqa: E402  (a missing PETSc fails here, never skips)
from petsc4py import PETSc  # noqa: E402

import petsc_htp  # noqa: E402
from petsc_htp.training import checkpoint  # noqa: E402
from petsc_htp.paper.model import HTPConfig, HTPNet  # noqa: E402
from petsc_htp.scenes.dataset import TEST_SEED_OFFSET  # noqa: E402
from petsc_htp.bench.harness import reason_name  # noqa: E402
from petsc_htp.petscmat import frame_mat as _frame_mat  # noqa: E402
from petsc_htp.scenes.generator import make_frame  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
EXAMPLE = ROOT / "examples" / "poisson_multiphase.py"
_PREFIXES = itertools.count()


# ------------------------------------------------------------------ fixtures

@pytest.fixture(scope="session")
def nan_ckpt(tmp_path_factory):
    """A checkpoint whose weights are all NaN."""
    import torch
    net = HTPNet(HTPConfig(d=32, n_layers=1, heads=4))
    with torch.no_grad():
        for p in net.parameters():
            p.fill_(float("nan"))
    path = tmp_path_factory.mktemp("ckpt") / "nan.pt"
    checkpoint.save(path, net, {"note": "NaN weights"})
    return path


@pytest.fixture(scope="session")
def indefinite_ckpt(tmp_path_factory):
    """A checkpoint whose off-diagonal factors are huge: M is symmetric but indefinite."""
    import torch
    torch.manual_seed(1)
    net = HTPNet(HTPConfig(d=32, n_layers=1, heads=4))
    with torch.no_grad():
        for head in (net.u_head, net.v_head, net.bridge_u, net.bridge_v):
            head.weight.mul_(300.0)
            head.bias.fill_(1.0)
    path = tmp_path_factory.mktemp("ckpt") / "indefinite.pt"
    checkpoint.save(path, net, {"note": "indefinite"})
    return path


@pytest.fixture(scope="module")
def frame():
    return make_frame(1024, seed=3)


@pytest.fixture
def options():
    """Set options under a fresh prefix; remove them after the test."""
    prefix = f"t{next(_PREFIXES)}_"
    db = PETSc.Options()
    names = []

    def put(**kw):
        for k, v in kw.items():
            db.setValue(prefix + k, v)
            names.append(prefix + k)
        return prefix

    yield put
    for name in names:
        db.delValue(name)


def make_ksp(A, prefix):
    ksp = PETSc.KSP().create(comm=A.getComm())
    ksp.setOptionsPrefix(prefix)
    ksp.setOperators(A, A)
    ksp.setFromOptions()
    return ksp


def htp_opts(ckpt, ksp="cg", **extra):
    """Options of HTPPC's paper variant (the network in ``ckpt``)."""
    base = dict(ksp_type=ksp, ksp_rtol=1e-8, ksp_norm_type="unpreconditioned", ksp_max_it=5000,
                pc_type="python", pc_python_type="petsc_htp.HTPPC", htp_variant="paper", htp_checkpoint=str(ckpt),
                htp_threads=1)   # one torch thread: no spin-waiting on a small, busy machine
    base.update(extra)
    return base


def solve(ksp, A, b_array):
    b = A.createVecs("left")
    b.setArray(b_array)
    x = b.duplicate()
    x.set(0.0)
    ksp.solve(b, x)
    r = b.duplicate()
    A.mult(x, r)
    r.aypx(-1.0, b)
    return ksp.getConvergedReason(), ksp.getIterationNumber(), r.norm() / b.norm()


def frame_mat(frame):
    A = _frame_mat(frame, PETSc.COMM_SELF)
    petsc_htp.attach(A, coords=frame.coords, density=frame.rho)
    return A


def error_text(excinfo):
    """The exception and its whole cause/context chain as one string."""
    out, exc = [], excinfo.value
    while exc is not None:
        out.append(f"{type(exc).__name__}: {exc}")
        exc = exc.__cause__ or exc.__context__
    return "\n".join(out)


# ------------------------------------------------------------- convergence

@pytest.mark.parametrize("ksp_type", ["cg", "gmres"])
def test_converges_with_cg_and_gmres(frame, tiny_ckpt, options, ksp_type):
    extra = {"ksp_pc_side": "right"} if ksp_type == "gmres" else {}
    prefix = options(**htp_opts(tiny_ckpt, ksp_type, **extra))
    A = frame_mat(frame)
    ksp = make_ksp(A, prefix)
    reason, its, relres = solve(ksp, A, frame.b)
    assert reason > 0, reason_name(reason)
    assert relres <= 1.01e-8
    assert 1 < its < 5000
    ctx = ksp.getPC().getPythonContext()
    assert isinstance(ctx, petsc_htp.HTPPC)
    assert ctx.setup.ordering == "morton (given)"


@pytest.mark.parametrize("ksp_type", ["cg", "fgmres"])
def test_shipped_checkpoint_beats_jacobi_on_held_out_frames(options, ksp_type):
    """CG, and flexible GMRES (a float32 M is not exactly linear, see options/gmres_paper.opts)."""
    krylov = {"ksp_type": ksp_type, "ksp_rtol": 1e-8, "ksp_norm_type": "unpreconditioned", "ksp_max_it": 20000}
    if ksp_type == "fgmres":
        krylov.update(ksp_pc_side="right", ksp_gmres_restart=100)
    for seed in (TEST_SEED_OFFSET, TEST_SEED_OFFSET + 1):
        fr = make_frame(1024, seed=seed)
        A = frame_mat(fr)
        its = {}
        for pc in ("jacobi", "htp"):
            extra = ({"pc_type": "python", "pc_python_type": "petsc_htp.HTPPC", "htp_threads": 1} if pc == "htp"
                     else {"pc_type": "jacobi"})
            reason, its[pc], relres = solve(make_ksp(A, options(**krylov, **extra)), A, fr.b)
            assert reason > 0 and relres <= 1.01e-8, (pc, reason_name(reason), relres)
        assert its["htp"] < its["jacobi"], (seed, its)


def test_matrix_without_attachments_uses_rcm(tiny_ckpt, options):
    side = 30                                    # N = 900: not a multiple of L = 128
    path = sp.diags([-np.ones(side - 1), 2 * np.ones(side), -np.ones(side - 1)], [-1, 0, 1])
    lap = (sp.kron(sp.identity(side), path) + sp.kron(path, sp.identity(side))).tocsr()
    rng = np.random.default_rng(0)
    shuffle = rng.permutation(side * side)       # scramble the natural order
    lap = lap[shuffle][:, shuffle].tocsr()
    A = PETSc.Mat().createAIJ(size=lap.shape, csr=(lap.indptr, lap.indices, lap.data), comm=PETSc.COMM_SELF)
    A.assemble()
    prefix = options(**htp_opts(tiny_ckpt))
    ksp = make_ksp(A, prefix)
    reason, its, relres = solve(ksp, A, rng.standard_normal(side * side))
    assert reason > 0 and relres <= 1.01e-8
    ctx = ksp.getPC().getPythonContext()
    assert ctx.setup.ordering == "rcm"
    text = view_text(ksp)
    assert "ordering: rcm" in text and "WARNING: no coordinates attached" in text     # the network reads none


def test_n_not_multiple_of_leaf(tiny_ckpt, options):
    fr = make_frame(1000, seed=5)
    A = frame_mat(fr)
    ksp = make_ksp(A, options(**htp_opts(tiny_ckpt)))
    reason, _, relres = solve(ksp, A, fr.b)
    assert reason > 0 and relres <= 1.01e-8
    part = ksp.getPC().getPythonContext().setup.op.part
    assert (part.n, part.n_leaves, part.n_tiles) == (1000, 8, 7)


# -------------------------------------------------------------------- view

def view_text(ksp):
    """``ksp.view()`` through a PETSc ASCII viewer on a file."""
    with tempfile.TemporaryDirectory() as tmp:
        path = str(Path(tmp) / "view.txt")
        vw = PETSc.Viewer().createASCII(path, comm=ksp.getComm())
        ksp.view(vw)
        vw.destroy()
        return Path(path).read_text()


def test_view_lines(frame, tiny_ckpt, options):
    A = frame_mat(frame)
    ksp = make_ksp(A, options(**htp_opts(tiny_ckpt)))
    solve(ksp, A, frame.b)
    text = view_text(ksp)
    for needle in ("Python: petsc_htp.HTPPC", "HTPPC, variant paper: the paper's Hierarchical Transformer Preconditioner",
                   "model: d=32, n_l=1, L=128, L_s=32, heads=4, highways=yes;", "device cpu",
                   f"checkpoint {tiny_ckpt}", "N=1024, L=128, K=8 leaves, M_H=7 tiles",
                   "factor memory", "ordering: morton (given)", "setup: analysis", "numeric",
                   "apply: float32", "setups: 1 analyses (pattern), 1 numeric (values)",
                   "fallback none not needed"):
        assert needle in text, (needle, text)
    assert "no coordinates attached" not in text
    n_params = HTPNet(HTPConfig(d=32, n_layers=1, heads=4)).n_params()
    assert f"{n_params} parameters" in text


@pytest.mark.slow
def test_ksp_view_and_log_view_from_the_example(tiny_ckpt):
    out = subprocess.run([sys.executable, str(EXAMPLE), "-n", "1024", "-options_file", "cg_paper", "-htp_checkpoint",
                          str(tiny_ckpt), "-htp_threads", "1", "-ksp_view", "-log_view"], cwd=ROOT, capture_output=True,
                         text=True, timeout=300)
    assert out.returncode == 0, out.stdout + out.stderr
    text = out.stdout
    assert "converged reason: CONVERGED_RTOL" in text
    assert "type: python" in text and "HTPPC, variant paper: the paper's Hierarchical Transformer Preconditioner" in text
    assert "model: d=32, n_l=1" in text and "M_H=7 tiles" in text
    events = {line.split()[0]: line.split() for line in text.splitlines() if line.split()[:1] in (["HTPSetup"], ["HTPApply"])}
    assert set(events) == {"HTPSetup", "HTPApply"}, text[-3000:]
    assert int(events["HTPSetup"][1]) == 1            # count column
    assert int(events["HTPApply"][1]) >= 2


# ----------------------------------------------------------- setup caching

def counts(ctx):
    """(analyses, numeric steps) run by an HTPPC."""
    return ctx.analysis_count, ctx.numeric_count


def test_setup_reruns_only_what_changed(frame, tiny_ckpt, options):
    A = frame_mat(frame)
    ksp = make_ksp(A, options(**htp_opts(tiny_ckpt)))
    reason, its1, _ = solve(ksp, A, frame.b)
    pc = ksp.getPC()
    ctx = pc.getPythonContext()
    assert reason > 0 and counts(ctx) == (1, 1)
    solve(ksp, A, frame.b)                          # same operator: no new setup
    pc.setUp()
    ctx.setUp(pc)                                   # even calling the context directly
    assert counts(ctx) == (1, 1)
    probe = np.random.default_rng(0).standard_normal(frame.n)
    analysis, m_probe = ctx.analysis, ctx.setup.apply(probe)
    A.scale(3.0)                                    # new values, same pattern: numeric step only
    reason, its2, relres = solve(ksp, A, frame.b)
    assert counts(ctx) == (1, 2) and ctx.analysis is analysis
    assert reason > 0 and relres <= 1.01e-8
    assert abs(its2 - its1) <= max(2, 0.02 * its1)  # scale invariant features (float32: 221 against 224 its)
    np.testing.assert_allclose(ctx.setup.apply(probe), m_probe / 3, rtol=1e-3, atol=1e-6 * np.abs(m_probe).max())
    net = ctx.variant.htp
    A.shift(0.5)
    solve(ksp, A, frame.b)
    assert counts(ctx) == (1, 3) and ctx.variant.htp is net  # the network is reused
    petsc_htp.attach(A, coords=frame.coords, density=2 * frame.rho)   # same geometry, new density
    solve(ksp, A, frame.b)
    assert counts(ctx) == (1, 4)
    petsc_htp.attach(A)                             # geometry removed -> new analysis, RCM ordering
    reason, _, _ = solve(ksp, A, frame.b)
    assert reason > 0 and counts(ctx) == (2, 5) and ctx.setup.ordering == "rcm"


def test_threads_option_sets_torch_and_says_so(frame, tiny_ckpt, options):
    import torch
    before = torch.get_num_threads()
    torch.set_num_threads(2)
    try:
        A = frame_mat(frame)
        ksp = make_ksp(A, options(**htp_opts(tiny_ckpt)))          # -htp_threads 1
        reason, _, _ = solve(ksp, A, frame.b)
        assert reason > 0 and torch.get_num_threads() == 1
        assert "and torch threads: 1 (set process-wide to 1 by -t" in view_text(ksp)
    finally:
        torch.set_num_threads(before)


def test_reuse_preconditioner_skips_setup(frame, tiny_ckpt, options):
    A = frame_mat(frame)
    ksp = make_ksp(A, options(**htp_opts(tiny_ckpt)))
    solve(ksp, A, frame.b)
    ctx = ksp.getPC().getPythonContext()
    ksp.getPC().setReusePreconditioner(True)
    A.scale(2.0)
    reason, _, relres = solve(ksp, A, frame.b)
    assert counts(ctx) == (1, 1) and reason > 0 and relres <= 1.01e-8
    ksp.getPC().setReusePreconditioner(False)
    solve(ksp, A, frame.b)
    assert counts(ctx) == (1, 2)


def test_attach_survives_new_wrappers(frame):
    A = frame_mat(frame)
    P = PETSc.KSP().create(comm=PETSc.COMM_SELF)
    P.setOperators(A, A)
    again = P.getOperators()[1]                     # a new Python wrapper of the same Mat
    np.testing.assert_array_equal(again.getAttr("petsc_htp_coords"), frame.coords)
    np.testing.assert_array_equal(again.getAttr("petsc_htp_density"), frame.rho)
    with pytest.raises(ValueError, match="coords must have shape"):
        petsc_htp.attach(A, coords=frame.coords[:, :1])


# ------------------------------------------------------------------ guards

def python_pc(A, ckpt, options, **extra):
    """A PCPYTHON with HTPPC's paper variant on ``A`` (the network in ``ckpt``)."""
    extra = {"htp_variant": "paper", **extra}
    prefix = options(pc_type="python", pc_python_type="petsc_htp.HTPPC", htp_checkpoint=str(ckpt),
                     htp_threads=1, **extra)
    pc = PETSc.PC().create(comm=PETSc.COMM_SELF)
    pc.setOptionsPrefix(prefix)
    pc.setOperators(A, A)
    pc.setFromOptions()
    return pc


def seqaij(csr, shape=None):
    csr = sp.csr_matrix(csr, shape=shape)
    A = PETSc.Mat().createAIJ(size=csr.shape, csr=(csr.indptr.astype(PETSc.IntType),
                                                   csr.indices.astype(PETSc.IntType), csr.data),
                              comm=PETSc.COMM_SELF)
    A.assemble()
    return A


def test_guard_non_square(tiny_ckpt, options):
    A = seqaij(sp.random(6, 8, density=0.5, random_state=0) + sp.eye(6, 8))
    with pytest.raises(PETSc.Error) as exc:
        python_pc(A, tiny_ckpt, options).setUp()
    assert "non-square" in error_text(exc) and "6 x 8" in error_text(exc)


def test_guard_nan(frame, tiny_ckpt, options):
    bad = frame.A.copy()
    bad.data[5] = np.nan
    with pytest.raises(PETSc.Error) as exc:
        python_pc(seqaij(bad), tiny_ckpt, options).setUp()
    assert "NaN or Inf" in error_text(exc)


@pytest.mark.parametrize("n", [0, 5])
def test_guard_empty(tiny_ckpt, options, n):
    A = PETSc.Mat().createAIJ(size=(n, n), nnz=1, comm=PETSc.COMM_SELF)
    A.assemble()
    with pytest.raises(PETSc.Error) as exc:
        python_pc(A, tiny_ckpt, options).setUp()
    assert "empty matrix" in error_text(exc)


def test_guard_missing_checkpoint(frame, tmp_path, options):
    missing = tmp_path / "nope.pt"
    with pytest.raises(PETSc.Error) as exc:
        python_pc(frame_mat(frame), missing, options).setUp()
    text = error_text(exc)
    assert "CheckpointError" in text and str(missing) in text and "does not exist" in text


def test_guard_corrupt_checkpoint(frame, tmp_path, options):
    bad = tmp_path / "corrupt.pt"
    bad.write_bytes(b"this is not a torch checkpoint" * 10)
    with pytest.raises(PETSc.Error) as exc:
        python_pc(frame_mat(frame), bad, options).setUp()
    text = error_text(exc)
    assert "CheckpointError" in text and str(bad) in text and "corrupt" in text


def test_guard_bad_option(frame, tiny_ckpt, options):
    with pytest.raises(PETSc.Error) as exc:
        python_pc(frame_mat(frame), tiny_ckpt, options, htp_fallback="maybe").setUp()
    assert "fallback 'maybe' unknown" in error_text(exc)


def test_guard_size_mismatch(frame, tiny_ckpt, options):
    A = frame_mat(frame)
    pc = python_pc(A, tiny_ckpt, options)
    pc.setUp()
    x = PETSc.Vec().createSeq(frame.n - 1, comm=PETSc.COMM_SELF)
    y = x.duplicate()
    with pytest.raises(ValueError, match="size mismatch"):
        pc.getPythonContext().apply(pc, x, y)


def test_apply_matches_setup_and_is_symmetric(frame, tiny_ckpt, options):
    A = frame_mat(frame)
    pc = python_pc(A, tiny_ckpt, options)
    pc.setUp()
    ctx = pc.getPythonContext()
    rng = np.random.default_rng(0)
    u, v = (A.createVecs("left") for _ in range(2))
    u.setArray(rng.standard_normal(frame.n))
    v.setArray(rng.standard_normal(frame.n))
    mu, mv = u.duplicate(), v.duplicate()
    pc.apply(u, mu)
    pc.applyTranspose(v, mv)
    np.testing.assert_allclose(mu.getArray(), ctx.setup.apply(u.getArray()), rtol=1e-12)
    assert mu.norm() > 0
    assert abs(v.dot(mu) - u.dot(mv)) <= 1e-4 * abs(v.dot(mu)) + 1e-8


# ---------------------------------------------------------------- fallback

def test_nan_weights_without_fallback_diverge(frame, nan_ckpt, options):
    A = frame_mat(frame)
    ksp = make_ksp(A, options(**htp_opts(nan_ckpt)))
    reason, _, _ = solve(ksp, A, frame.b)
    assert reason < 0, reason_name(reason)
    assert reason_name(reason) in ("DIVERGED_NANORINF", "DIVERGED_INDEFINITE_PC")
    ctx = ksp.getPC().getPythonContext()
    assert "factors are not finite" in ctx.fallback_reason and not ctx.fallback_active
    assert "WARNING: HTP factors are not finite" in view_text(ksp)


def test_nan_weights_with_jacobi_fallback_converge(frame, nan_ckpt, options):
    A = frame_mat(frame)
    ksp = make_ksp(A, options(**htp_opts(nan_ckpt, htp_fallback="jacobi")))
    reason, its, relres = solve(ksp, A, frame.b)
    assert reason > 0 and relres <= 1.01e-8
    ctx = ksp.getPC().getPythonContext()
    assert ctx.fallback_active
    assert "fallback: jacobi ACTIVE (HTP factors are not finite" in view_text(ksp)
    # the same iterations as PETSc's own Jacobi
    prefix = options(ksp_type="cg", ksp_rtol=1e-8, ksp_norm_type="unpreconditioned", ksp_max_it=5000,
                     pc_type="jacobi")
    _, its_jacobi, _ = solve(make_ksp(A, prefix), A, frame.b)
    assert abs(its - its_jacobi) <= 1


def test_spd_guard_shifts_an_indefinite_m(frame, indefinite_ckpt, options):
    A = frame_mat(frame)
    ksp = make_ksp(A, options(**htp_opts(indefinite_ckpt)))          # the guard is on by default
    reason, _, relres = solve(ksp, A, frame.b)
    ctx = ksp.getPC().getPythonContext()
    assert ctx.setup.guard_shift > 0 and not ctx.fallback_reason
    assert reason > 0 and relres <= 1.01e-8, reason_name(reason)
    assert re.search(r"SPD guard shift added: [0-9.e+]+ \* D\^-1", view_text(ksp))


def test_indefinite_m_is_reported_and_fallback_recovers(frame, indefinite_ckpt, options):
    A = frame_mat(frame)
    ksp = make_ksp(A, options(**htp_opts(indefinite_ckpt, htp_spd_guard="false")))
    reason, _, _ = solve(ksp, A, frame.b)
    ctx = ksp.getPC().getPythonContext()
    assert ctx.fallback_reason.startswith("Rayleigh probe found M indefinite")
    assert reason_name(reason) == "DIVERGED_INDEFINITE_PC"
    ksp = make_ksp(A, options(**htp_opts(indefinite_ckpt, htp_fallback="jacobi", htp_spd_guard="false")))
    reason, _, relres = solve(ksp, A, frame.b)
    assert reason > 0 and relres <= 1.01e-8
    assert "fallback: jacobi ACTIVE (Rayleigh probe found M indefinite" in view_text(ksp)
