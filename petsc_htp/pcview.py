"""HTPPC's ``-ksp_view``: what runs and why, the setup's own lines, then each inner PETSc solver's own view; and
:class:`Inspection`, the part of HTPPC a viewer or a program reads (its inner solvers)."""
from __future__ import annotations

import sys

from petsc4py import PETSc

from .ranksplit import describe as describe_split
from .twolevel.inner import view as view_inner


def lines(ctx) -> list:
    """The lines of an :class:`~petsc_htp.pc.HTPPC` context ``ctx``: variant and title, model, the setup's
    description, setups, torch threads where torch runs, checks and fallback."""
    opts = ctx.opts
    if ctx.variant is None:                    # nothing imported for a view before the setup
        return [f"HTPPC, variant {opts.variant}; not set up yet"]
    state = "" if ctx.setup is not None else "; not set up yet"
    title = getattr(ctx.setup, "title", None) or ctx.variant.title      # the method that runs (V-cycles as it comes)
    out = [f"HTPPC, variant {opts.variant}: {title}{state}"]
    if ctx.variant.model:
        out.append(f"  model: {ctx.variant.model}")
    if getattr(ctx.variant, "note", ""):
        out.append(f"  {ctx.variant.note}")
    if ctx.setup is None:
        return out
    out += ["  " + line for line in ctx.setup.describe() + ctx.columns.describe() + describe_split(ctx.cut)]
    which = "BLAS, OpenMP" + (" and torch" if "torch" in sys.modules else "")
    threads = f"; {which} threads: {ctx.opts.threads}" + (f" ({ctx.threads_note})" if ctx.threads_note else "")
    out.append(f"  setups: {ctx.analysis_count} analyses (pattern), {ctx.numeric_count} numeric (values)" + threads)
    k = opts.probes
    probe = f"{k} Rayleigh probe{'s' if k > 1 else ''}" if k else "no Rayleigh probe"
    if ctx.fallback_active:
        out.append(f"  fallback: jacobi ACTIVE ({ctx.fallback_reason}); applying D^-1")
    elif ctx.fallback_reason:
        out.append(f"  fallback: {opts.fallback}; WARNING: {ctx.fallback_reason}")
    else:
        out.append(f"  checks passed (finite, {probe}); fallback {opts.fallback} not needed")
    return out


def view(ctx, viewer):
    """:func:`lines` on an ASCII ``viewer``, then the inner solvers (``ctx.getInnerPCs()``), indented."""
    for line in lines(ctx):                    # one call per line: each gets the viewer's indentation
        viewer.printfASCII(f"  {line}\n")
    for role, pc in ctx.getInnerPCs().items():
        view_inner(pc, viewer, f"{role}:")


class Inspection:
    """What a PCPYTHON context of this package shows: ``-ksp_view`` and its inner PETSc solvers by role (HTPPC's
    base; it reads the context's ``setup`` and ``variant``)."""

    def view(self, pc, viewer):
        """ASCII description (:func:`view`): what runs, the setup's own lines, checks, then the inner solvers'
        own views, indented."""
        if viewer.getType() == PETSc.Viewer.Type.ASCII:
            view(self, viewer)

    def getInnerPCs(self) -> dict:
        """The inner PETSc solvers by role (leaf solver and coarse solver of the two-level method; the factor of a
        small matrix; none for the paper's variant or before setup)."""
        if self.setup is None or self.variant is None:
            return {}
        return self.variant.inner_pcs(self.setup)

    def getLeafPC(self):
        """The leaf solver's PC (the two-level method), else None."""
        return self.getInnerPCs().get("leaf solver")

    def getCoarsePC(self):
        """The coarse solver's PC (the two-level method), else None."""
        return self.getInnerPCs().get("coarse solver")
