"""Each baseline family (GAMG, AMGCL, pyamg) as its experts would report it: its default setting and its best
one among those a run swept (``cg_gamg``, ``cg_gamg_default`` and ``gamg_t<threshold>_a<levels>``;
``amgcl`` and ``amgcl_ce<K>``; ``pyamg`` and ``pyamg_sa``), beside HTPPC's default, per problem."""
from __future__ import annotations

import math

from .aggregate import cells
from .markdown import md_table, ms, n_label
from .methods import FAMILIES, family

HTP = "cg_htp"


def families(methods) -> dict:
    """{family: (its default method, [its methods in the run])} for the families present in ``methods``, in the
    order of :data:`~.methods.FAMILIES`."""
    out = {name: (default, []) for name, default, _ in FAMILIES}
    for m in methods:
        fam = family(m)
        if fam:
            out[fam[0]][1].append(m)
    return {name: v for name, v in out.items() if v[1]}


def _entry(c) -> str:
    return "—" if not c or not c["total_ms"]["count"] else f"{ms(c['total_ms']['median'])} ({c['iterations']['median']:.0f})"


def best_table(rows, methods, keys=("case", "n")) -> str:
    """Markdown: per problem (``keys``), HTPPC's default, and every family's default and best setting (median ms,
    iterations; the best among those that converged on every frame), and HTPPC's ratio to each best."""
    fams = families(methods)
    if not fams:
        return "(no baseline families in this run)"
    by = cells(rows, *keys, "method")
    head = ["N" if k in ("n", "scale") else k for k in keys] + [HTP]
    for fam in fams:
        head += [f"{fam} default", f"{fam} best", f"{HTP} / {fam} best"]
    body = []
    for key in dict.fromkeys(tuple(r.get(k) for k in keys) for r in rows):
        htp = by.get((*key, HTP))
        line = [n_label(v) if k in ("n", "scale") else str(v) for k, v in zip(keys, key)] + [_entry(htp)]
        for default, members in fams.values():
            done = [(c["total_ms"]["median"], m) for m in members
                    if (c := by.get((*key, m))) and c["total_ms"]["count"] and not c["failed"]]
            best = min(done, default=(math.nan, None))
            line += [_entry(by.get((*key, default))) if (*key, default) in by else "not run",
                     f"{_entry(by[(*key, best[1])])} {best[1]}" if best[1] else
                     "✗ all failed" if any((*key, m) in by for m in members) else "not run",
                     f"{htp['total_ms']['median'] / best[0]:.2f}" if best[1] and htp and htp["total_ms"]["count"]
                     else "—"]
        body.append(line)
    return md_table(head, body, left=len(keys))
