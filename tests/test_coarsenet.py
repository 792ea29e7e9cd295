"""Tests for the learned coarse space (petsc_htp.twolevel.coarsenet, petsc_htp.twolevel.coarsetrain)."""
import json

import numpy as np
import pytest
import scipy.sparse as sp
import torch

from petsc_htp.twolevel import coarsenet
from petsc_htp.training.checkpoint import CheckpointError
from petsc_htp.twolevel.coarsenet import CoarseConfig, CoarseNet, learned_basis
from petsc_htp.twolevel.coarsetrain import TrainSettings, context_loss, make_context, train
from petsc_htp.twolevel.leaves import choose_leaves
from petsc_htp.training.pcg import pcg
from petsc_htp.scenes.generator import make_frame
from petsc_htp.twolevel.batched import analyse, factor

SEED = 1_000_000          # the first held-out test frame
TINY = CoarseConfig(rank=3, width=8, heads=2, gcn_layers=1, attn_layers=1, noise_channels=2)


@pytest.fixture(autouse=True)
def one_thread():
    """One torch thread: these small problems slow down many-fold on a busy shared machine."""
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(threads)


def tiny_net(seed=0, cfg=TINY):
    """An untrained small network."""
    torch.manual_seed(seed)
    return CoarseNet(cfg)


def bare(frame, seed=0):
    """The frame's matrix under a random symmetric permutation, and the permuted rhs."""
    q = np.random.default_rng(seed).permutation(frame.n)
    return sp.csr_matrix(frame.A[q][:, q]), frame.b[q]


def test_shapes_padding_and_constant_column():
    fr = make_frame(1024, SEED)
    for A, xy, rho in ((fr.A, fr.coords, fr.rho), (bare(fr)[0], None, None)):
        lv = choose_leaves(A, xy, leaf=100)
        an = analyse(A, lv)
        P = learned_basis(tiny_net(), an, A, xy, rho)
        assert P.shape == (lv.n_leaves, lv.max_size, 3) and P.dtype == torch.float64
        assert lv.sizes.min() < lv.max_size                        # there is padding to check
        assert torch.all(P[an.mask == 0] == 0) and torch.isfinite(P).all()
        assert torch.all(P[:, :, 0] == an.mask)                     # the leaf constant comes first
        assert factor(an, A, coarse="given", basis=P).rank == 3 + an.constants.shape[2]     # and the pieces


def test_basis_is_invariant_to_scaling_a():
    fr = make_frame(1024, SEED)
    an = analyse(fr.A, choose_leaves(fr.A, fr.coords))
    net = tiny_net()
    P = learned_basis(net, an, fr.A, fr.coords, fr.rho)
    for c in (1e-3, 250.0):
        Q = learned_basis(net, an, sp.csr_matrix(c * fr.A), fr.coords, fr.rho)
        assert torch.allclose(P, Q, rtol=0, atol=1e-4 * P.abs().max())
    assert not torch.allclose(P, learned_basis(net, an, fr.A, fr.coords, None), atol=1e-3)


def test_gradients_flow_through_the_coarse_solve():
    fr = make_frame(512, SEED)
    net = tiny_net()
    ctx = make_context(TINY, fr.A, choose_leaves(fr.A, fr.coords, leaf=64), fr.coords, fr.rho)
    loss = context_loss(net, ctx, torch.Generator().manual_seed(0))
    loss.backward()
    assert 0 < loss.item() < 1
    grads = {name: p.grad for name, p in net.named_parameters()}
    assert all(g is not None and torch.isfinite(g).all() for g in grads.values())
    for name in ("embed.weight", "gcn.0.weight", "attn.0.qkv.weight", "attn.0.bias_scale", "head.1.weight"):
        assert grads[name].abs().max() > 0, name


def test_save_load_round_trip_and_bad_files(tmp_path):
    fr = make_frame(256, SEED)
    an = analyse(fr.A, choose_leaves(fr.A, fr.coords, leaf=64))
    net = tiny_net(3)
    path = coarsenet.save(tmp_path / "c.pt", net, {"note": "test"})
    loaded, prov = coarsenet.load(path)
    assert loaded.cfg == TINY and prov == {"note": "test"} and not loaded.training
    assert torch.equal(learned_basis(net, an, fr.A), learned_basis(loaded, an, fr.A))
    (tmp_path / "bad.pt").write_bytes(path.read_bytes()[:200])
    with pytest.raises(CheckpointError, match="corrupt"):
        coarsenet.load(tmp_path / "bad.pt")
    with pytest.raises(CheckpointError, match="does not exist"):
        coarsenet.load(tmp_path / "missing.pt")
    torch.save({"format": "something else"}, tmp_path / "other.pt")
    with pytest.raises(CheckpointError, match="not a petsc_htp coarse"):
        coarsenet.load(tmp_path / "other.pt")


def test_shipped_checkpoint_beats_const_and_matches_eig():
    """Held-out frame: within 10 % of eig at equal r with geometry, 20 % as a bare matrix."""
    net, prov = coarsenet.load()
    r = net.cfg.rank
    fr = make_frame(1024, SEED)
    A_bare, b_bare = bare(fr, 1)
    for A, b, xy, rho, slack in ((fr.A, fr.b, fr.coords, fr.rho, 1.1), (A_bare, b_bare, None, None, 1.2)):
        an = analyse(A, choose_leaves(A, xy))
        its = {c: pcg(A, b, factor(an, A, coarse=c, rank=r).apply, 1e-8).iterations for c in ("const", "eig")}
        res = pcg(A, b, factor(an, A, coarse="given", basis=learned_basis(net, an, A, xy, rho)).apply, 1e-8)
        assert res.converged and res.iterations < its["const"]
        assert res.iterations <= slack * its["eig"], (res.iterations, its)
    assert prov["steps"] > 0 and "command" in prov


def test_short_training_lowers_the_held_out_loss(tmp_path):
    s = TrainSettings(scales=(256,), frames=4, val_frames=1, max_steps=60, eval_every=30, lr=1e-2,
                      warmup=5, max_minutes=5.0, out=str(tmp_path / "run"), cache_dir=str(tmp_path / "cache"))
    best = train(TINY, s)
    rows = [json.loads(line) for line in open(tmp_path / "run" / "train_log.jsonl")]
    evals = [row for row in rows if "val_loss" in row]
    assert [row["step"] for row in evals] == [0, 30, 60]
    assert evals[-1]["val_loss"] < evals[0]["val_loss"]
    assert coarsenet.load(best)[0].cfg == TINY and (tmp_path / "run" / "final.pt").is_file()
