"""``report.md``: the header and each study's section, built only from the raw rows and ``meta.json``.

The same rows always give the same text, so ``--report-only DIR`` reproduces
a report byte for byte.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from . import store
from .aggregate import ordered
from .markdown import tol
from .studies import STUDIES


@dataclass
class Results:
    """A results folder: ``meta.json`` and the rows of every study that ran."""

    meta: dict
    rows: dict

    def methods(self, study) -> list:
        """Method names of a study's rows, in the order the run listed them."""
        return ordered((r["method"] for r in self.rows.get(study, [])), self.meta.get("methods", ()))

    def scales(self, study) -> list:
        """Sorted distinct N of a study's rows."""
        return sorted({r["n"] for r in self.rows.get(study, []) if r.get("n")})


def load(out) -> Results:
    """Read ``meta.json`` and the ``<study>.jsonl`` rows of every study of a results folder."""
    if not (Path(out) / store.META).is_file():
        raise ValueError(f"{out} is not a results folder (no {store.META})")
    rows = {s.data: store.read_jsonl(store.study_path(out, s.data)) for s in STUDIES.values()}
    return Results(store.read_json(f"{out}/{store.META}"), {s: r for s, r in rows.items() if r})


def present(res) -> list:
    """The studies whose rows the folder has, in registry order."""
    return [s for s in STUDIES.values() if s.data in res.rows]


def header(res) -> str:
    """Title, machine, software, protocol and the command that produced the folder."""
    m = res.meta
    mach = m.get("machine", {})
    ck = m.get("checkpoint") or {}
    lines = [
        "# petsc_htp benchmark",
        "",
        f"- Date: {m.get('date', '?')}; commit `{m.get('commit') or 'unknown'}`",
        f"- Machine: {mach.get('cpu', '?')} ({mach.get('cores', '?')} cores), {mach.get('platform', '?')}",
        "- Software: " + ", ".join(f"{k} {v}" for k, v in sorted(m.get("versions", {}).items())),
        "- Threads: " + ", ".join(f"{k}={v}" for k, v in sorted(m.get("threads", {}).items())),
        f"- HTP checkpoint: `{ck.get('path', 'none')}` (sha256 {ck.get('sha256', '—')}); "
        f"HTP device {m.get('device', 'auto')}",
        f"- Command: `petsc-htp bench {' '.join(m.get('argv', []))}`",
        "- Studies: " + ", ".join(f"{s} ({m['study_s'][s]:.0f} s)" for s in m.get("studies", ())
                                  if s in m.get("study_s", {})),
        "",
        "Protocol: every method solves the same held-out test frames (`load_dataset(N, \"test\")`) of the "
        f"singular Neumann multiphase Poisson problem from x0 = 0 to relative residual {tol(m.get('rtol', 1e-8))} "
        "in the unpreconditioned 2-norm (`options/common.opts`), at most "
        f"{m.get('max_it', '?')} iterations. PETSc methods are the options files in `options/`, each loaded "
        "under its own prefix into a fresh KSP; setup is KSPSetUp + PCSetUpOnBlocks (inference, AMG setup "
        "or factorisation), solve is KSPSolve. `pyamg` is pyamg's classical Ruge–Stüben AMG (one V-cycle) "
        "preconditioning a NumPy CG on the mean-projected rhs, a CPU reference. One warm-up solve per "
        "(method, N) is excluded. A run counts as failed on a DIVERGED_* reason, an exception, a NaN, or a "
        "true residual ||b - A x|| / ||b|| (constant null-space part removed) above 10 × rtol; failed "
        "frames are left out of the means and counted.",
    ]
    dims = {m.get("dim")} | {v.get("dim") for v in m.values() if isinstance(v, dict)}
    if 3 in dims:
        lines += ["", "**3-D scenes** (`--dim 3`): the generator's near-cubic boxes in octree (Morton) order, "
                  "7-point operator; N = side³ where N is a cube."]
    ranks = m.get("threads", {}).get("MPI ranks", 1)
    if ranks > 1:
        lines += ["", f"**{ranks} MPI ranks**: PETSc methods run on all of them (the matrix split by rows); "
                  "pyamg and AMGCL solve the gathered matrix on rank 0 alone. Peak RSS is the largest over ranks."]
    if m.get("quick"):
        lines += ["", "**Quick run** (`--quick`): CI-sized scales, frames and budgets; not for comparison."]
    return "\n".join(lines)


def build(res) -> str:
    """The whole report: the header and the section of every study the run asked for and has rows for."""
    wanted = set(res.meta.get("studies", STUDIES))
    return "\n\n".join([header(res)] + [s.section(res) for s in present(res) if s.name in wanted]) + "\n"

