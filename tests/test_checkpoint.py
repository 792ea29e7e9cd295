import dataclasses

import pytest
import torch

from petsc_htp.training import checkpoint
from petsc_htp.paper import weights
from petsc_htp.training.checkpoint import CheckpointError
from petsc_htp.paper.model import HTPConfig, HTPNet


def test_round_trip(tmp_path, tiny_cfg):
    net = HTPNet(tiny_cfg)
    path = checkpoint.save(tmp_path / "a.pt", net, {"steps": 3})
    loaded, prov = weights.load(path)
    assert loaded.cfg == tiny_cfg and prov["steps"] == 3
    for (k, v), (k2, v2) in zip(net.state_dict().items(), loaded.state_dict().items()):
        assert k == k2 and torch.equal(v, v2)
    assert not list(tmp_path.glob("*.tmp"))


def test_missing_corrupt_version_and_mismatch(tmp_path, tiny_cfg):
    with pytest.raises(CheckpointError, match="does not exist"):
        weights.load(tmp_path / "nope.pt")
    bad = tmp_path / "bad.pt"
    bad.write_bytes(b"not a checkpoint at all")
    with pytest.raises(CheckpointError, match="corrupt or unreadable"):
        weights.load(bad)
    good = checkpoint.save(tmp_path / "good.pt", HTPNet(tiny_cfg), {})
    truncated = tmp_path / "trunc.pt"
    truncated.write_bytes(good.read_bytes()[:500])
    with pytest.raises(CheckpointError, match="corrupt"):
        weights.load(truncated)
    obj = checkpoint.read(good)
    obj["version"] = 99
    torch.save(obj, tmp_path / "v99.pt")
    with pytest.raises(CheckpointError, match="version 99"):
        weights.load(tmp_path / "v99.pt")
    with pytest.raises(CheckpointError, match="does not match"):
        weights.load(good, expect=HTPConfig())
    obj = checkpoint.read(good)
    obj["config"]["d"] = 64
    torch.save(obj, tmp_path / "wrong.pt")
    with pytest.raises(CheckpointError, match="do not match"):
        weights.load(tmp_path / "wrong.pt")


def test_warm_start_copies_weights_and_keeps_new_ones(tmp_path, tiny_cfg):
    src = HTPNet(tiny_cfg)
    state = {k: v for k, v in src.state_dict().items() if not k.startswith("leaf_pos")}
    obj = {"format": checkpoint.FORMAT, "version": checkpoint.VERSION, "config": tiny_cfg.to_dict(),
           "state_dict": state, "provenance": {"steps": 7}}
    torch.save(obj, tmp_path / "old.pt")        # a checkpoint from before leaf_pos existed
    torch.manual_seed(1)
    dst = HTPNet(tiny_cfg)
    fresh = dst.leaf_pos[0].weight.clone()
    assert weights.warm_start(dst, tmp_path / "old.pt")["steps"] == 7
    assert torch.equal(dst.slot, src.slot) and torch.equal(dst.leaf_pos[0].weight, fresh)
    with pytest.raises(CheckpointError, match="does not match"):
        weights.warm_start(HTPNet(dataclasses.replace(tiny_cfg, d=64)), tmp_path / "old.pt")
    obj["state_dict"]["surplus"] = torch.zeros(1)
    torch.save(obj, tmp_path / "surplus.pt")
    with pytest.raises(CheckpointError, match="lacks"):
        weights.warm_start(dst, tmp_path / "surplus.pt")
