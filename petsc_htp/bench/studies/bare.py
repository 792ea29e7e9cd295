"""A bare single solve: the DMDA program's matrix (:func:`petsc_htp.scenes.gallery.variable_poisson`), nothing attached.

Each frame is a fresh Mat and KSP with no coordinates, density or null space, so the preconditioner's
whole setup (HTPPC's analysis included) is in the frame's time, as in ``examples/dmda_poisson.py``. One
warm-up solve per method (a frame of its own) keeps one-time costs such as first calls out.
"""
from __future__ import annotations

import numpy as np

from ...scenes.gallery import variable_poisson
from ...scenes.generator import Frame
from ..aggregate import cells
from ..cases import Problem
from ..markdown import md_table, ms, n_label
from .base import Size, Study, solve_all

SIDES = Size("bare_sides", [256], [32], "grid sides of the bare single-solve study")
FRAMES = Size("bare_frames", 3, 1, "coefficient fields (seeds) per side of the bare single-solve study")
CONTRAST = 1000.0


def frame(side, seed) -> Frame:
    """The DMDA problem as a :class:`~petsc_htp.scenes.Frame` (row-major cells)."""
    A, b, k = variable_poisson(side, side, CONTRAST, seed)
    y, x = np.divmod(np.arange(side * side), side)
    return Frame(A=A, b=b, rho=k.ravel(), coords=np.column_stack([(x + 0.5) / side, (y + 0.5) / side]),
                 grid_shape=(side, side), perm=np.arange(side * side),
                 params={"n": side * side, "seed": seed, "source": "dmda", "contrast": CONTRAST})


def problems(sides, frames) -> list:
    """Every side's frames, nothing attached."""
    return [Problem(frame(s, seed), case="bare", attach=False) for s in sides for seed in range(frames)]


def table(res) -> str:
    """Median setup + solve ms, mean iterations, per method and side."""
    by = cells(res.rows["bare"], "method", "n")
    scales = res.scales("bare")
    head = ["Method"] + [f"N={n_label(n)}: setup + solve ms (its)" for n in scales]
    body = [[m] + [f"{ms(c['setup_ms']['median'])} + {ms(c['solve_ms']['median'])} = "
                   f"**{ms(c['total_ms']['median'])}** ({c['iterations']['mean']:.0f})"
                   + (f" ✗{c['failed']}" if c["failed"] else "") if (c := by.get((m, n))) and c["total_ms"]["count"]
                   else (f"✗ {c['failure']}" if c else "—") for n in scales] for m in res.methods("bare")]
    return md_table(head, body)


class Bare(Study):
    """One bare solve of the DMDA variable-coefficient Poisson problem, setup included."""

    name = "bare"
    help = "a bare single solve (DMDA 5-point variable-coefficient Poisson, nothing attached, analysis included)"
    sizes = (SIDES, FRAMES)

    def meta(self, settings):
        return {"bare": {"sides": settings["bare_sides"], "frames": settings["bare_frames"], "contrast": CONTRAST}}

    def expected_solves(self, ctx):
        return len(ctx.methods) * len(ctx.settings["bare_sides"]) * ctx.settings["bare_frames"]

    def measure(self, ctx, tick):
        s = ctx.settings
        return solve_all(ctx.methods, problems(s["bare_sides"], s["bare_frames"]), ctx.extra, tick, "bare")

    def section(self, res):
        meta = res.meta.get("bare", {})
        return "\n\n".join([
            "## A bare single solve",
            f"`examples/dmda_poisson.py`'s matrix: 5-point variable-coefficient Poisson on a side x side grid in "
            f"row-major order, conductivity 1 with discs of {meta.get('contrast', CONTRAST):g}, Dirichlet boundaries, "
            f"handed over with nothing attached; {meta.get('frames', '?')} coefficient fields per side, each a "
            "fresh Mat and KSP, so the setup column holds the whole preconditioner setup (HTPPC's analysis "
            "included). Median ms, mean iterations; one warm-up solve per method excluded.",
            table(res),
        ])

    def summary(self, res):
        return table(res)


STUDY = Bare()
