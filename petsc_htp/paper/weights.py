"""The paper network's checkpoints: load one, or warm-start a network from one (:mod:`petsc_htp.training.checkpoint`)."""
from __future__ import annotations

from ..training.checkpoint import CheckpointError, read
from .model import HTPConfig, HTPNet


def warm_start(net: HTPNet, path) -> dict:
    """Copy a checkpoint's weights into ``net`` (same configuration); returns its provenance.

    Weights the checkpoint lacks (added to the network since) keep their initial values.
    """
    obj = read(path)
    if obj["config"] != net.cfg.to_dict():
        raise CheckpointError(f"checkpoint {path} configuration {obj['config']} does not match "
                              f"the network's {net.cfg.to_dict()}")
    res = net.load_state_dict(obj["state_dict"], strict=False)
    if res.unexpected_keys:
        raise CheckpointError(f"checkpoint {path} has weights this network lacks: {res.unexpected_keys}")
    return obj.get("provenance", {})


def load(path=None, expect: HTPConfig | None = None) -> tuple[HTPNet, dict]:
    """Return (network in eval mode, provenance); ``expect`` must equal the stored config if given."""
    obj = read(path)
    try:
        cfg = HTPConfig(**obj["config"])
    except TypeError as exc:
        raise CheckpointError(f"checkpoint {path} has an unknown configuration: {exc}") from exc
    if expect is not None and expect != cfg:
        raise CheckpointError(f"checkpoint {path} configuration {cfg} does not match the requested {expect}")
    net = HTPNet(cfg)
    try:
        net.load_state_dict(obj["state_dict"])
    except RuntimeError as exc:
        raise CheckpointError(f"checkpoint {path} weights do not match its configuration: {exc}") from exc
    net.eval()
    return net, obj.get("provenance", {})
