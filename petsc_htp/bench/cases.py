"""The problems a study solves: held-out test frames, stress cases and generalization sets."""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from ..scenes import Frame, dataset_seeds, load_dataset, make_frame


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


def held_out_frames(n, count, distribution="full") -> list:
    """The first ``count`` held-out test frames at ``n`` (cached dataset)."""
    return load_dataset(n, "test", distribution, count=count)


def table_problems(scales, frames) -> list:
    """Held-out test frames of the full distribution at every scale, grouped by N."""
    return [Problem(f) for n in scales for f in held_out_frames(n, frames)]


def curve_problems(scales) -> list:
    """The representative frame per N: the first held-out test frame."""
    return [Problem(held_out_frames(n, 1)[0], case="curve") for n in scales]


# ------------------------------------------------------------------ stress cases

def natural_order(frame) -> Frame:
    """The frame permuted from Morton to row-major order (the grid's natural numbering)."""
    order = np.argsort(frame.perm, kind="stable")
    A = frame.A[order][:, order].tocsr()
    A.sort_indices()
    return dataclasses.replace(frame, A=A, b=frame.b[order], rho=frame.rho[order],
                               coords=frame.coords[order], perm=frame.perm[order],
                               params={**frame.params, "ordering": "natural"})


def inconsistent(frame, offset=0.1) -> Frame:
    """The frame with ``offset * rms(b)`` added to every entry of b: b leaves the range of A."""
    shift = offset * float(np.sqrt(np.mean(frame.b ** 2)))
    return dataclasses.replace(frame, b=frame.b + shift, params={**frame.params, "rhs_offset": shift})


def _seeds(count):
    return [int(s) for s in dataset_seeds("test", count)]


def _contrast(n, count, value):
    """Frames whose heavy density is fixed at ``value`` (range ``[0.99 value, value]``)."""
    return [make_frame(n, s, "full", contrast=(0.99 * value, value)) for s in _seeds(count)]


STRESS = (
    ("reference", "full distribution, random rhs (the table's setting)"),
    ("contrast 1e2", "heavy density fixed at 100 (top of the training range)"),
    ("contrast 1e3", "heavy density fixed at 1000 (10x past training)"),
    ("contrast 1e4", "heavy density fixed at 10000 (100x past training)"),
    ("closed only", "only closed barriers (sealed sub-domains)"),
    ("large N", "N larger than any training scale"),
    ("odd N", "N not a power of two (ragged last grid row, partial last leaf)"),
    ("rtol 1e-10", "tolerance 1e-10"),
    ("rtol 1e-12", "tolerance 1e-12 (near double-precision limit)"),
    ("natural order", "row-major ordering, no coordinates or density attached"),
    ("buoyancy rhs", "rhs -d(rho)/dy, supported on density interfaces only"),
    ("inconsistent rhs", "b + 0.1 rms(b): not mean-zero, outside the range of the singular A"),
)


def stress_problems(n, frames, large_n, odd_n) -> list:
    """Every stress case of :data:`STRESS`, ``frames`` frames each (grouped by case)."""
    base = held_out_frames(n, frames)
    seeds = _seeds(frames)
    cases = {
        "reference": [Problem(f) for f in base],
        "contrast 1e2": [Problem(f) for f in _contrast(n, frames, 1e2)],
        "contrast 1e3": [Problem(f) for f in _contrast(n, frames, 1e3)],
        "contrast 1e4": [Problem(f) for f in _contrast(n, frames, 1e4)],
        "closed only": [Problem(f) for f in held_out_frames(n, frames, "closed_only")],
        "large N": [Problem(f) for f in held_out_frames(large_n, frames)],
        "odd N": [Problem(f) for f in held_out_frames(odd_n, frames)],
        "rtol 1e-10": [Problem(f, rtol=1e-10) for f in base],
        "rtol 1e-12": [Problem(f, rtol=1e-12) for f in base],
        "natural order": [Problem(natural_order(f), attach=False) for f in base],
        "buoyancy rhs": [Problem(make_frame(n, s, "full", rhs="buoyancy")) for s in seeds],
        "inconsistent rhs": [Problem(inconsistent(f)) for f in base],
    }
    out = []
    for name, _ in STRESS:
        for p in cases[name]:
            p.case = name
            out.append(p)
    return out


# --------------------------------------------------------------- generalization

TRAIN_SETS = (
    ("full", "Full"),
    ("no_closed", "Excl. closed barriers"),
    ("low_contrast", "Low contrast [5, 25]"),
    ("no_closed_low_contrast", "Excl. closed + low contrast"),
)
EVAL_SETS = (
    ("full", "Full / in-distribution"),
    ("closed_only", "Closed barriers only"),
    ("high_contrast", "High contrast (25, 100]"),
    ("closed_high", "Closed + high contrast"),
)


def eval_problems(name, n, count) -> list:
    """Test frames of one generalization eval set (see :data:`EVAL_SETS`)."""
    if name == "closed_high":
        frames = [make_frame(n, s, "closed_only", contrast=(25.0, 100.0)) for s in _seeds(count)]
    else:
        frames = held_out_frames(n, count, name)
    return [Problem(f, case=name) for f in frames]
