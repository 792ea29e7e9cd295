"""Models the studies train themselves: one folder per (configuration, distribution, loss, budget)."""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path

from ..training import checkpoint
from ..paper import weights
from ..paper.model import HTPConfig
from . import store


@dataclass(frozen=True)
class Budget:
    """How long each study model trains (passed to :class:`petsc_htp.paper.train.TrainSettings`)."""

    minutes: float | None
    steps: int
    scales: tuple
    frames: int
    eval_n: int
    log_every: int
    eval_every: int
    device: str = "cpu"
    lr: float = 5e-4
    warmup: int = 50

    def describe(self) -> str:
        """One line for the report."""
        limit = f"{self.minutes:g} min" if self.minutes else "no time limit"
        return (f"at most {self.steps} steps and {limit} per model (auto-stop may end it sooner), "
                f"lr {self.lr:g} after {self.warmup} warm-up steps, "
                f"{self.frames} training frames per scale at N = {', '.join(map(str, self.scales))}, "
                f"device {self.device}")


def base_config(path=None) -> HTPConfig:
    """Configuration of checkpoint ``path`` (or the shipped model); the paper's default without one."""
    try:
        return HTPConfig(**checkpoint.read(path)["config"])
    except checkpoint.CheckpointError:
        return HTPConfig()


def label(cfg, loss="cosine") -> str:
    """Short human-readable name of a configuration."""
    return f"d={cfg.d}, n_l={cfg.n_layers}, {'hw' if cfg.highways else 'no-hw'}, {loss}"


def model_key(cfg, distribution, loss) -> str:
    """Folder name of a study model."""
    return f"d{cfg.d}_l{cfg.n_layers}_{'hw' if cfg.highways else 'nohw'}_{loss}_{distribution}"


def trained_checkpoint(out, cfg, distribution, loss, budget) -> Path:
    """Train (or reuse, when trained before with the same budget) a model; return its final checkpoint."""
    from ..paper.train import TrainSettings, train

    folder = Path(out) / "models" / model_key(cfg, distribution, loss)
    final, stamp = folder / "final.pt", folder / "budget.json"
    wanted = store.clean({"budget": dataclasses.asdict(budget), "config": cfg.to_dict()})
    if final.is_file() and stamp.is_file() and store.read_json(stamp) == wanted:
        return final
    (folder / "train_log.jsonl").unlink(missing_ok=True)
    settings = TrainSettings(scales=tuple(budget.scales), distribution=distribution, frames=budget.frames,
                             loss=loss, max_steps=budget.steps, max_minutes=budget.minutes,
                             log_every=budget.log_every, eval_every=budget.eval_every,
                             ckpt_every=budget.steps, device=budget.device, out=str(folder), eval_n=budget.eval_n,
                             lr=budget.lr, warmup=budget.warmup)
    path = train(cfg, settings)
    store.write_json(stamp, wanted)
    return Path(path)


def model_info(path) -> dict:
    """Configuration, parameter count and training provenance of a checkpoint, for result rows."""
    net, prov = weights.load(path)
    cfg = net.cfg
    return {"checkpoint": str(path), "params": net.n_params(), "d": cfg.d, "n_layers": cfg.n_layers,
            "highways": cfg.highways, "loss": prov.get("loss", "cosine"), "train_steps": prov.get("steps"),
            "train_wall_s": prov.get("wall_s"), "train_distribution": prov.get("distribution")}
