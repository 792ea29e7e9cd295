"""Simulation: every method over a run of the two-phase flow, one persistent KSP, previous pressure as guess.

The run is recorded once per grid side (the pressure systems of :class:`petsc_htp.sim.flow.Flow`,
projected with ``cg_gamg``) and replayed by every method through
:class:`petsc_htp.sim.simulation.PressureSolver` and :class:`~petsc_htp.sim.simulation.ReusePolicy`, so
that all of them solve the same frames. HTP variants run with and without PC reuse; two-level ones
also rebuilt every frame with their coarse space kept for k frames (``-htp_coarse_space_every k``).
"""
from __future__ import annotations

import math

import numpy as np

from ...sim.flow import Flow
from ..harness import Loaded
from ...scenes.generator import Frame, row_major
from ..aggregate import FPS_BUDGETS, group, ordered
from ..cases import Problem, held_out_frames
from ..markdown import image, its, md_table, ms, n_label, ratio
from ..plotting import colors, figure, fps_lines, save
from .base import Size, Study, solve_all, tag

CHART = "simulation.png"
REFERENCE = "cg_gamg"       # projects the recorded run
RATIO_BAR = 1.3             # simulation / generator iterations an HTP variant should stay within
GROWTH = 1.5                # ReusePolicy's cap on a reused PC (the example's default)
DENSITY_RATIO = 1000.0      # the example's default


def _uses(method, text) -> bool:
    """True when the method's options (comments aside) contain ``text``."""
    if not method.is_petsc:
        return False
    lines = (li.split("#")[0] for li in method.path.read_text().splitlines())
    return any(text in " ".join(li.split()) for li in lines)


def is_htp(method) -> bool:
    """True when the method's options use ``petsc_htp.HTPPC``."""
    return _uses(method, "petsc_htp.HTPPC")


def is_twolevel(method) -> bool:
    """True when the method's options use HTPPC's two-level variant (its default: no ``-htp_variant paper``)."""
    return is_htp(method) and not (_uses(method, "-htp_variant paper") or _uses(method, "-sub_htp_variant paper"))


def recorded_run(side, frames, seed=0, dim=2):
    """The pressure systems of ``frames`` frames of a ``side`` x ``side`` (x ``side`` with ``dim`` 3) run,
    and the fluid regions.

    Returns
    -------
    systems : list of (A, b, coords, coefficient)
        ``coefficient`` is ``1/rho``, the operator's material coefficient (HTP's density feature).
    regions : numpy.ndarray of int
    """
    from petsc4py import PETSc

    from ...sim.simulation import PressureSolver
    from ..runner import PRINT_ONLY

    sim = Flow(side, side, nz=side if dim == 3 else None, density_ratio=DENSITY_RATIO, seed=seed)
    systems, solver = [], None
    with Loaded(REFERENCE, prefix="sim_reference_"):
        for name in PRINT_ONLY:
            PETSc.Options("sim_reference_").delValue(name)
        for _ in range(frames):
            sim.advance()
            A, b, coords, rho = sim.system()
            solver = solver or PressureSolver(A, sim.regions, "sim_reference_")
            solver.solve(A, b, coords, 1.0 / rho, rebuild=True)
            sim.project(solver.pressure())
            systems.append((A, b, coords, 1.0 / rho))
    solver.destroy()
    return systems, sim.regions


def flow_frames(n, count, seed=0, dim=2) -> list:
    """``count`` frames of a ``dim``-D run at about ``n`` cells as generator-style :class:`Frame` (rho = 1/rho)."""
    side = max(8, round(n ** (1.0 / dim)))
    systems, _ = recorded_run(side, count, seed, dim)
    sim = Flow(side, side, nz=side if dim == 3 else None, density_ratio=DENSITY_RATIO, seed=seed)
    return [Frame(A=A, b=b, rho=coef, coords=coords, grid_shape=(side,) * dim, perm=row_major(sim.idx, sim.shape),
                  params={"n": A.shape[0], "seed": k, "source": "flow"})
            for k, (A, b, coords, coef) in enumerate(systems)]


def frame_row(res, rtol) -> dict:
    """A replayed frame's row fields from :meth:`PressureSolver.solve`'s result."""
    from ..harness import reason_name

    code = res.pop("code")
    failure = (reason_name(code) if code < 0 else
               "RESIDUAL" if not res["relres"] <= 10 * rtol else None)
    return {"iterations": res.pop("its"), "reason": reason_name(code), "total_ms": res["setup_ms"] + res["solve_ms"],
            "ok": failure is None, "failure": failure, **res}


def replay(method, systems, regions, reuse, extra, keep=0) -> list:
    """One method over the recorded run (reuse: rebuild every ``reuse`` frames, 0 = every frame;
    keep: ``-htp_coarse_space_every keep``)."""
    from ...sim.simulation import PressureSolver, ReusePolicy
    from ..runner import load

    rows, loaded = [], load(method, list(extra) + ([("htp_coarse_space_every", str(keep))] if keep else []))
    solver = PressureSolver(systems[0][0], regions, method.prefix)
    rtol, policy = solver.ksp.getTolerances()[0], ReusePolicy(reuse, GROWTH)
    try:
        for frame, (A, b, coords, coef) in enumerate(systems):
            rebuild = policy.rebuild()
            try:
                row = frame_row(solver.solve(A, b, coords, coef, rebuild, policy.cap()), rtol)
            except Exception as exc:  # a failing frame is a result
                row = {"ok": False, "failure": "EXCEPTION", "reason": "EXCEPTION", "error": str(exc)[:200],
                       "iterations": 0, "total_ms": None, "rebuilt": rebuild, "reused_its": 0}
            if not row["ok"]:
                solver.x.set(0.0)       # no garbage initial guess for the next frame
            policy.record(row["rebuilt"], row["iterations"] - row["reused_its"])
            rows.append({"method": method.name, "htp": is_htp(method), "reuse": reuse, "keep": keep, "n": A.shape[0],
                         "frame": frame, "kind": "simulation", **row})
    finally:
        solver.destroy()
        loaded.__exit__(None, None, None)
    return rows


def replay_external(method, systems) -> list:
    """An external solver (pyamg, AMGCL) over the recorded run, rebuilt every frame from x0 = 0."""
    from ..harness import common_setting
    from ..external import solve

    rows, rtol = [], common_setting("ksp_rtol", 1e-8)
    for frame, (A, b, coords, coef) in enumerate(systems):
        try:
            res = solve(method.name, A, b, rtol, int(common_setting("ksp_max_it", 10000)))
            relres = float(np.linalg.norm(b - A @ res["x"]) / (np.linalg.norm(b) or 1.0))
            failure = (res["reason"] if res["reason"].startswith("DIVERGED") else
                       "RESIDUAL" if not relres <= 10 * rtol else None)
            row = {"iterations": res["iterations"], "reason": res["reason"], "setup_ms": res["setup_ms"],
                   "solve_ms": res["solve_ms"], "total_ms": res["setup_ms"] + res["solve_ms"], "relres": relres,
                   "ok": failure is None, "failure": failure}
        except Exception as exc:  # a failing frame is a result
            row = {"ok": False, "failure": "EXCEPTION", "reason": "EXCEPTION", "error": str(exc)[:200],
                   "iterations": 0, "total_ms": None}
        rows.append({"method": method.name, "htp": False, "reuse": 0, "keep": 0, "n": A.shape[0], "frame": frame,
                     "kind": "simulation", "rebuilt": True, "reused_its": 0, **row})
    return rows


def variants(method, every) -> list:
    """(reuse, keep) settings to run: rebuilt every frame; HTP variants also with PC reuse, two-level
    ones also with their coarse space kept ``every`` frames."""
    return ([(0, 0)] + [(every, 0)] * (is_htp(method) and every > 0)
            + [(0, every)] * (is_twolevel(method) and every > 1))


def run(methods, sides, frames, every, gen_frames, extra, tick) -> list:
    """Every method (and reuse setting) over the run at every side, then on ``gen_frames`` generator frames.

    PETSc methods replay the run through one persistent KSP; pyamg and AMGCL rebuild every frame.
    """
    from petsc4py import PETSc

    from ..external import missing

    PETSc.Log.begin()              # for the rows' pc_setups (PCSetUp events, inner PCs included)
    rows = []
    petsc = [m for m in methods if m.is_petsc]
    outside = [m for m in methods if not m.is_petsc and not missing(m.name)]
    for side in sides:
        systems, regions = recorded_run(side, frames)
        for m in petsc:
            for reuse, keep in variants(m, every):
                replay(m, systems[:1], regions, reuse, extra, keep)      # warm-up, discarded
                for row in replay(m, systems, regions, reuse, extra, keep):
                    rows.append(tag(row, side=side))
                    tick()
        for m in outside:
            replay_external(m, systems[:1])                               # warm-up, discarded
            for row in replay_external(m, systems):
                rows.append(tag(row, side=side))
                tick()
        gen = [Problem(f, case="generator") for f in held_out_frames(side * side, gen_frames)]
        rows += [tag(r, kind="generator", reuse=0, side=side, htp=is_htp(m))
                 for m in petsc + outside for r in solve_all([m], gen, extra, tick, "simulation", warmup=False)]
    return rows


# ------------------------------------------------------------------ report

def label(method, reuse, keep=0) -> str:
    """``cg_paper``, ``cg_paper reuse 5`` or ``cg_twolevel_eig keep W 5``."""
    return f"{method} reuse {reuse}" if reuse else f"{method} keep W {keep}" if keep else method


def stats(rows) -> dict:
    """Per-run numbers: ms per frame (mean, p95), mean iterations, setups (restarts at the cap among them),
    failures, frames over 41.7 ms."""
    t = np.array([r["total_ms"] for r in rows if r.get("total_ms") is not None])
    budget = max(b for _, b in FPS_BUDGETS)
    return {"frames": len(rows), "mean": float(t.mean()) if t.size else math.nan,
            "p95": float(np.percentile(t, 95)) if t.size else math.nan,
            "its": float(np.mean([r["iterations"] for r in rows if r["ok"]] or [math.nan])),
            "setups": sum(bool(r["rebuilt"]) for r in rows), "restarts": sum(bool(r.get("restarted")) for r in rows),
            "failed": sum(not r["ok"] for r in rows), "over": int(np.sum(t > budget))}


def _runs(res):
    """{(side, method, reuse, keep): simulation rows} and {(side, method): generator rows}, in run order."""
    rows = res.rows["simulation"]
    sim = group([{"keep": 0, **r} for r in rows if r["kind"] == "simulation"], "side", "method", "reuse", "keep")
    gen = group([r for r in rows if r["kind"] == "generator"], "side", "method")
    return sim, gen


def ratios(res) -> list:
    """[(side, method, HTP variant?, sim its, generator its, ratio)] of every method measured both ways.

    The simulation side is the run rebuilt every frame.
    """
    sim, gen = _runs(res)
    out = []
    for (side, m), g in gen.items():
        s = stats(sim.get((side, m, 0, 0), []))["its"]
        gi = float(np.mean([r["iterations"] for r in g if r["ok"]] or [math.nan]))
        out.append((side, m, bool(g[0].get("htp")), s, gi, s / gi))
    return out


def tables(res) -> str:
    """The per-run table and the iteration-ratio table."""
    sim, _ = _runs(res)
    head = ["Method", "N", "ms/frame mean", "p95", "mean its", "setups", "failures", "> 41.7 ms"]
    body = [[label(m, reuse, keep), n_label(rows[0]["n"]), ms(s["mean"]), ms(s["p95"]), its(s["its"]),
             f"{s['setups']}/{s['frames']}" + (f" ({s['restarts']} at the cap)" if s["restarts"] else ""),
             str(s["failed"]), str(s["over"])]
            for (side, m, reuse, keep), rows in sim.items() if (s := stats(rows))]
    rat = [[m + (" (HTP)" if htp else ""), f"{side}²", its(s), its(g), ratio(r),
            ("✓" if r <= RATIO_BAR else "✗") if htp else ""] for side, m, htp, s, g, r in ratios(res)]
    return "\n\n".join([md_table(head, body),
                        "Mean iterations on simulation frames (no reuse) over those on held-out generator frames "
                        f"at N = side² (fresh KSP, x0 = 0); the bar for HTP variants is a ratio within {RATIO_BAR}:",
                        md_table(["Method", "side", "sim its", "generator its", "ratio", f"≤ {RATIO_BAR}"], rat)])


def chart(res, out) -> str:
    """ms per frame over the run, one panel per grid side, with the 60 and 24 fps lines."""
    sim, _ = _runs(res)
    sides = ordered(k[0] for k in sim)
    names = ordered(k[1] for k in sim)
    color = colors(names)
    fig, axes = figure(6.5 * len(sides), 4.4, cols=len(sides))
    for ax, side in zip(axes[0], sides):
        for (s, m, reuse, keep), rows in sim.items():
            if s == side:
                ax.plot([r["frame"] for r in rows], [r.get("total_ms") or math.nan for r in rows],
                        color=color[m], ls="--" if reuse else ":" if keep else "-", lw=1,
                        label=label(m, reuse, keep))
        ax.set_yscale("log")
        ax.set_xlabel("frame")
        ax.set_ylabel("setup + solve ms")
        ax.set_title(f"{side} x {side} simulation (dashed: PC reuse; dotted: coarse space kept)")
        fps_lines(ax)
    axes[0, -1].legend(fontsize=7, ncol=2)
    return save(fig, out, CHART)


class Simulation(Study):
    """Methods over a run of the two-phase flow simulation."""

    name = "simulation"
    help = ("methods over a run of the two-phase flow (persistent KSP, previous pressure as guess; HTP variants "
            "with and without PC reuse, two-level ones also with the coarse space kept): ms per frame, "
            "iterations, setups, failures, sim/generator iterations")
    sizes = (Size("sim_n", [64, 128], [32], "grid sides of the simulation study"),
             Size("sim_frames", 50, 4, "frames per simulation run"),
             Size("sim_reuse", 5, 2, "HTP reuse runs rebuild every k frames (two-level: also the coarse space "
                                      "kept k frames)"),
             Size("sim_gen_frames", 5, 1, "generator frames per N for the iteration ratio"))
    readme_links = ((CHART, "simulation frames"),)

    def meta(self, settings):
        return {"sim": {"sides": settings["sim_n"], "frames": settings["sim_frames"],
                        "reuse": settings["sim_reuse"], "gen_frames": settings["sim_gen_frames"]}}

    def expected_solves(self, ctx):
        s = ctx.settings
        runs = sum(len(variants(m, s["sim_reuse"])) if m.is_petsc else 1 for m in ctx.methods)
        return len(s["sim_n"]) * (runs * s["sim_frames"] + len(ctx.methods) * s["sim_gen_frames"])

    def measure(self, ctx, tick):
        s = ctx.settings
        return run(ctx.methods, s["sim_n"], s["sim_frames"], s["sim_reuse"], s["sim_gen_frames"], ctx.extra, tick)

    def section(self, res):
        meta = res.meta.get("sim", {})
        return "\n\n".join([
            "## 9. Simulation",
            f"{meta.get('frames', '?')} frames of `examples/multiphase_flow.py`'s scene (density ratio "
            f"{DENSITY_RATIO:g}) per grid side, recorded once (projected with {REFERENCE}) and replayed by every "
            "method with one persistent KSP and the previous pressure as initial guess; HTP variants also with "
            f"PC reuse (rebuild every {meta.get('reuse', '?')} frames, or within a frame once the reused PC has "
            f"taken {GROWTH}× the iterations of the last rebuilt frame: the solve then goes on from that iterate); "
            f"two-level variants also rebuilt every frame with their coarse space kept for {meta.get('reuse', '?')} "
            "frames (`keep W`: `-htp_coarse_space_every`, like GAMG's `-pc_gamg_reuse_interpolation`). "
            "ms per frame = setup + solve over every frame (failed ones included); setups: frames whose PC "
            "was rebuilt (the others run with `PCSetReusePreconditioner`); one warm-up frame per run is excluded.",
            tables(res),
            image(CHART, "ms per frame over the simulation"),
        ])

    def charts(self, res, out):
        return [chart(res, out)]

    def readme(self, res, prefix):
        return "### Simulation\n\n" + tables(res) + "\n\n" + image(CHART, "Simulation", prefix)

    def summary(self, res):
        return tables(res)


STUDY = Simulation()
