"""Solvers outside PETSc that the benchmark compares with: pyamg's AMG and AMGCL, each built from scratch per solve.

- ``pyamg``: pyamg's classical Ruge-Stueben AMG, one V-cycle preconditioning a NumPy CG;
- ``pyamg_sa``: pyamg's smoothed aggregation, likewise (on a Neumann matrix both V-cycles' outputs are made
  mean-free, as PETSc's KSP does with the attached null space: SA's singular coarse solve otherwise breaks CG);
- ``amgcl``: AMGCL through ``pyamgcl`` (smoothed aggregation, SPAI0 smoothing, its own CG). Its coarse
  direct solve needs a nonsingular matrix, so one cell per null region is pinned (its couplings zeroed,
  the right-hand side made mean-zero there with b = 0 at the pin): the pinned system has the Neumann
  problem's solution with x = 0 at the pins. The pinning is part of its setup time. pyamgcl has no
  initial guess (it starts from zero) and no residual history: for speed against accuracy its hierarchy
  preconditions the same NumPy CG as pyamg's.

Every solver stops at ||b - A x|| <= rtol ||b|| (unpreconditioned), like the options files.
"""
from __future__ import annotations

import time

import numpy as np

from ..training.pcg import pcg

DESCRIPTION = {"pyamg": "pyamg classical (Ruge-Stueben) AMG, one V-cycle preconditioning a NumPy CG",
               "pyamg_sa": "pyamg smoothed-aggregation AMG, one V-cycle preconditioning a NumPy CG",
               "amgcl": "AMGCL (pyamgcl 1.0): smoothed aggregation, SPAI0 smoothing, its CG; one cell pinned"}
NAMES = tuple(DESCRIPTION)
COARSE_SWEEP = "amgcl_ce"      # amgcl_ce<K>: AMGCL with coarse_enough K (its default is 3000)
PCG_REASONS = {"converged": "CONVERGED_RTOL", "max_it": "DIVERGED_ITS", "nan": "DIVERGED_NANORINF",
               "indefinite_pc": "DIVERGED_INDEFINITE_PC", "indefinite_mat": "DIVERGED_INDEFINITE_MAT"}
AMGCL_PRM = {"coarsening.type": "smoothed_aggregation", "relax.type": "spai0"}


def is_external(name) -> bool:
    """Whether ``name`` is an external solver: one of :data:`NAMES` or ``amgcl_ce<K>``."""
    return name in NAMES or (name.startswith(COARSE_SWEEP) and name[len(COARSE_SWEEP):].isdigit())


def _amgcl_prm(name) -> dict:
    """AMGCL's parameters for ``amgcl`` or ``amgcl_ce<K>`` (coarse_enough K)."""
    size = name[len(COARSE_SWEEP):] if name.startswith(COARSE_SWEEP) else ""
    return {**AMGCL_PRM, **({"coarse_enough": int(size)} if size else {})}


def missing(name) -> str | None:
    """Why ``name`` cannot run here (its package is not installed), or None."""
    module = "pyamgcl" if name.startswith("amgcl") else "pyamg"
    try:
        __import__(module)
    except ImportError as exc:
        hint = " (needs Boost headers: apt-get install libboost-dev; pip install pybind11; " \
               "pip install --no-build-isolation pyamgcl)" if module == "pyamgcl" else ""
        return f"{module} is not installed{hint}: {exc}"
    return None


class _Stamped:
    """Wrap a preconditioner apply, recording the time of every call."""

    def __init__(self, apply):
        self.apply, self.times = apply, []

    def __call__(self, r):
        self.times.append(time.perf_counter())
        return self.apply(r)


def _pyamg(name, A, b, rtol, maxit, monitor) -> dict:
    import pyamg

    np.random.seed(0)          # pyamg's spectral-radius estimates start from np.random: the same rows every run
    t0 = time.perf_counter()
    ml = (pyamg.ruge_stuben_solver if name == "pyamg" else pyamg.smoothed_aggregation_solver)(A)
    vcycle = ml.aspreconditioner().matvec
    neumann = np.abs(A @ np.ones(A.shape[0])).max() <= 1e-10 * np.abs(A.diagonal()).max()
    if neumann:                                  # constant null space: mean-free b and M r
        apply = _Stamped(lambda r: (z := vcycle(r)) - z.mean())
    else:
        apply = _Stamped(vcycle)
    t1 = time.perf_counter()
    res = pcg(A, b - b.mean() if neumann else b, apply, rtol=rtol, maxiter=maxit)
    t2 = time.perf_counter()
    out = {"setup_ms": 1e3 * (t1 - t0), "solve_ms": 1e3 * (t2 - t1), "iterations": res.iterations,
           "reason": PCG_REASONS[res.reason], "x": res.x, "ksp": "numpy-cg", "pc": f"{name}({len(ml.levels)} levels)"}
    if monitor:
        times = (apply.times + [t2] * len(res.history))[:len(res.history)]
        bnorm = float(np.linalg.norm(b))
        out["curve"] = [[1e3 * (t - t0), k, float(h) / bnorm] for k, (t, h) in enumerate(zip(times, res.history))]
    return out


def pinned(A, b) -> tuple:
    """A with the couplings of the first row of every null region zeroed (same pattern), and b made mean-zero
    on those regions with 0 at the pinned rows."""
    from scipy.sparse.csgraph import connected_components

    from ..twolevel.nullspace import null_regions

    regions = connected_components(A, directed=False)[1]
    null = null_regions(A, regions)
    first = np.full(null.size, -1)
    first[regions[::-1]] = np.arange(A.shape[0])[::-1]
    pins = np.zeros(A.shape[0], dtype=bool)
    pins[first[null]] = True
    data = A.data.copy()
    rows = np.repeat(np.arange(A.shape[0]), np.diff(A.indptr))
    data[(pins[rows] | pins[A.indices]) & (rows != A.indices)] = 0.0
    mean = np.bincount(regions, b) / np.bincount(regions)
    rhs = np.where(null[regions], b - mean[regions], b)
    rhs[pins] = 0.0
    return A.__class__((data, A.indices, A.indptr), shape=A.shape), rhs


def _amgcl_once(A, b, rtol, maxit, prm) -> dict:
    import pyamgcl

    t0 = time.perf_counter()
    Ap, rhs = pinned(A, b)
    solver = pyamgcl.solver(pyamgcl.amg(Ap, prm), prm={"type": "cg", "tol": rtol, "maxiter": maxit})
    t1 = time.perf_counter()
    x = np.asarray(solver(rhs))
    t2 = time.perf_counter()
    its = int(solver.iters)
    return {"setup_ms": 1e3 * (t1 - t0), "solve_ms": 1e3 * (t2 - t1), "iterations": its,
            "reason": "CONVERGED_RTOL" if its < maxit else "DIVERGED_ITS", "x": x, "ksp": "amgcl-cg",
            "pc": f"amgcl(sa, spai0, coarse_enough {prm.get('coarse_enough', 3000)})"}


def _amgcl_curve(A, b, rtol, maxit, prm) -> dict:
    """AMGCL's hierarchy (one V-cycle) preconditioning the NumPy CG, for a residual history (pyamgcl keeps none)."""
    import pyamgcl

    t0 = time.perf_counter()
    Ap, rhs = pinned(A, b)
    apply = _Stamped(pyamgcl.amg(Ap, prm))
    t1 = time.perf_counter()
    res = pcg(Ap, rhs, apply, rtol=rtol * np.linalg.norm(b) / np.linalg.norm(rhs), maxiter=maxit)
    t2 = time.perf_counter()
    times = (apply.times + [t2] * len(res.history))[:len(res.history)]
    bnorm = float(np.linalg.norm(b))
    return {"setup_ms": 1e3 * (t1 - t0), "solve_ms": 1e3 * (t2 - t1), "iterations": res.iterations,
            "reason": PCG_REASONS[res.reason], "x": res.x, "ksp": "numpy-cg", "pc": "amgcl(sa, spai0)",
            "curve": [[1e3 * (t - t0), k, float(h) / bnorm] for k, (t, h) in enumerate(zip(times, res.history))]}


def solve(name, A, b, rtol, maxit, monitor=False) -> dict:
    """Solve the frame ``A x = b`` with external solver ``name`` from scratch.

    Returns setup_ms, solve_ms, iterations, reason (PETSc's names), x, ksp and pc, and with ``monitor``
    a ``curve`` of [ms since setup start, iteration, ||r|| / ||b||].
    """
    why = missing(name)
    if why:
        raise RuntimeError(why)
    if name.startswith("amgcl"):
        return (_amgcl_curve if monitor else _amgcl_once)(A, b, rtol, maxit, _amgcl_prm(name))
    return _pyamg(name, A, b, rtol, maxit, monitor)
