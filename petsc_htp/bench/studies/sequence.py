"""Sequence mode: one nonzero pattern and new values every frame, one persistent Mat and KSP per method.

The held-out test frames of one N share the generator's pattern. Every PETSc method solves them through a
:class:`petsc_htp.sim.simulation.PressureSolver` (the frame's values set into its Mat, coordinates and density
attached, x0 = 0), so PETSc runs its preconditioner's setup again each frame on the same pattern: GAMG
with its interpolation reused (``cg_gamg.opts``), HTPPC's numeric step only. pyamg and AMGCL rebuild from
scratch. Methods take turns frame by frame; a warm-up frame per method and N, on a solver of its own, is
left out. Two-level HTPPC rows also record the numeric step's phases and the first frame's setup
(analysis included), and once per N the parts of an application in MatMults of A.
"""
from __future__ import annotations

import math

import numpy as np

from ..aggregate import cells, group
from ..cases import held_out_frames
from ..markdown import image, its, md_table, ms, n_label, ratio
from ..plotting import time_bars
from ..applycosts import apply_costs
from ..baselines import best_table
from .base import DIM, Size, Study, tag

CHART = "sequence.png"
SCALES = Size("seq_scales", [16384, 65536], [256, 1024], "N of the sequence study")
FRAMES = Size("seq_frames", 20, 3, "frames per N of the sequence study")
PHASES = ("leaf", "coarse_space", "products", "coarse_factor")


def _ctx(solver):
    """The HTPPC context of a solver's PC when it is the two-level variant, else None."""
    pc = solver.ksp.getPC()
    ctx = pc.getPythonContext() if pc.getType() == "python" else None
    return ctx if ctx is not None and hasattr(getattr(ctx, "setup", None), "forms") else None


def _petsc_row(solver, frame, rtol) -> dict:
    """Solve one frame with a persistent solver; its row (with the two-level phases)."""
    from .simulation import frame_row

    row = frame_row(solver.solve(frame.A, frame.b, frame.coords, frame.rho, rebuild=True), rtol)
    ctx = _ctx(solver)
    if ctx is not None:
        row.update(phases=dict(ctx.setup.times), analysis_ms=ctx.setup.analysis_ms,
                   analyses=ctx.analysis_count)
    return row


def _solvers(methods, first, extra) -> tuple:
    """Options loaded and a persistent solver for every PETSc method (after one warm-up frame each)."""
    from scipy.sparse.csgraph import connected_components

    from ...sim.simulation import PressureSolver
    from ..runner import load

    regions = connected_components(first.A, directed=False)[1]
    loaded, solvers = [], {}
    for m in methods:
        if m.is_petsc:
            loaded.append(load(m, extra))
            warm = PressureSolver(first.A, regions, m.prefix, warm=False)
            try:
                warm.solve(first.A, first.b, first.coords, first.rho, rebuild=True)
            except Exception:  # the method fails again on every frame, and its rows say why
                pass
            finally:
                warm.destroy()
            solvers[m.name] = PressureSolver(first.A, regions, m.prefix, warm=False)
    return loaded, solvers


def run(methods, scales, frames, extra, tick, dim=2) -> list:
    """Every method over ``frames`` held-out frames per N, frame by frame, one persistent solver each."""
    from ..external import missing
    from ..runner import solve_method, exception_row, peak_rss_mb
    from ..cases import Problem

    rows = []
    for n in scales:
        seq = held_out_frames(n, frames + 1, dim=dim)
        loaded, solvers = _solvers(methods, seq[0], extra)
        try:
            for m in methods:
                if not m.is_petsc and not missing(m.name):
                    solve_method(m, m.prefix, Problem(seq[0], case="sequence"), False)       # warm-up
            for k, frame in enumerate(seq[1:]):
                for m in methods:
                    if m.is_petsc:
                        try:
                            row = _petsc_row(solvers[m.name], frame, solvers[m.name].ksp.getTolerances()[0])
                        except Exception as exc:  # a failing frame is a result
                            row = exception_row(m, Problem(frame), exc)
                        row.update(method=m.name, n=n, peak_rss_mb=peak_rss_mb())
                    else:
                        row = solve_method(m, m.prefix, Problem(frame, case="sequence"), False)
                    rows.append(tag(row, study="sequence", kind="frame", frame=k, first=k == 0))
                    tick()
            for m in methods:
                ctx = _ctx(solvers[m.name]) if m.is_petsc else None
                if ctx is not None:
                    rows.append({"study": "sequence", "kind": "apply", "method": m.name, "n": n,
                                 **apply_costs(ctx.setup)})
        finally:
            for s in solvers.values():
                s.destroy()
            for entry in reversed(loaded):
                entry.__exit__(None, None, None)
    return rows


def _frames(res):
    return [r for r in res.rows["sequence"] if r.get("kind") == "frame"]


def times(res) -> str:
    """Median ms per frame (setup + solve) and mean iterations, per method and N; the first frame left out."""
    rows = [r for r in _frames(res) if not r.get("first")]
    by, methods = cells(rows, "method", "n"), res.methods("sequence")
    scales = sorted({r["n"] for r in rows})
    body = [[m] + [f"{ms(c['total_ms']['median'])} ({its(c['iterations']['mean'])})" + (
        f" ✗{c['failed']}" if c["failed"] else "") if (c := by.get((m, n))) else "—" for n in scales] for m in methods]
    return md_table(["Method"] + [n_label(n) for n in scales], body)


def phases(res) -> str:
    """Two-level rows: first setup, numeric step and its phases, apply parts in MatMults of A."""
    fr = group(_frames(res), "method", "n")
    apply = {(r["method"], r["n"]): r for r in res.rows["sequence"] if r.get("kind") == "apply"}
    head = ["Method", "N", "first setup ms", "numeric ms", "numeric / first"] + [p.replace("_", " ") for p in PHASES] \
        + ["apply ms", "apply in MatMults", "leaf solve", "coarse solve", "thin products"]
    body = []
    for (m, n), rows in fr.items():
        if "phases" not in rows[0]:
            continue
        first = [r["setup_ms"] for r in rows if r.get("first") and r.get("ok")]
        later = [r for r in rows if not r.get("first") and r.get("ok")]
        numeric = float(np.median([r["setup_ms"] for r in later])) if later else math.nan
        med = {p: float(np.median([r["phases"][p] for r in later])) if later else math.nan for p in PHASES}
        a = apply.get((m, n), {})
        unit = a.get("matmult") or math.nan
        body.append([m, n_label(n), ms(first[0] if first else math.nan), ms(numeric),
                     ratio(numeric / first[0]) if first else "—"] + [ms(med[p]) for p in PHASES]
                    + [ms(a.get("apply")), f"{a.get('apply', math.nan) / unit:.1f}"]
                    + [f"{a.get(k, math.nan) / unit:.1f}" for k in ("leaf solve", "coarse solve", "thin products")])
    return md_table(head, body, left=2) if body else "(no two-level HTPPC method in this run)"


class Sequence(Study):
    """Sequence mode (one pattern, values changing per frame, persistent KSP)."""

    name = "sequence"
    help = ("one pattern, new values every frame: each method keeps one Mat and one KSP (GAMG reuses its "
            "interpolation, HTPPC runs its numeric step), pyamg and AMGCL rebuild; ms per frame, the two-level "
            "numeric step's phases and apply parts")
    default = True
    sizes = (SCALES, FRAMES, DIM)
    readme_links = ((CHART, "sequence mode"),)

    def meta(self, settings):
        return {"sequence": {"scales": settings["seq_scales"], "frames": settings["seq_frames"], "dim": settings["dim"]}}

    def expected_solves(self, ctx):
        return len(ctx.methods) * len(ctx.settings["seq_scales"]) * ctx.settings["seq_frames"]

    def measure(self, ctx, tick):
        s = ctx.settings
        return run(ctx.methods, s["seq_scales"], s["seq_frames"], ctx.extra, tick, s["dim"])

    def section(self, res):
        meta = res.meta.get("sequence", {})
        return "\n\n".join([
            "## Sequence mode (one pattern, new values per frame)",
            f"{meta.get('frames', '?')} held-out frames per N, which share one nonzero pattern, solved in turn by "
            "every method with one persistent Mat and KSP (x0 = 0): PETSc sets each preconditioner up again on the "
            "new values (GAMG reusing its interpolation, HTPPC's numeric step only); pyamg and AMGCL rebuild. "
            "Median ms per frame (setup + solve) over the frames after the first, mean iterations in parentheses; "
            "one warm-up frame per method and N is excluded.",
            times(res),
            "Each baseline family at its default and its best swept setting (ms per frame, iterations):",
            best_table([r for r in _frames(res) if not r.get("first")], res.methods("sequence"), ("n",)),
            "Two-level HTPPC: the first frame's setup (analysis included) against the median numeric step of the "
            "later frames and its phases (ms), and the parts of one application (the form in use) in MatMults "
            "of A:",
            phases(res),
            image(CHART, "Sequence mode"),
        ])

    def charts(self, res, out):
        from ..report import Results

        rows = [r for r in _frames(res) if not r.get("first")]
        return [time_bars(Results(res.meta, {"sequence": rows}), out, "sequence", CHART,
                          "Sequence mode: ms per frame (setup hatched)")]

    def readme(self, res, prefix):
        return "### Sequence mode\n\n" + times(res) + "\n\n" + phases(res) + "\n\n" + image(CHART, "Sequence", prefix)

    def summary(self, res):
        return times(res) + "\n\n" + phases(res)


STUDY = Sequence()
