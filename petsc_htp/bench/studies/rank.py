"""Coarse-space size of the two-level variant: iterations, time and memory against r, eig against learned."""
from __future__ import annotations

import math

from ..aggregate import cells
from ..cases import table_problems
from ..markdown import its, md_table, ms, n_label, pm
from .base import Size, Study, solve_all

EIG = "cg_twolevel_eig"
LEARNED = "cg_twolevel_learned"


def rank_methods(ranks) -> list:
    """``cg_twolevel_eig`` at every r (named ``eig r=…``), then the learned coarse space at its network's r."""
    from ..methods import Method, resolve_method

    eig = resolve_method(EIG)
    return [Method(f"eig_r{r}", eig.path, (("htp_coarse_rank", str(r)),)) for r in ranks] + [resolve_method(LEARNED)]


def _rank(method) -> str:
    return method[len("eig_r"):] if method.startswith("eig_r") else "4 (network)"


def _reaching(by, ranks, n, target) -> str:
    """Smallest eig r whose mean iterations are at most ``target`` at N = n."""
    for r in ranks:
        c = by.get((f"eig_r{r}", n))
        if c and c["iterations"]["count"] and c["iterations"]["mean"] <= target:
            return f"at r = {r}"
    return f"at no r ≤ {ranks[-1]}"


class Rank(Study):
    """eig at r = 1 … 8 and learned (r = 4) on held-out frames, interleaved frame by frame."""

    name = "rank"
    help = "two-level coarse size: eig at every --ranks r against learned (iterations, setup, memory)"
    sizes = (Size("rank_scales", [4096, 16384], [256], "N of the rank study"),
             Size("ranks", [1, 2, 3, 4, 6, 8], [1, 4], "eig coarse vectors per leaf r of the rank study"),
             Size("rank_frames", 10, 2, "held-out frames per N of the rank study"))

    def meta(self, settings):
        return {"rank": {"scales": settings["rank_scales"], "ranks": settings["ranks"],
                         "frames": settings["rank_frames"]}}

    def expected_solves(self, ctx):
        s = ctx.settings
        return len(s["rank_scales"]) * s["rank_frames"] * (len(s["ranks"]) + 1)

    def measure(self, ctx, tick):
        s = ctx.settings
        problems = table_problems(s["rank_scales"], s["rank_frames"])
        return solve_all(rank_methods(s["ranks"]), problems, ctx.extra, tick, "rank")

    def section(self, res):
        rows = res.rows["rank"]
        by = cells(rows, "method", "n")
        meta = res.meta.get("rank", {})
        ranks, scales = meta.get("ranks", []), sorted({r["n"] for r in rows})
        methods = [f"eig_r{r}" for r in ranks] + [LEARNED]
        head = ["Coarse space", "r"] + [f"its, N={n_label(n)}" for n in scales] + \
            [f"setup + solve ms, N={n_label(n)}" for n in scales] + [f"B/unknown, N={n_label(n)}" for n in scales]
        table = []
        for m in methods:
            cs = [by.get((m, n)) for n in scales]
            table.append(["eig" if m.startswith("eig") else "learned", _rank(m)]
                         + [pm(c["iterations"], its) if c else "—" for c in cs]
                         + [f"{ms(c['setup_ms']['median'])} + {ms(c['solve_ms']['median'])}" if c else "—"
                            for c in cs]
                         + [f"{c['bytes_per_unknown']['median']:.0f}" if c and not math.isnan(
                             c["bytes_per_unknown"]["median"]) else "—" for c in cs])
        learned = {n: by[(LEARNED, n)]["iterations"]["mean"] for n in scales if (LEARNED, n) in by}
        reach = "; ".join(f"N = {n_label(n)}: learned (r = 4) {its(v)} its, eig reaches it "
                          f"{_reaching(by, ranks, n, v)}" for n, v in learned.items())
        return "\n\n".join([
            "## Coarse-space size (two-level variant)",
            f"CG + two-level HTP on {meta.get('frames', '?')} held-out frames per N, rtol 1e-8 (as the table), "
            "every coarse space solving each frame in turn: `eig` (one inverse-iteration step of each leaf's "
            "Neumann matrix from r smooth seeds) at every r, and the learned coarse space at its network's r = 4 "
            "(refined by the same step). Mean ± std iterations, median setup + solve ms, held bytes per unknown.",
            md_table(head, table),
            "Iterations of equal quality: " + (reach or "no learned rows") + ".",
        ])


STUDY = Rank()
