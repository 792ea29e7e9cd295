"""HTPPC's ``-ksp_view``: what runs and why, the setup's own lines, then each inner PETSc solver's own view."""
from __future__ import annotations

import sys

from .twolevel.inner import view as view_inner


def lines(ctx) -> list:
    """The lines of an :class:`~petsc_htp.pc.HTPPC` context ``ctx``: variant and title, model, the setup's
    description, setups, torch threads where torch runs, checks and fallback."""
    opts = ctx.opts
    if ctx.variant is None:                    # nothing imported for a view before the setup
        return [f"HTPPC, variant {opts.variant}; not set up yet"]
    state = "" if ctx.setup is not None else "; not set up yet"
    out = [f"HTPPC, variant {opts.variant}: {ctx.variant.title}{state}"]
    if ctx.variant.model:
        out.append(f"  model: {ctx.variant.model}")
    if ctx.setup is None:
        return out
    out += ["  " + line for line in ctx.setup.describe()]
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
