"""The problems studies solve: one linear system each, built from held-out test frames."""
from __future__ import annotations

from dataclasses import dataclass

from ..scenes.dataset import dataset_seeds, load_dataset
from ..scenes.generator import Frame


@dataclass
class Problem:
    """One linear system to solve.

    Attributes
    ----------
    frame : petsc_htp.scenes.Frame
        Operator ``frame.A`` and right-hand side ``frame.b``.
    case : str
        Label of the study cell it belongs to (``table`` for the main runs).
    attach : bool
        Hand the frame's coordinates and density to HTP (``petsc_htp.attach``).
    rtol : float or None
        Overrides the options files' relative tolerance.
    """

    frame: Frame
    case: str = "table"
    attach: bool = True
    rtol: float | None = None

    @property
    def n(self) -> int:
        """Number of unknowns."""
        return self.frame.n

    @property
    def seed(self):
        """Scene seed of the frame."""
        return self.frame.params.get("seed")


def held_out_frames(n, count, distribution="full", dim=2) -> list:
    """The first ``count`` held-out test frames at ``n`` (cached dataset; ``dim`` 2 or 3)."""
    return load_dataset(n, "test", distribution, count=count, dim=dim)


def held_out_seeds(count) -> list:
    """Scene seeds of the first ``count`` held-out test frames."""
    return [int(s) for s in dataset_seeds("test", count)]


def table_problems(scales, frames, dim=2) -> list:
    """Held-out test frames of the full distribution at every scale, grouped by N."""
    return [Problem(f) for n in scales for f in held_out_frames(n, frames, dim=dim)]
