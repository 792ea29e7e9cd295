"""What every study shares: the :class:`Study` protocol, its size settings and measurement context."""
from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path


def _show(value) -> str:
    if isinstance(value, list):
        return " ".join(map(str, value))
    return f"{value:g}" if isinstance(value, float) else str(value)


@dataclass(frozen=True)
class Size:
    """A size setting: ``settings[name]``, from flag ``--name`` or the full-run / ``--quick`` default.

    Attributes
    ----------
    name : str
        Key in the settings (and the flag, underscores as dashes, unless ``flag`` is given).
    full, quick
        Defaults of a full run and of ``--quick``; a list makes the flag take several values (or none: the flag
        alone, e.g. ``--scale-sides-3d``, leaves that part out).
    help : str
        Help of the flag; without it the setting has no flag.
    flag : str
        The flag, when not derived from ``name``.
    kind : callable or None
        Type of the values (default that of ``full``).
    """

    name: str
    full: object
    quick: object
    help: str = ""
    flag: str = ""
    kind: type | None = None

    def add_to(self, parser):
        """Add the flag to an argparse parser or group (nothing without ``help``)."""
        if not self.help:
            return
        many = isinstance(self.full, list)
        kind = self.kind or type(self.full[0] if many else self.full)
        text = self.help if self.full is None else f"{self.help} ({_show(self.full)} / {_show(self.quick)})"
        parser.add_argument(self.flag or "--" + self.name.replace("_", "-"), dest=self.name, type=kind,
                            nargs="*" if many else None, help=text)


SCALES = Size("scales", [1024, 2048, 4096, 8192, 16384], [256, 512], "N of table/curves/fastpath")
DIM = Size("dim", 2, 2, "scene dimension of table, sequence, curves, stability and defaults: 2, or 3 for near-cubic "
                        "boxes with the 7-point operator (N = side^3, e.g. --scales 32768 262144)")
FRAMES = Size("frames", 20, 2, "held-out frames per N")
TRAINING = (
    Size("train_minutes", 15.0, 0.5, "wall-clock limit per study model", flag="--train-budget-minutes"),
    Size("train_steps", 100_000, 2, "step limit per study model"),
    Size("train_scales", [1024, 2048], [256], "training N of study models"),
    Size("train_frames", 100, 2, "training frames per scale"),
    Size("eval_n", 1024, 256), Size("log_every", 25, 1), Size("eval_every", 200, 2),
)


@dataclass
class Context:
    """What a measurement reads: sizes, methods, HTP flags and the results folder.

    Attributes
    ----------
    settings : dict
        Every :class:`Size` by name.
    methods : list of petsc_htp.bench.methods.Method
    out : Path
        Results folder (study models are trained into ``out/models``).
    checkpoint, device : str or None
        ``--checkpoint`` and ``--device``.
    threads : int
        ``--threads`` (0: the default).
    """

    settings: dict
    methods: list
    out: Path
    checkpoint: str | None = None
    device: str | None = None
    threads: int = 0

    @cached_property
    def extra(self) -> list:
        """``htp_*`` options every PETSc solve gets (checkpoint, device, threads)."""
        from ..runner import htp_options

        return htp_options(self.checkpoint and Path(self.checkpoint).resolve(), self.device, self.threads)

    @cached_property
    def budget(self):
        """The :class:`~petsc_htp.bench.training.Budget` of every study model."""
        from ...paper.inference import resolve_device
        from ..training import Budget

        s = self.settings
        return Budget(minutes=s["train_minutes"], steps=s["train_steps"], scales=tuple(s["train_scales"]),
                      frames=s["train_frames"], eval_n=s["eval_n"], log_every=s["log_every"],
                      eval_every=s["eval_every"], device=str(resolve_device(self.device or "auto")))

    @cached_property
    def config(self):
        """Network configuration of ``--checkpoint`` (or the shipped model): the base of trained models."""
        from ..training import base_config

        return base_config(self.checkpoint)


class Study(ABC):
    """One benchmark study: what it measures, the solves it expects, its report section and charts.

    A subclass sets the attributes and overrides the methods it needs; its
    module defines ``STUDY``, an instance, listed in ``studies.ORDER``.

    Attributes
    ----------
    name : str
        ``--studies`` name; its rows are ``<name>.jsonl``.
    help : str
        Line of ``petsc-htp bench -h``.
    default : bool
        Part of the default ``--studies``.
    data : str
        Name of the study whose rows it reads: its own, unless it reuses another's measurement.
    sizes : tuple of Size
        Settings it reads (shared ones may be listed by several studies).
    readme_links : tuple of (str, str)
        (chart file, title) pairs of README's "More charts" line.
    """

    name = ""
    help = ""
    default = False
    sizes = ()
    readme_links = ()

    @property
    def data(self) -> str:
        """The study whose rows this one reads (itself)."""
        return self.name

    def meta(self, settings) -> dict:
        """Entries of ``meta.json`` describing its sizes."""
        return {}

    def expected_solves(self, ctx) -> int:
        """Number of solves :meth:`measure` reports through ``tick`` (the progress bar's total)."""
        return 0

    def measure(self, ctx, tick) -> list:
        """Run the study; return its result rows (dicts), calling ``tick()`` after every solve.

        A study that reads another study's rows (``data``) measures nothing itself.
        """
        return []

    @abstractmethod
    def section(self, res) -> str:
        """Its section of report.md from the results (:class:`~petsc_htp.bench.report.Results`)."""

    def charts(self, res, out) -> list:
        """Draw its charts into folder ``out``; return the file names."""
        return []

    def readme(self, res, prefix) -> str:
        """Its part of README's results block (chart links start with ``prefix``); '' for none."""
        return ""

    def summary(self, res) -> str:
        """Text printed after a run; '' for none."""
        return ""


def solve_all(methods, problems, extra, tick, study, **kw) -> list:
    """Every method on every problem (frames outermost), rows tagged with ``study``."""
    from ..runner import run_methods

    return [tag(row, study=study) for row in run_methods(methods, problems, extra, tick=tick, **kw)]


def tag(row, **fields) -> dict:
    """``row`` updated with ``fields``."""
    row.update(fields)
    return row
