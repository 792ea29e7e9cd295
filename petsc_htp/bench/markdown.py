"""Markdown for the report and README: number formats, tables, image links and time cells."""
from __future__ import annotations

import math


def missing(x) -> bool:
    """True for None and non-finite numbers."""
    return x is None or (isinstance(x, float) and not math.isfinite(x))


def ms(x) -> str:
    """Milliseconds with precision that suits their size."""
    if missing(x):
        return "—"
    if x < 10:
        return f"{x:.2f}"
    if x < 1000:
        return f"{x:.1f}"
    return f"{x:,.0f}"


def its(x) -> str:
    """A (mean) iteration count, rounded."""
    return "—" if missing(x) else f"{x:,.0f}"


def pm(s, fmt) -> str:
    """``mean ± std`` of a :func:`petsc_htp.bench.aggregate.summary`."""
    return "—" if missing(s["mean"]) else f"{fmt(s['mean'])} ± {fmt(s['std'])}"


def tol(x) -> str:
    """A tolerance such as 1e-8."""
    return f"{x:g}".replace("e-0", "e-")


def sci(x) -> str:
    """Scientific notation with two digits."""
    return "—" if missing(x) else f"{x:.1e}"


def ratio(x) -> str:
    """A speed-up or reduction factor."""
    if missing(x):
        return "—"
    return f"{x:.2f}×" if x >= 0.1 else f"{x:.2g}×"


def n_label(n) -> str:
    """N with a thin thousands separator, as in the paper's tables."""
    return f"{n:,}".replace(",", " ")


def md_table(header, rows, left=1) -> str:
    """A GitHub-flavoured Markdown table; the first ``left`` columns left-aligned, the others right-aligned."""
    def line(cells):
        return "| " + " | ".join(str(c).replace("|", "\\|") for c in cells) + " |"

    rule = "|" + "|".join([":---"] * left + ["---:"] * (len(header) - left)) + "|"
    return "\n".join([line(header), rule] + [line(row) for row in rows])


def image(name, title, prefix="") -> str:
    """A Markdown image of chart ``name`` (``prefix`` is its folder relative to the document)."""
    return f"![{title}]({prefix}{name})"


def time_cell(c, bold=False) -> str:
    """A :func:`~petsc_htp.bench.aggregate.cell` as ``mean ms (mean iterations)`` with its failures."""
    if c is None:
        return "—"
    if not c["total_ms"]["count"]:
        return f"✗ {c['failure']}"
    text = f"{ms(c['total_ms']['mean'])} ({its(c['iterations']['mean'])})"
    text = f"**{text}**" if bold else text
    return text + (f" ✗{c['failed']}/{c['frames']} {c['failure']}" if c["failed"] else "")


def median_cell(c) -> str:
    """A :func:`~petsc_htp.bench.aggregate.cell` as ``median ms (median iterations)``, its failed frames counted."""
    if c is None:
        return "—"
    if not c["total_ms"]["count"]:
        return f"✗ {c['failure']}"
    return (f"{ms(c['total_ms']['median'])} ({c['iterations']['median']:.0f})"
            + (f" ✗{c['failed']}" if c["failed"] else ""))
