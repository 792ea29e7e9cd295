import json

import pytest
import torch

from petsc_htp import checkpoint
from petsc_htp.model import HTPConfig
from petsc_htp.train import AutoStop, TrainSettings, train


@pytest.mark.slow
def test_short_training_lowers_loss_and_iterations(tmp_path):
    cfg = HTPConfig(d=32, n_layers=1, leaf=32, p_off=4, heads=4, n_gcn=1)
    s = TrainSettings(scales=(256,), frames=8, max_steps=80, log_every=10, eval_every=10, ckpt_every=40,
                      lr=3e-3, eval_n=256, geometry_free=0.0, out=str(tmp_path / "run"),
                      cache_dir=str(tmp_path / "cache"))
    path = train(cfg, s)
    rows = [json.loads(line) for line in open(tmp_path / "run" / "train_log.jsonl")]
    losses = [r["loss"] for r in rows if "loss" in r]
    iters = [r["pcg_iters"] for r in rows if "pcg_iters" in r]
    assert losses[-1] < losses[0]
    net, prov = checkpoint.load(path)
    assert net.cfg == cfg and prov["steps"] == 80
    untrained = prov["heldout_untrained"]["pcg_iters"]
    assert min(iters[-3:]) < untrained, (iters, untrained)
    # resume continues from the saved step
    s.max_steps, s.resume = 90, True
    train(cfg, s)
    assert checkpoint.load(tmp_path / "run" / "final.pt")[1]["steps"] == 90


def test_autostop_needs_min_lr_and_stagnation():
    stop = AutoStop(min_lr=1e-6, patience=3)
    assert not any(stop.update(1.0 / (k + 1), 1e-6) for k in range(10))   # improving: keep going
    assert not any(stop.update(0.5, 1e-3) for _ in range(5))               # stagnant but lr high
    assert [stop.update(0.5, 1e-6) for _ in range(3)][-1]


def test_bad_loss_name(tmp_path):
    with pytest.raises(ValueError, match="unknown loss"):
        train(HTPConfig(d=32, n_layers=1, heads=4), TrainSettings(loss="mse", out=str(tmp_path)))
