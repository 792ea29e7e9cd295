"""A pressure solver that lives across the frames of a simulation: one Mat, one KSP, reuse the PETSc way.

:func:`simulate` runs :class:`petsc_htp.sim.flow.Flow` with the method whose
options sit under a prefix (see :mod:`petsc_htp.bench.harness`): the matrix keeps
its nonzero pattern and gets new values every frame, the previous pressure is
the initial guess, and :class:`ReusePolicy` decides when the preconditioner is
rebuilt (``PCSetReusePreconditioner`` otherwise).
"""
import json
import math
import sys
import time
from pathlib import Path

import numpy as np
from petsc4py import PETSc

from ..atomic import atomic_open
from .flow import Flow
from .plot import frame_images, plot_runs, write_gif
from ..bench.harness import bjacobi_blocks, reason_name
from ..petscmat import attach, gathered, local_csr, preallocated_aij, region_nullspace


def create_matrix(A, regions):
    """Distributed AIJ preallocated for ``A``'s pattern (no values yet), symmetric, one constant null vector per
    region; returns ``(mat, start, end)``, this rank's rows ``start:end``."""
    mat, start, end = preallocated_aij(A)
    mat.setOption(PETSc.Mat.Option.SYMMETRIC, True)
    mat.setOption(PETSc.Mat.Option.SYMMETRY_ETERNAL, True)
    mat.setNullSpace(region_nullspace(mat, regions))
    return mat, start, end


def pc_setups():
    """PETSc's count of (outermost) PCSetUp events so far."""
    return PETSc.Log.Event("PCSetUp").getPerfInfo()["count"]


def numeric_count(pc):
    """A python PC context's ``numeric_count``, else None."""
    return getattr(pc.getPythonContext(), "numeric_count", None) if pc.getType() == "python" else None


class PressureSolver:
    """One Mat with a fixed pattern and one KSP, reused frame after frame.

    Parameters
    ----------
    A : scipy.sparse.csr_matrix
        The first frame's matrix (its pattern is kept).
    regions : numpy.ndarray of int
        Connected fluid region of each row (one null vector each).
    prefix : str
        Options prefix of the method.
    warm : bool
        Start every solve from the previous solution (else from zero).
    """

    def __init__(self, A, regions, prefix="", warm=True):
        self.mat, self.start, self.end = create_matrix(A, regions)
        self.indptr, self.indices, _ = local_csr(A, self.start, self.end)
        self.entries = slice(A.indptr[self.start], A.indptr[self.end])
        self.ksp = PETSc.KSP().create(comm=self.mat.getComm())
        self.ksp.setOptionsPrefix(prefix)
        self.ksp.setOperators(self.mat, self.mat)
        with bjacobi_blocks(prefix, A.shape[0]):
            self.ksp.setFromOptions()
        self.warm = warm
        self.ksp.setInitialGuessNonzero(warm)          # the previous frame's pressure
        self.max_it = self.ksp.getTolerances()[3]
        self.x, self.b = self.mat.createVecs()
        self.x.set(0.0)
        self.r = self.b.duplicate()

    def solve(self, A, rhs, coords, coefficient, rebuild, cap=None):
        """Update the values, attach geometry and solve, reusing the PC unless ``rebuild``.

        ``coefficient`` is attached as HTP's per-row ``density`` feature, which
        means the operator's material coefficient (the benchmark's rho); here that is
        ``1/rho``. Attaching the physical density instead tripled HTP's iterations
        at 64 x 64 (729 against 243).

        With a reused PC the solve stops after ``cap`` iterations (if given); if it has not
        converged by then, or failed otherwise, the PC is rebuilt and the solve goes on from
        that iterate (zero if not finite): a stale preconditioner costs at most ``cap``
        iterations, never a failed frame.

        Returns
        -------
        dict
            ``its`` (all of the frame's), ``code`` (converged reason), ``relres`` (true), ``setup_ms``
            (KSPSetUp + PCSetUpOnBlocks), ``solve_ms``, ``update_ms``, ``rebuilt``, ``restarted``
            (rebuilt after the cap), ``reused_its`` (iterations with the reused PC before a restart),
            ``pc_setups`` (PCSetUp events) and ``numeric_setups`` (python PCs, else None).
        """
        t0 = time.perf_counter()
        if not self.warm:
            self.x.set(0.0)
        self.mat.setValuesCSR(self.indptr, self.indices, A.data[self.entries])
        self.mat.assemble()
        attach(self.mat, coords=coords, density=coefficient)
        self.b.setArray(rhs[self.start:self.end])
        pc = self.ksp.getPC()
        setups, numeric = pc_setups(), numeric_count(pc)
        update_ms = 1e3 * (time.perf_counter() - t0)
        first = self._attempt(rebuild, self.max_it if rebuild or cap is None else min(cap, self.max_it))
        restarted = not rebuild and first["code"] < 0
        if restarted and not np.isfinite(self.x.norm()):
            self.x.set(0.0)
        attempts = [first] + ([self._attempt(True, self.max_it)] if restarted else [])
        self.mat.mult(self.x, self.r)
        self.r.aypx(-1.0, self.b)
        after = numeric_count(pc)
        total = {key: sum(at[key] for at in attempts) for key in ("its", "setup_ms", "solve_ms")}
        return {**total, "code": attempts[-1]["code"], "relres": self.r.norm() / (self.b.norm() or 1.0),
                "update_ms": update_ms, "rebuilt": rebuild or restarted, "restarted": restarted,
                "reused_its": first["its"] if restarted else 0,
                "pc_setups": pc_setups() - setups,
                "numeric_setups": None if after is None else after - numeric}

    def _attempt(self, rebuild, max_it):
        """KSPSetUp and KSPSolve with at most ``max_it`` iterations, from the current ``x``."""
        self.ksp.getPC().setReusePreconditioner(not rebuild)
        self.ksp.setTolerances(max_it=max_it)
        t1 = time.perf_counter()
        self.ksp.setUp()
        self.ksp.setUpOnBlocks()
        t2 = time.perf_counter()
        self.ksp.solve(self.b, self.x)
        t3 = time.perf_counter()
        self.ksp.setTolerances(max_it=self.max_it)
        return {"its": self.ksp.getIterationNumber(), "code": self.ksp.getConvergedReason(),
                "setup_ms": 1e3 * (t2 - t1), "solve_ms": 1e3 * (t3 - t2)}

    def pressure(self):
        """The current solution as a numpy array (the whole of it on every rank)."""
        return gathered(self.x)

    def destroy(self):
        """Free the PETSc objects."""
        for obj in (self.ksp, self.mat, self.x, self.b, self.r):
            obj.destroy()


class ReusePolicy:
    """When to rebuild the preconditioner, and how long a reused one may run.

    Always at the first frame; with ``every`` = 0 at every frame; otherwise
    ``every`` frames after the last rebuild. A frame with the reused PC gets
    :meth:`cap` = ``growth`` times the iterations of the last rebuilt frame; one
    that needs more is rebuilt on the spot (:meth:`PressureSolver.solve`).
    """

    def __init__(self, every, growth):
        self.every, self.growth = every, growth
        self.since, self.ref_its = None, 0

    def rebuild(self):
        """Whether the coming frame rebuilds before its solve."""
        return self.since is None or self.every == 0 or self.since >= self.every

    def cap(self):
        """Iterations a reused PC may take in the coming frame (None: no rebuilt frame has iterated yet)."""
        return math.ceil(self.growth * self.ref_its) if self.ref_its else None

    def record(self, rebuilt, fresh_its):
        """Note a solved frame: whether its PC was rebuilt, and the iterations with the rebuilt PC.

        A rebuilt frame that converged in 0 iterations (its start was already the solution)
        says nothing about the PC and leaves the reference as it was.
        """
        self.since = 1 if rebuilt else self.since + 1
        if rebuilt and fresh_its > 0:
            self.ref_its = fresh_its


# ------------------------------------------------------------------- runs

def simulate(cfg, label, prefix="", verbose=True):
    """Run the scene with the method under ``prefix``; returns (records, failed).

    ``cfg`` holds nx, ny, frames, density_ratio, seed, reuse_every, reuse_growth, out, animate, and nz for a
    3-D flow (absent or None: 2-D).
    Writes ``out/LABEL.jsonl`` (atomically) and ``out/LABEL.png``, with ``animate`` also a GIF.
    """
    if cfg["frames"] < 1:
        raise ValueError(f"frames must be at least 1, got {cfg['frames']}")
    sim = Flow(cfg["nx"], cfg["ny"], density_ratio=cfg["density_ratio"], seed=cfg["seed"], nz=cfg.get("nz"))
    policy = ReusePolicy(cfg["reuse_every"], cfg["reuse_growth"])
    solver, records, images = None, [], []
    try:
        for frame in range(cfg["frames"]):
            t0 = time.perf_counter()
            sim.advance()
            A, rhs, coords, density = sim.system()
            div_before = sim.max_divergence()
            t1 = time.perf_counter()
            if solver is None:
                solver = PressureSolver(A, sim.regions, prefix)
            res = solver.solve(A, rhs, coords, 1.0 / density, policy.rebuild(), policy.cap())
            t2 = time.perf_counter()
            code = res.pop("code")
            converged = code > 0
            div_after = sim.project(solver.pressure()) if converged else None
            heavy, light = sim.phase_mass()
            rec = {"frame": frame, "method": label, "n": sim.n, **res,
                   "reason": reason_name(code),
                   "div_before": div_before, "div_after": div_after,
                   "physics_ms": 1e3 * (t1 - t0 + time.perf_counter() - t2), "substeps": sim.substeps,
                   "mass_heavy": heavy, "mass_light": light}
            records.append(rec)
            if verbose:
                print(f"{label} frame {frame:3d}  its {rec['its']:5d}  setup {rec['setup_ms']:7.2f} ms  "
                      f"solve {rec['solve_ms']:7.2f} ms  {rec['reason']:<16} relres {rec['relres']:.2e}  "
                      f"div {math.nan if div_after is None else div_after:.2e}  "
                      f"rebuilt {'after the cap' if rec['restarted'] else 'yes' if rec['rebuilt'] else 'no'}",
                      flush=True)
            if not converged:
                print(f"error: {label}: frame {frame}: KSP did not converge ({rec['reason']})",
                      file=sys.stderr, flush=True)
                break
            policy.record(rec["rebuilt"], rec["its"] - rec["reused_its"])
            if cfg["animate"]:
                images.append(frame_images(sim, solver.pressure()))
    finally:
        if solver is not None:
            solver.destroy()
    out = Path(cfg["out"])
    with atomic_open(out / f"{label}.jsonl") as handle:
        handle.writelines(json.dumps(rec) + "\n" for rec in records)
    plot_runs([out / f"{label}.jsonl"], out / f"{label}.png")
    if images:
        write_gif(*zip(*images), out / f"{label}.gif")
    return records, not converged


def summary(records):
    """One line: solver ms per frame (mean, p95), mean iterations, setups, max divergence."""
    ms = np.array([r["setup_ms"] + r["solve_ms"] for r in records])
    divs = [r["div_after"] for r in records if r["div_after"] is not None]
    return (f"{records[0]['method']}: {len(records)} frames, N={records[0]['n']}, "
            f"ms/frame mean {ms.mean():.2f} p95 {np.percentile(ms, 95):.2f}, "
            f"mean its {np.mean([r['its'] for r in records]):.1f}, "
            f"setups {sum(r['rebuilt'] for r in records)} "
            f"(PCSetUp events {sum(r['pc_setups'] for r in records)}), "
            f"max div {max(divs, default=math.nan):.2e}")
