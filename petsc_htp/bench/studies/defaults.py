"""Defaults by time: the two-level variant over leaf size, coarse rank, overlap, form and coarse solver, in
sequence mode.

Every configuration is ``cg_twolevel_eig`` (or ``cg_twolevel_const``) with ``-htp_leaf L -htp_coarse_rank r
-htp_overlap k -htp_form f -htp_coarse_tol 0``, a leaf factorisation (``-htp_leaf_pc_type``: cholesky,
exact, or icc) and a coarse solver (``-htp_coarse_solver``: lu or gamg) and solves the sequence study's frames (:mod:`.sequence`, methods interleaved frame by
frame). Configurations are ranked by the geometric mean over N of their median ms per frame relative to the
fastest configuration at that N; the default is the first whose every frame (the first included) took at
most :data:`ITERATION_BAR` CG iterations (35 in 2-D, 40 in 3-D).
"""
from __future__ import annotations

import math

import numpy as np

from ..aggregate import cells, pareto_front
from ..markdown import image, its, md_table, ms, n_label, ratio
from ..plotting import figure, save
from .base import DIM, Size, Study

CHART = "defaults.png"
SCALES = Size("defaults_scales", [16384, 65536], [256, 1024], "N of the defaults sweep")
FRAMES = Size("defaults_frames", 5, 2, "frames per N of the defaults sweep")
LEAVES = Size("defaults_leaves", [16, 32, 64, 128, 256, 512], [32, 64], "leaf sizes L of the defaults sweep")
RANKS = Size("defaults_ranks", [2, 3, 4, 6, 8], [2, 4], "coarse ranks r of the defaults sweep")
OVERLAPS = Size("defaults_overlaps", [0, 1], [0, 1], "leaf overlaps of the defaults sweep")
LEAF_PCS = Size("defaults_leaf_pcs", ["cholesky"], ["cholesky"],
                "leaf factorisations of the defaults sweep: cholesky (exact) and/or icc", kind=str)
FORMS = Size("defaults_forms", ["deflated", "balanced"], ["deflated", "balanced"], "forms of the defaults sweep",
             kind=str)
COARSE_SOLVERS = Size("defaults_coarse_solvers", ["lu"], ["lu"], "coarse solvers of the defaults sweep: lu and/or gamg",
                      kind=str)
ITERATION_BAR = {2: 35, 3: 40}     # the most CG iterations a default may take on any frame, by dimension


def configurations(leaves, ranks, overlaps, leaf_pcs=("cholesky",), forms=("deflated", "balanced"),
                   solvers=("lu",)) -> list:
    """Every (name, coarse, L, r, overlap, form, leaf PC, coarse solver) of the sweep: eig at every r > 1 (r = 1
    is const), const once per L."""
    out = []
    for solver in solvers:
        for pc in leaf_pcs:
            tail = ("" if pc == "cholesky" else f" {pc}") + ("" if solver == "lu" else f" {solver}")
            for L in leaves:
                for ov in overlaps:
                    for form in forms:
                        out += [(f"eig L{L} r{r} ov{ov} {form}{tail}", "eig", L, r, ov, form, pc, solver)
                                for r in ranks if r > 1]
                        out.append((f"const L{L} ov{ov} {form}{tail}", "const", L, 1, ov, form, pc, solver))
    return out


def sweep_methods(leaves, ranks, overlaps, leaf_pcs=("cholesky",), forms=("deflated", "balanced"),
                  solvers=("lu",)) -> list:
    """The sweep's configurations as benchmark methods."""
    from ..methods import Method, resolve_method

    base = {"eig": resolve_method("cg_twolevel_eig"), "const": resolve_method("cg_twolevel_const")}
    out = []
    for name, coarse, L, r, ov, form, pc, solver in configurations(leaves, ranks, overlaps, leaf_pcs, forms,
                                                                    solvers):
        extra = (("htp_leaf", str(L)), ("htp_overlap", str(ov)), ("htp_form", form), ("htp_coarse_tol", "0"),
                 ("htp_leaf_pc_type", pc), ("htp_coarse_solver", solver))
        extra += (("htp_coarse_rank", str(r)),) if coarse == "eig" else ()
        out.append(Method(name.replace(" ", "_"), base[coarse].path, extra))
    return out


def _label(method) -> str:
    return method.replace("_", " ")


def table(res) -> tuple:
    """{(method, n): cell} of the frames after the first, the scales, and the configurations by overall rank."""
    rows = [r for r in res.rows["defaults"] if r.get("kind") == "frame" and not r.get("first")]
    by = cells(rows, "method", "n")
    scales = sorted({r["n"] for r in rows})
    best = {n: min((c["total_ms"]["median"] for (m, k), c in by.items() if k == n and not c["failed"]
                    and c["total_ms"]["count"]), default=math.nan) for n in scales}
    score = {}
    for m in dict.fromkeys(r["method"] for r in rows):
        cs = [by.get((m, n)) for n in scales]
        if all(c and not c["failed"] and c["total_ms"]["count"] for c in cs):
            score[m] = float(np.exp(np.mean([np.log(c["total_ms"]["median"] / best[n]) for c, n in zip(cs, scales)])))
    return by, scales, sorted(score, key=score.get), score


def most_iterations(res) -> dict:
    """The most CG iterations each configuration took on any frame (the first included)."""
    out = {}
    for r in res.rows["defaults"]:
        if r.get("kind") == "frame":
            out[r["method"]] = max(out.get(r["method"], 0), r.get("iterations") or 0)
    return out


def chosen(res) -> str | None:
    """The fastest configuration (geometric mean over N) within the iteration bar on every frame, or None."""
    worst = most_iterations(res)
    bar = ITERATION_BAR[res.meta.get("defaults", {}).get("dim", 2)]
    return next((m for m in table(res)[2] if worst.get(m, math.inf) <= bar), None)


def body(res, top=12) -> str:
    by, scales, order, score = table(res)
    worst = most_iterations(res)
    head = (["Configuration"] + [f"N={n_label(n)}: ms (its)" for n in scales]
            + ["most its", "× fastest (geo. mean)"])
    rows = [[_label(m)] + [f"{ms(by[(m, n)]['total_ms']['median'])} ({its(by[(m, n)]['iterations']['mean'])})"
                           for n in scales] + [str(worst.get(m, "—")), ratio(score[m])] for m in order[:top]]
    return md_table(head, rows)


def forms(res) -> str:
    """An application's cost in MatMults of A, deflated against balanced, for the picked leaf size and rank."""
    pick = chosen(res)
    apply = {(r["method"], r["n"]): r for r in res.rows["defaults"] if r.get("kind") == "apply"}
    if not pick:
        return ""
    lines = []
    for form in ("deflated", "balanced"):
        name = pick.replace("deflated", form).replace("balanced", form)
        for (m, n), a in sorted(apply.items()):
            if m == name:
                lines.append([_label(m), n_label(n), ms(a["apply"]), f"{a['apply'] / a['matmult']:.1f}"]
                             + [f"{a[k] / a['matmult']:.1f}" for k in ("leaf solve", "coarse solve", "thin products")])
    return md_table(["Configuration", "N", "apply ms", "in MatMults", "leaf solve", "coarse solve(s)",
                     "thin products"], lines, left=2)


def solvers(res) -> str:
    """The picked configuration with each coarse solver swept, N by N: median ms per frame (mean iterations)."""
    pick, names = chosen(res), res.meta.get("defaults", {}).get("solvers", ["lu"])
    if not pick or len(names) < 2:
        return ""
    by, scales, _, _ = table(res)
    base = pick
    for solver in names:
        base = base.removesuffix(f"_{solver}")
    rows = []
    for solver in names:
        m = base + ("" if solver == "lu" else f"_{solver}")
        rows.append([solver] + [f"{ms(by[(m, n)]['total_ms']['median'])} ({its(by[(m, n)]['iterations']['mean'])})"
                                if (m, n) in by else "—" for n in scales])
    return ("The picked configuration with each coarse solver, N by N (`-htp_coarse_solver auto` takes the LU up "
            "to a coarse size and GAMG above it, `petsc_htp.twolevel.sizing.COARSE_DIRECT_MAX`, in 2-D on several ranks "
            "`COARSE_REDUNDANT_MAX`):\n\n"
            + md_table(["Coarse solver of " + _label(base)] + [f"N={n_label(n)}: ms (its)" for n in scales], rows))


def chart(res, out) -> str:
    """ms per frame against mean iterations of every configuration, one panel per N; the front joined."""
    by, scales, order, _ = table(res)
    fig, axes = figure(5.2 * len(scales), 4.2, cols=len(scales))
    for ax, n in zip(axes[0], scales):
        pts = [(m, by[(m, n)]) for m in order if (m, n) in by]
        xy = [(c["iterations"]["mean"], c["total_ms"]["median"]) for _, c in pts]
        for (m, _), (x, y) in zip(pts, xy):
            kind = "o" if "ov0" in m else "s"
            ax.plot(x, y, kind, ms=4, color="tab:blue" if "deflated" in m else "tab:orange", alpha=0.7)
        front = pareto_front(xy)
        ax.plot([xy[i][0] for i in front], [xy[i][1] for i in front], "k-", lw=1, label="front")
        if order:
            c = by.get((order[0], n))
            ax.plot(c["iterations"]["mean"], c["total_ms"]["median"], "r*", ms=12, label="default: " + _label(order[0]))
        ax.set_xlabel("mean CG iterations")
        ax.set_ylabel("median ms per frame (setup + solve)")
        ax.set_yscale("log")
        ax.set_title(f"N={n_label(n)} (blue deflated, orange balanced; o overlap 0, s overlap 1)", fontsize=8)
        ax.legend(fontsize=7)
    return save(fig, out, CHART)


class Defaults(Study):
    """The sweep that picks HTPPC's defaults by time."""

    name = "defaults"
    help = "defaults by time: two-level leaf size, coarse rank, overlap and form in sequence mode; the front"
    sizes = (SCALES, FRAMES, LEAVES, RANKS, OVERLAPS, LEAF_PCS, FORMS, COARSE_SOLVERS, DIM)
    readme_links = ((CHART, "defaults sweep"),)

    def meta(self, settings):
        return {"defaults": {k: settings[s.name] for k, s in (("scales", SCALES), ("frames", FRAMES),
                                                                ("leaves", LEAVES), ("ranks", RANKS),
                                                                ("overlaps", OVERLAPS), ("leaf_pcs", LEAF_PCS),
                                                                ("forms", FORMS), ("solvers", COARSE_SOLVERS),
                                                                ("dim", DIM))}}

    def _methods(self, s):
        return sweep_methods(s["defaults_leaves"], s["defaults_ranks"], s["defaults_overlaps"],
                             s["defaults_leaf_pcs"], s["defaults_forms"], s["defaults_coarse_solvers"])

    def expected_solves(self, ctx):
        s = ctx.settings
        return len(self._methods(s)) * len(s["defaults_scales"]) * s["defaults_frames"]

    def measure(self, ctx, tick):
        from .sequence import run

        s = ctx.settings
        rows = run(self._methods(s), s["defaults_scales"], s["defaults_frames"], ctx.extra, tick, s["dim"])
        return [{**r, "study": "defaults"} for r in rows]

    def section(self, res):
        meta = res.meta.get("defaults", {})
        pick = chosen(res)
        return "\n\n".join([
            "## Defaults by time (two-level variant)",
            f"{meta.get('dim', 2)}-D scenes: `cg_twolevel_eig` at leaf sizes {meta.get('leaves')}, coarse ranks "
            f"{meta.get('ranks')}, overlaps {meta.get('overlaps')}, leaf factorisations "
            f"{meta.get('leaf_pcs', ['cholesky'])}, forms {meta.get('forms', ['deflated', 'balanced'])} and coarse "
            f"solvers {meta.get('solvers', ['lu'])}, and `cg_twolevel_const` at each leaf size, "
            f"overlap, factorisation, form and coarse solver (`-htp_coarse_tol 0`), in sequence mode ({meta.get('frames', '?')} "
            "frames per N, configurations "
            "interleaved frame by frame). Median ms per frame (setup + solve) after the first frame, mean "
            "iterations, the most iterations on any frame; ranked by the geometric mean over N of the time "
            "relative to the fastest configuration at that N (the fastest 12):",
            body(res),
            f"Picked: **{_label(pick) if pick else '—'}**, the fastest configuration that took at most "
            f"{ITERATION_BAR[meta.get('dim', 2)]} iterations on every frame.",
            "One application of the picked leaf size and rank in each form, in MatMults of A (the deflated form: "
            "one leaf solve, one coarse solve and two thin products; the balanced one: a second coarse solve "
            "and three more thin products):",
            forms(res),
            *filter(None, [solvers(res)]),
            image(CHART, "Defaults sweep"),
        ])

    def charts(self, res, out):
        return [chart(res, out)]

    def summary(self, res):
        pick = chosen(res)
        return body(res) + f"\n\nPicked: {_label(pick) if pick else '—'}"


STUDY = Defaults()
