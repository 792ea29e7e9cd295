"""Matrices from other programs (:mod:`petsc_htp.bench.foreigncases`): single solves and sequences.

Single-solve mode: each case's first frame, a fresh Mat (nothing attached but the null space a Neumann matrix
has) and a fresh KSP, the whole setup in the time, after one warm-up solve per method and N (under
:data:`SMALL_ROWS` rows the median of ``--foreign-repeats`` such solves); and the same solve
as the first call of a fresh process (:mod:`petsc_htp.bench.fresh`), which also gives each method's own peak
memory. Sequence mode: later frames of the same case
through one persistent KSP per PETSc method (new values in the same Mat; for the free surface, whose pattern
changes, a new Mat each frame), pyamg and AMGCL rebuilding. Methods take turns frame by frame.
"""
from __future__ import annotations

import time

import numpy as np

from ..aggregate import cells
from ..baselines import best_table
from ..foreigncases import CASES, PATTERN_CHANGES, pyamg_cases
from ..markdown import image, md_table, median_cell, ms, n_label
from .base import Size, Study, solve_all, tag

CHART = "foreign.png"
SCALES = Size("foreign_scales", [65536], [2048], "N of the foreign study")
FRAMES = Size("foreign_frames", 4, 2, "sequence frames per case of the foreign study (0: single solves only)")
REPEATS = Size("foreign_repeats", 5, 1, "single solves of every method on a matrix under SMALL_ROWS rows, one after "
               "the other (the median by setup + solve is reported; one above)")
SMALL_ROWS = 20000      # below this a single solve takes milliseconds and varies by its own size between runs
CASE_NAMES = Size("foreign_cases", list(CASES), ["dmda2d", "dmda3d", "free_surface", "fem_tri", "neumann"],
                  "cases of the foreign study", kind=str)


def bare_frame(A, b, case):
    """A bare :class:`~petsc_htp.scenes.Frame` around ``A``, ``b``."""
    from ...scenes.generator import Frame

    return Frame(A=A, b=b, rho=np.ones(A.shape[0]), coords=np.zeros((A.shape[0], 2)), grid_shape=(A.shape[0], 1),
                 perm=np.arange(A.shape[0]), params={"case": case, "seed": 0})


def problems(names, scales, examples=True) -> list:
    """Frame 0 of every case at every N, then PyAMG's examples; nothing attached."""
    from ..cases import Problem

    out = [Problem(bare_frame(*CASES[c](n, 0), c), case=c, attach=False) for n in scales for c in names]
    if examples:
        out += [Problem(bare_frame(A, b, c), case=c, attach=False) for c, (A, b) in pyamg_cases().items()]
    return out


class _Persistent:
    """One PETSc method's KSP kept over a case's frames: new values into the same Mat, or a new Mat."""

    def __init__(self, method):
        from petsc4py import PETSc

        self.ksp = PETSc.KSP().create()
        self.ksp.setOptionsPrefix(method.prefix)
        self.mat, self.pattern = None, None

    def solve(self, A, b) -> dict:
        """Set the frame's values (a new Mat when the pattern changed) and solve from zero; the row's fields."""
        from ..harness import reason_name
        from ...petscmat import frame_mat, frame_vec

        frame = bare_frame(A, b, "")
        pattern = (A.indptr.tobytes(), A.indices.tobytes())
        if self.mat is not None and pattern == self.pattern:
            self.mat.setValuesCSR(A.indptr, A.indices, A.data)
            self.mat.assemble()
        else:
            old, self.mat, self.pattern = self.mat, frame_mat(frame), pattern
            if old is not None and old.getSize() != self.mat.getSize():
                self.ksp.reset()                        # PETSc's KSP keeps work vectors of the old size
            self.ksp.setOperators(self.mat, self.mat)
            if old is None:                             # once: KSPReset keeps the KSP's and PC's types and options
                self.ksp.setFromOptions()               # (a second made PCPYTHON a new context each frame)
            else:
                old.destroy()
        rhs = frame_vec(frame, self.mat)
        x = rhs.duplicate()
        x.set(0.0)
        try:
            t0 = time.perf_counter()
            self.ksp.setUp()
            t1 = time.perf_counter()
            self.ksp.solve(rhs, x)
            t2 = time.perf_counter()
            code = self.ksp.getConvergedReason()
            return {"setup_ms": 1e3 * (t1 - t0), "solve_ms": 1e3 * (t2 - t1), "iterations": self.ksp.getIterationNumber(),
                    "reason": reason_name(code), "x": x.getArray().copy()}
        finally:
            rhs.destroy()
            x.destroy()

    def destroy(self):
        for obj in (self.ksp, self.mat):
            if obj is not None:
                obj.destroy()


def sequence(methods, names, scales, frames, extra, tick) -> list:
    """Frames 1 .. ``frames`` of every case through persistent solvers (frame 0, left out, warms them up)."""
    from ..cases import Problem
    from ..runner import finish_row, solve_method, base_row, exception_row, load, peak_rss_mb

    rows = []
    loaded = [load(m, extra) for m in methods if m.is_petsc]
    try:
        for n in scales:
            for case in names:
                solvers = {m.name: _Persistent(m) for m in methods if m.is_petsc}
                try:
                    for k in range(frames + 1):
                        A, b = CASES[case](n, k)
                        problem = Problem(bare_frame(A, b, case), case=case, attach=False)
                        for m in methods:
                            try:
                                if m.is_petsc:
                                    res = solvers[m.name].solve(A, b)
                                    row = finish_row({**base_row(m, problem), **res}, A, b, res.pop("x"),
                                                  solvers[m.name].ksp.getTolerances()[0])
                                else:
                                    row = solve_method(m, m.prefix, problem, False)
                            except Exception as exc:  # a failing frame is a result
                                row = exception_row(m, problem, exc)
                            row.pop("x", None)
                            row["peak_rss_mb"] = peak_rss_mb()
                            if k:
                                rows.append(tag(row, study="foreign", mode="sequence", frame=k, scale=n))
                                tick()
                finally:
                    for s in solvers.values():
                        s.destroy()
    finally:
        for entry in reversed(loaded):
            entry.__exit__(None, None, None)
    return rows


def _mode(res, mode) -> list:
    return [r for r in res.rows["foreign"] if r.get("mode") == mode]


def table(res, mode) -> str:
    """Median ms (setup + solve), iterations and the largest true relres per case and method."""
    rows = _mode(res, mode)
    if not rows:
        return "(none in this run)"
    size = "scale" if mode == "sequence" else "n"        # a moving free surface changes N frame by frame
    by = cells(rows, "case", size, "method")
    methods = res.methods("foreign")
    keys = list(dict.fromkeys((r["case"], r[size]) for r in rows))
    body = []
    for case, n in keys:
        line = [case, n_label(n)]
        for m in methods:
            line.append(median_cell(by.get((case, n, m))))
        body.append(line)
    return md_table(["case", "N"] + methods, body, left=2)


def fresh(methods, names, scales, threads, tick) -> list:
    """Frame 0 of every case solved once by every method, each in a fresh process (:mod:`petsc_htp.bench.fresh`)."""
    import tempfile
    from pathlib import Path

    from ..fresh import run, save

    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for n in scales:
            for case in names:
                path = Path(tmp) / "frame.npz"
                save(path, *CASES[case](n, 0))
                for m in methods:
                    rows.append(tag(run(path, m.spec, case, threads or 1), study="foreign", mode="fresh", scale=n,
                                    method=m.name))
                    tick()
    return rows


def fresh_table(res) -> str:
    """Each method's solve as a fresh process's first call: setup + solve ms, and peak memory above the process's
    resident memory before the solve (MiB)."""
    rows = [r for r in res.rows["foreign"] if r.get("mode") == "fresh"]
    if not rows:
        return "(none in this run)"
    methods = res.methods("foreign")
    by = {(r["case"], r["scale"], r["method"]): r for r in rows}
    body = []
    for case, n in dict.fromkeys((r["case"], r["scale"]) for r in rows):
        line = [case, n_label(n)]
        for m in methods:
            r = by.get((case, n, m))
            line.append("—" if r is None else f"✗ {r.get('failure')}" if not r.get("ok") else
                        f"{ms(r['total_ms'])} / {r['peak_rss_mb'] - r['baseline_mb']:.0f}")
        body.append(line)
    return md_table(["case", "N"] + methods, body, left=2)


class Foreign(Study):
    """Matrices from other programs, single solves and sequences."""

    name = "foreign"
    help = ("matrices from other programs (DMDA with Dirichlet rows in 2-D/3-D, a moving free surface, rotated "
            "anisotropy, P1 FEM on triangles and tets, log-normal permeability, Neumann walls, PyAMG's examples): "
            "single solves with fresh KSPs, as a fresh process's first call (with its peak memory), and sequences "
            "with persistent KSPs")
    sizes = (SCALES, FRAMES, REPEATS, CASE_NAMES)
    readme_links = ((CHART, "foreign matrices"),)

    def meta(self, settings):
        return {"foreign": {"scales": settings["foreign_scales"], "frames": settings["foreign_frames"],
                            "cases": settings["foreign_cases"], "repeats": settings["foreign_repeats"]}}

    def expected_solves(self, ctx):
        s = ctx.settings
        per_n = len(s["foreign_cases"]) * (2 + s["foreign_frames"])
        return len(ctx.methods) * (len(s["foreign_scales"]) * per_n + len(pyamg_cases()))

    def measure(self, ctx, tick):
        s = ctx.settings
        bad = [c for c in s["foreign_cases"] if c not in CASES]
        if bad:
            raise ValueError(f"unknown foreign case(s) {', '.join(bad)}; the cases are {', '.join(CASES)}")
        reps = max(1, s["foreign_repeats"])
        single = solve_all(ctx.methods, problems(s["foreign_cases"], s["foreign_scales"]), ctx.extra, tick, "foreign",
                           repeats=lambda p: reps if p.n < SMALL_ROWS else 1)
        for row in single:
            row.setdefault("mode", "single")
        seq = sequence(ctx.methods, s["foreign_cases"], s["foreign_scales"], s["foreign_frames"], ctx.extra, tick) \
            if s["foreign_frames"] else []
        return single + seq + fresh(ctx.methods, s["foreign_cases"], s["foreign_scales"], ctx.threads, tick)

    def section(self, res):
        meta = res.meta.get("foreign", {})
        changes = ", ".join(PATTERN_CHANGES)
        return "\n\n".join([
            "## Matrices from other programs",
            "Single solves: each case's matrix handed over bare (a Neumann matrix with its null space), a fresh "
            "Mat and KSP, setup (analysis included) + solve ms and median iterations in parentheses, after one "
            f"warm-up solve per method and N; under {SMALL_ROWS} rows the median of "
            f"{meta.get('repeats', 1)} single solves in a row per method.",
            table(res, "single"),
            "Each baseline family at its default and its best swept setting, single solves (ms, iterations):",
            best_table(_mode(res, "single"), res.methods("foreign")),
            f"Sequence mode: {meta.get('frames', '?')} more frames per case with new values on one persistent KSP "
            f"per PETSc method ({changes}: a new pattern every frame, so a new Mat, its N about the one shown); "
            "pyamg and AMGCL rebuild. Median ms per frame (iterations).",
            table(res, "sequence"),
            "The same, sequence mode (ms per frame):",
            best_table(_mode(res, "sequence"), res.methods("foreign"), ("case", "scale")),
            "The same single solve as the first call of a fresh Python process (imports excluded): setup + solve ms "
            "/ peak resident memory above the process's before the solve, MiB:",
            fresh_table(res),
            image(CHART, "Foreign matrices"),
        ])

    def charts(self, res, out):
        from ..plotting import foreign_bars

        rows = [r for r in res.rows["foreign"] if r.get("mode") == "single"]
        return [foreign_bars(rows, res.methods("foreign"), out, CHART)] if rows else []

    def summary(self, res):
        return table(res, "single") + "\n\n" + table(res, "sequence")


STUDY = Foreign()
