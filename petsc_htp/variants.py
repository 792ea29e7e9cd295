"""The preconditioner variants behind HTPPC, each a two-step setup: analysis (pattern) and numeric (values).

A variant is a class constructed from :class:`~petsc_htp.pcoptions.HTPOptions` with

- ``analyse(A, coords)``: the per-pattern step (ordering, leaves, structure), returning an object
  with ``analysis_ms``;
- ``numeric(analysis, A, density, previous)``: the per-values step, returning the setup object
  (``apply(r)``, ``check(probes)``, ``describe()``, ``setup_ms``); ``previous`` is the last setup
  of the same analysis, whose buffers it may reuse;
- ``model``: a line naming the model, or None.

A new variant is one class here and its name in :data:`VARIANTS`.
"""
from __future__ import annotations

import dataclasses
import time

from . import twolevel
from .checkpoint import DEFAULT
from .inference import HTP, resolve_device
from .leaves import choose_leaves


class Paper:
    """The paper's HTP: the network emits the H-matrix factors of M (float32 apply)."""

    def __init__(self, opts):
        self.opts = opts
        self.htp = HTP.cached(opts.checkpoint or None, opts.device)
        cfg = self.htp.net.cfg
        self.model = (f"d={cfg.d}, n_l={cfg.n_layers}, L={cfg.leaf}, L_s={cfg.coarse}, heads={cfg.heads}, "
                      f"highways={'yes' if cfg.highways else 'no'}; {self.htp.net.n_params()} parameters; "
                      f"device {self.htp.device}; checkpoint {opts.checkpoint or 'shipped ' + str(DEFAULT)}")

    def analyse(self, A, coords):
        """Ordering, partition and structural features."""
        return self.htp.analyse(A, coords, self.opts.ordering)

    def numeric(self, analysis, A, density, previous):
        """Network, factors and SPD guard."""
        return self.htp.numeric(analysis, A, density, self.opts.shift, self.opts.spd_guard, into=previous)


class TwoLevel:
    """Exact leaf solves, a coarse space per leaf and its exact Galerkin operator (float64, SPD)."""

    model = None

    def __init__(self, opts):
        self.opts = opts
        self.device = resolve_device(opts.device)

    def analyse(self, A, coords):
        """Leaves (Morton with coordinates, else METIS), block index maps, connected components."""
        t0 = time.perf_counter()
        leaves = choose_leaves(A, coords, self.opts.ordering, self.opts.leaf)
        analysis = twolevel.analyse(A, leaves, self.device)
        return dataclasses.replace(analysis, analysis_ms=1e3 * (time.perf_counter() - t0))

    def numeric(self, analysis, A, density, previous):
        """Leaf inverses, coarse space, Galerkin coarse operator."""
        return twolevel.factor(analysis, A, self.opts.coarse, 1 if self.opts.coarse == "const" else
                               self.opts.coarse_rank)


VARIANTS = {"paper": Paper, "twolevel": TwoLevel}
