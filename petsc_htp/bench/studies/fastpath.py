"""The torch PCG fast path (CUDA Graphs on GPU, eager on CPU) on the table's frames."""
from __future__ import annotations

from ..aggregate import cells, group, summary
from ..cases import held_out_frames
from ..markdown import image, md_table, ms, n_label, time_cell
from ..plotting import time_bars
from .base import FRAMES, SCALES, Study

CHART = "fastpath.png"


def run(scales, frames, ckpt, device) -> list:
    """Every fast-path method on ``frames`` held-out frames per N; the first frame per N is a discarded warm-up."""
    from ...fastpath import METHODS, run_fastpath
    from ...paper.inference import HTP, resolve_device

    dev = resolve_device(device)
    methods, htp, note = list(METHODS), None, None
    try:
        htp = HTP.load(ckpt, device=str(dev))
    except Exception as exc:  # no usable checkpoint: the classical methods still run
        methods.remove("htp")
        note = f"htp skipped: {type(exc).__name__}: {exc}"
    rows = []
    for n in scales:
        held = held_out_frames(n, frames)
        rows += run_fastpath([held[0]] + held, methods, htp, dev)[len(methods):]
    for row in rows:
        row.update(study="fastpath", ok=row.get("reason") == "converged", note=note,
                   failure=None if row.get("reason") == "converged" else row.get("reason"))
    return rows


class Fastpath(Study):
    """The fast path's PCG with none, Jacobi, block Jacobi and HTP."""

    name = "fastpath"
    help = "torch CUDA-Graph PCG (eager on CPU), also --fastpath"
    sizes = (SCALES, FRAMES)
    readme_links = ((CHART, "fast path"),)

    def measure(self, ctx, tick):
        return run(ctx.settings["scales"], ctx.settings["frames"], ctx.checkpoint, ctx.device or "auto")

    def section(self, res):
        rows = res.rows["fastpath"]
        by = cells(rows, "method", "n")
        methods, scales = res.methods("fastpath"), res.scales("fastpath")
        device = rows[0].get("device", "?")
        head = ["Method"] + [n_label(n) for n in scales]
        main = [[m] + [time_cell(by.get((m, n))) for n in scales] for m in methods]
        per = []
        for m in methods:
            groups = group([r for r in rows if r["method"] == m], "n")
            per.append([m] + [f"{ms(summary(r.get('us_per_iter') for r in g)['median'])} / "
                              f"{ms(summary(r.get('us_per_apply') for r in g)['median'])} / "
                              f"{ms(summary(r.get('inference_ms') for r in g)['median'])}"
                              for (n,), g in sorted(groups.items())])
        where = (f"on {device}" if device != "cpu" else
                 "on the CPU: **no CUDA device on this machine, so the fast path ran eagerly (no CUDA Graphs)**")
        notes = sorted({r["note"] for r in rows if r.get("note")})
        return "\n\n".join([
            "## 8. Fast path (torch PCG, CUDA Graphs)",
            f"`petsc_htp.fastpath.run_fastpath` {where}, torch {rows[0].get('torch', '?')}, float32 vectors, "
            "same frames and rtol; setup + solve ms (iterations), mean over the frames (first frame per N a "
            "discarded warm-up)." + (" " + " ".join(notes) if notes else ""),
            md_table(head, main),
            "Median µs per iteration / µs per preconditioner apply / HTP inference ms:",
            md_table(head, per),
            image(CHART, "Fast path time per frame"),
        ])

    def charts(self, res, out):
        return [time_bars(res, out, "fastpath", CHART, "Fast path: per-frame time (setup hatched)")]


STUDY = Fastpath()
