"""HTPPC's PETSc log events: one per setup phase and one per part of an application (``-log_view``).

Like PCHPDDM's, the events nest: ``HTPSetup`` holds ``HTPChoice`` and ``HTPAnalysis`` (a new pattern) and the
numeric phases,
``HTPApply`` the parts of one application. :func:`phase` also keeps each phase's wall time for ``-ksp_view``.
"""
from __future__ import annotations

import contextlib
import time

from petsc4py import PETSc

EVENTS = {"HTPSetup": "setup of the preconditioner (analysis when the pattern changed, then the numeric step)",
          "HTPChoice": "which method serves the pattern (its graph, dominance, the ICC(0) trial; once per pattern)",
          "HTPAnalysis": "leaves, index maps, components and every matrix's pattern (once per pattern)",
          "HTPLeafFactor": "numeric factorisation of the leaf blocks",
          "HTPCoarseSpace": "the coarse vectors of every leaf",
          "HTPProducts": "C = O W and the Galerkin coarse operator E = W^T A W",
          "HTPLevels": "the multilevel variant's levels: leaves, smoothed coarse spaces, Galerkin operators",
          "HTPCoarseFactor": "set-up of the coarse solver (its factorisation or multigrid hierarchy)",
          "HTPApply": "one application y = M x",
          "HTPLeafSolve": "the leaf solve of an application",
          "HTPCoarseSolve": "the coarse solve of an application"}
_REGISTERED = {}


def event(name: str) -> PETSc.Log.Event:
    """The PETSc log event ``name`` of :data:`EVENTS` (registered once per process)."""
    if name not in _REGISTERED:
        _REGISTERED[name] = PETSc.Log.Event(name)
    return _REGISTERED[name]


@contextlib.contextmanager
def logged(name: str):
    """The block inside the PETSc log event ``name``."""
    ev = event(name)
    ev.begin()
    try:
        yield
    finally:
        ev.end()


@contextlib.contextmanager
def phase(name: str, times: dict, key: str):
    """The block inside the log event ``name``, its wall time in ms added to ``times[key]``."""
    t0 = time.perf_counter()
    with logged(name):
        yield
    times[key] = times.get(key, 0.0) + 1e3 * (time.perf_counter() - t0)
