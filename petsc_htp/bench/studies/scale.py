"""A plain PETSc DMDA program at scale on 1 and several ranks (:mod:`petsc_htp.bench.dmdarun`, one mpiexec process per
method, grid and rank count; methods take turns grid by grid): single solves and sequence mode, ms per frame, us per
unknown against N (is the cost O(N)?), strong scaling and peak memory. pyamg and AMGCL run on one rank only."""
from __future__ import annotations

import json
import math
import os
import shutil
import signal
import subprocess
import sys
from pathlib import Path

from ..aggregate import cells, value
from ..baselines import best_table
from ..markdown import image, md_table, median_cell, n_label
from .base import Size, Study

CHART = "scale.png"
SIDES_2D = Size("scale_sides_2d", [256, 1024, 2048], [48], "grid sides of the scale study's 2-D DMDA (N = side^2)")
SIDES_3D = Size("scale_sides_3d", [32, 64, 128], [10], "grid sides of the scale study's 3-D DMDA (N = side^3)")
RANKS = Size("scale_ranks", [1, 2], [1, 2], "MPI ranks of the scale study")
FRAMES = Size("scale_frames", 3, 1, "sequence frames after the single solve per grid of the scale study")


def grids(s) -> list:
    """(dim, side) of every grid, 2-D first, smallest first."""
    return [(2, n) for n in s["scale_sides_2d"]] + [(3, n) for n in s["scale_sides_3d"]]


TIMEOUT_S = 3600         # a worker that takes longer (a rank stuck in a collective) ends in a failure row


def run(method, dim, side, ranks, frames, threads=1, checkpoint=None, device=None) -> list:
    """:mod:`..dmdarun` under ``mpiexec -n ranks`` (the benchmark's threads, checkpoint and device): its rows; where
    it failed, its rows so far and a failure row naming its last error (also where it ran on other than ``ranks``
    ranks: an mpiexec of another MPI)."""
    mpiexec = shutil.which("mpiexec") or shutil.which("mpiexec", path=f"{Path(sys.executable).parent}:/usr/bin")
    cmd = [mpiexec or "mpiexec", "-n", str(ranks), sys.executable, "-m", "petsc_htp.bench.dmdarun", "--side", str(side),
           "--dim", str(dim), "--frames", str(frames), "--method", method.spec, "--threads", str(threads or 1)]
    cmd += [arg for flag, value in (("--checkpoint", checkpoint), ("--device", device)) if value
            for arg in (flag, str(value))]
    out, error = "", ""
    try:
        proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True)
        try:
            out, err = proc.communicate(timeout=TIMEOUT_S)
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)        # mpiexec and its ranks
            out, err = proc.communicate()
            error = f"timed out after {TIMEOUT_S} s"
    except OSError as exc:
        error = f"{type(exc).__name__}: {exc}"[:300]
    rows = _rows(out)
    if not error and proc.returncode and not (rows and rows[-1].get("failure") == "EXCEPTION"):
        error = ((err or out).strip().splitlines() or ["no output"])[-1][:300]
    if any(r["ranks"] != ranks for r in rows):
        rows, error = [], f"ran on {rows[0]['ranks']} rank(s), not {ranks}: mpiexec {mpiexec} is of another MPI"
    if error:
        rows.append({"method": method.name, "dim": dim, "side": side, "n": side ** dim, "ranks": ranks,
                     "frame": len(rows), "mode": "sequence" if rows else "single", "ok": False,
                     "failure": "EXCEPTION", "reason": "EXCEPTION", "error": error})
    for row in rows:
        row.update(method=method.name, case=f"{dim}-D, {ranks} rank{'s' if ranks > 1 else ''}", study="scale",
                   relres_proj=row.get("relres"))
    return rows


def _rows(out) -> list:
    """The JSON rows in a worker's output, one per frame (ranks that each print a failure row may interleave theirs:
    the first of a frame's is kept)."""
    rows, decoder, at = {}, json.JSONDecoder(), out.find('{"method"')
    while at >= 0:
        row, end = decoder.raw_decode(out, at)
        rows.setdefault(row["frame"], row)
        at = out.find('{"method"', end)
    return [rows[k] for k in sorted(rows)]


def _mode(res, mode) -> list:
    return [r for r in res.rows["scale"] if r.get("mode") == mode]


def times(rows, methods) -> str:
    """Median ms (iterations) per grid, rank count and method."""
    by = cells(rows, "dim", "n", "ranks", "method")
    body = []
    for dim, n, ranks in dict.fromkeys((r["dim"], r["n"], r["ranks"]) for r in rows):
        line = [f"{dim}-D", n_label(n), ranks]
        for m in methods:
            line.append(median_cell(by.get((dim, n, ranks, m))))
        body.append(line)
    return md_table(["grid", "N", "ranks"] + methods, body, left=3)


def per_unknown(rows, methods, dim) -> str:
    """Microseconds per unknown (median ms per frame over N) of the ``dim``-D grids per rank count and method, and
    its growth from the smallest N to the largest."""
    rows = [r for r in rows if r["dim"] == dim]
    by, ns = cells(rows, "ranks", "n", "method"), sorted({r["n"] for r in rows})
    body = []
    for ranks in dict.fromkeys(r["ranks"] for r in rows):
        for m in methods:
            us = [1e3 * value(by.get((ranks, n, m)), what="median") / n for n in ns]
            if not all(math.isnan(u) for u in us):
                growth = us[-1] / us[0] if len(us) > 1 else math.nan
                body.append([ranks, m] + [f"{u:.2f}" if not math.isnan(u) else "—" for u in us]
                            + ["—" if math.isnan(growth) else f"{growth:.2f}"])
    return md_table(["ranks", "method"] + [f"N = {n_label(n)}" for n in ns] + ["largest / smallest"], body, left=2)


def strong(rows, methods) -> str:
    """Setup + solve ms on the most ranks over that on one, per grid and method."""
    by = cells(rows, "dim", "n", "ranks", "method")
    most = max(r["ranks"] for r in rows)
    if most == 1:
        return "(one rank only in this run)"
    body = []
    for dim, n in dict.fromkeys((r["dim"], r["n"]) for r in rows):
        line = [f"{dim}-D", n_label(n)]
        for m in methods:
            one, many = (value(by.get((dim, n, r, m)), what="median") for r in (1, most))
            line.append("—" if math.isnan(one * many) else f"{many / one:.2f}")
        body.append(line)
    return md_table(["grid", "N"] + methods, body, left=2)


def memory(rows, methods) -> str:
    """Peak resident MiB summed over the ranks (the process's, matrix and imports included) per grid."""
    peak = {}
    for r in rows:
        if r.get("peak_rss_mb"):
            peak[(r["dim"], r["n"], r["ranks"], r["method"])] = r["peak_rss_mb"]
    body = [[f"{d}-D", n_label(n), k] + [f"{peak[(d, n, k, m)]:.0f}" if (d, n, k, m) in peak else "—" for m in methods]
            for d, n, k in dict.fromkeys(key[:3] for key in peak)]
    return md_table(["grid", "N", "ranks"] + methods, body, left=3)


def chart(res, out) -> str:
    """us per unknown against N, sequence mode, per method (solid: one rank, dashed: the most), 2-D and 3-D."""
    from ..plotting import colors, figure, save

    rows = _mode(res, "sequence") or _mode(res, "single")
    dims = sorted({r["dim"] for r in rows})
    by, color = cells(rows, "dim", "ranks", "method", "n"), colors(res.methods("scale"))
    fig, axes = figure(5.5 * len(dims), 4.2, 1, len(dims))
    for ax, dim in zip(axes[0], dims):
        for ranks, m in dict.fromkeys((r["ranks"], r["method"]) for r in rows if r["dim"] == dim):
            ns = sorted({r["n"] for r in rows if r["dim"] == dim and r["ranks"] == ranks and r["method"] == m})
            us = [1e3 * value(by.get((dim, ranks, m, n)), what="median") / n for n in ns]
            ax.plot(ns, us, "o-" if ranks == 1 else "s--", color=color[m], label=f"{m}, {ranks} rank(s)")
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("N")
        ax.set_ylabel("µs per unknown per frame (median)")
        ax.set_title(f"{dim}-D DMDA, {'sequence mode' if _mode(res, 'sequence') else 'single solves'}")
        ax.legend(fontsize=6)
    return save(fig, out, CHART)


class Scale(Study):
    """The DMDA program at scale on 1 and several ranks."""

    name = "scale"
    help = ("a plain PETSc DMDA program (2-D and 3-D, discs of contrast 1e3, Dirichlet) at scale on 1 and several "
            "MPI ranks, one process per method: single solves, sequence mode, us per unknown, strong scaling, memory")
    sizes = (SIDES_2D, SIDES_3D, RANKS, FRAMES)
    readme_links = ((CHART, "cost per unknown at scale"),)

    def meta(self, settings):
        return {"scale": {k: settings[s.name] for k, s in (("sides_2d", SIDES_2D), ("sides_3d", SIDES_3D),
                                                             ("ranks", RANKS), ("frames", FRAMES))}}

    def expected_solves(self, ctx):
        s = ctx.settings
        per_grid = sum(len(ctx.methods) if r == 1 else sum(m.is_petsc for m in ctx.methods) for r in s["scale_ranks"])
        return len(grids(s)) * per_grid

    def measure(self, ctx, tick):
        s, rows = ctx.settings, []
        for dim, side in grids(s):
            for ranks in s["scale_ranks"]:
                for m in ctx.methods:
                    if m.is_petsc or ranks == 1:
                        rows += run(m, dim, side, ranks, s["scale_frames"], ctx.threads, ctx.checkpoint,
                                    ctx.device)
                        tick()
        return rows

    def section(self, res):
        meta, methods = res.meta.get("scale", {}), res.methods("scale")
        single, seq = _mode(res, "single"), _mode(res, "sequence")
        return "\n\n".join([
            "## At scale: the DMDA program on 1 and several ranks",
            "`python -m petsc_htp.bench.dmdarun` under mpiexec, one process per method, grid and rank count "
            "(`petsc_htp.scenes.dmda`: 5-point / 7-point, 24 discs or balls of conductivity 1e3, Dirichlet, in the "
            "DMDA's numbering), after a warm-up grid. Single solve: frame 0, a fresh KSP, setup + solve ms "
            f"(iterations). Sequence mode: {meta.get('frames', '?')} more frames, the next seeds' discs put into "
            "the same Mat and solved by the same KSP (pyamg and AMGCL rebuild; they run on one rank only).",
            times(single, methods),
            "Each baseline family at its default and its best swept setting, single solves:",
            best_table(single, methods),
            "Sequence mode, median ms per frame (iterations):",
            times(seq, methods) if seq else "(none in this run)",
            best_table(seq, methods) if seq else "",
            "Microseconds per unknown per frame (sequence mode where run; AMGCL and pyamg rebuild every frame), "
            "2-D then 3-D:",
            *[per_unknown(seq or single, methods, dim) for dim in sorted({r["dim"] for r in single})],
            "Strong scaling: single-solve ms on the most ranks over one rank's (sequence mode below):",
            strong(single, methods),
            strong(seq, methods) if seq else "",
            "Peak resident memory, MiB, summed over the ranks (each process's, the matrix and imports included):",
            memory(single, methods),
            image(CHART, "Cost per unknown at scale"),
        ])

    def charts(self, res, out):
        return [chart(res, out)] if res.rows.get("scale") else []

    def summary(self, res):
        return times(_mode(res, "single"), res.methods("scale"))


STUDY = Scale()
