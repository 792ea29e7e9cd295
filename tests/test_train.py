import dataclasses
import json

import pytest

from petsc_htp.paper import weights
from petsc_htp.paper.model import HTPConfig
from petsc_htp.paper.train import AutoStop, TrainSettings, train


@pytest.mark.slow
def test_short_training_lowers_loss_and_iterations(tmp_path):
    cfg = HTPConfig(d=32, n_layers=1, leaf=32, p_off=4, heads=4, n_gcn=1)
    s = TrainSettings(scales=(256,), frames=8, max_steps=120, log_every=10, eval_every=10, ckpt_every=60,
                      lr=1e-3, eval_n=256, geometry_free=0.0, out=str(tmp_path / "run"),
                      cache_dir=str(tmp_path / "cache"))
    path = train(cfg, s)
    rows = [json.loads(line) for line in open(tmp_path / "run" / "train_log.jsonl")]
    losses = [r["loss"] for r in rows if "loss" in r]
    iters = [r["pcg_iters"] for r in rows if "pcg_iters" in r]
    assert losses[-1] < losses[0]
    net, prov = weights.load(path)
    assert net.cfg == cfg and prov["steps"] == 120
    untrained = prov["heldout_untrained"]["pcg_iters"]
    assert min(iters[-3:]) < untrained, (iters, untrained)
    # resume continues from the saved step
    s.max_steps, s.resume = 130, True
    train(cfg, s)
    assert weights.load(tmp_path / "run" / "final.pt")[1]["steps"] == 130
    # fine-tuning starts from the trained weights with a fresh optimizer and records its parent
    ft = dataclasses.replace(s, init=str(path), max_steps=10, resume=False, out=str(tmp_path / "ft"))
    prov = weights.load(train(cfg, ft))[1]
    assert prov["init"]["steps"] == 130 and prov["steps"] == 10
    assert prov["heldout_untrained"]["pcg_iters"] < untrained


def test_autostop_needs_min_lr_and_stagnation():
    stop = AutoStop(min_lr=1e-6, patience=3)
    assert not any(stop.update(1.0 / (k + 1), 1e-6) for k in range(10))   # improving: keep going
    assert not any(stop.update(0.5, 1e-3) for _ in range(5))               # stagnant but lr high
    assert [stop.update(0.5, 1e-6) for _ in range(3)][-1]


def test_bad_loss_name(tmp_path):
    with pytest.raises(ValueError, match="unknown loss"):
        train(HTPConfig(d=32, n_layers=1, heads=4), TrainSettings(loss="mse", out=str(tmp_path)))


def test_join_logs_continues_steps_and_wall_clock(tmp_path):
    from petsc_htp.paper.train import join_logs

    a, b = tmp_path / "a.jsonl", tmp_path / "b.jsonl"
    a.write_text('{"step": 10, "loss": 0.5, "wall_s": 5.0}\n{"step": 20, "wall_s": 9.0, "pcg_iters": 40}\n')
    b.write_text('{"step": 5, "loss": 0.3, "wall_s": 2.0, "pcg_iters": 30, "heldout_n": 2048}\n')
    rows = [json.loads(x) for x in join_logs([(a, 1024), (b, 4096)], tmp_path / "j.jsonl").read_text().splitlines()]
    assert [(r["step"], r["wall_s"], r["stage"]) for r in rows] == [(10, 5.0, 1), (20, 9.0, 1), (25, 11.0, 2)]
    assert [r.get("heldout_n") for r in rows] == [None, 1024, 2048]
    (tmp_path / "empty.jsonl").write_text("")
    with pytest.raises(ValueError, match="empty"):
        join_logs([(tmp_path / "empty.jsonl", 1024)], tmp_path / "k.jsonl")


def test_join_logs_command(tmp_path, capsys):
    from petsc_htp.cli import main

    log = tmp_path / "a.jsonl"
    log.write_text('{"step": 1, "wall_s": 1.0, "pcg_iters": 9}\n')
    assert main(["join-logs", str(tmp_path / "j.jsonl"), f"{log}:256", f"{log}:512"]) == 0
    assert len((tmp_path / "j.jsonl").read_text().splitlines()) == 2
    assert main(["join-logs", str(tmp_path / "k.jsonl"), str(log)]) == 2
    assert "LOG:HELDOUT_N" in capsys.readouterr().err
