"""What one application of the two-level preconditioner costs, part by part (the sequence study's apply rows)."""
from __future__ import annotations

import time


def _thin(setup, x, y):
    """The thin products of one application in the form in use (W's, C's or A W's, and F's)."""
    ops, cs, forms = setup.ops, setup.coarse, setup.forms
    exact, deflated = setup.leafsolver.exact, forms.form() == "deflated"
    if exact and deflated:
        ops.CT.mult(forms.v, cs.g)
    else:
        ops.W.multTranspose(x, cs.g)
        other = ops.C if exact else ops.AW
        if not deflated:
            other.mult(cs.c, forms.t)
        other.multTranspose(forms.v, cs.g)
        if exact and not deflated:
            ops.F.mult(cs.c, cs.c2)
    ops.W.multAdd(cs.c, forms.v, y)


def apply_costs(setup, reps=20) -> dict:
    """Milliseconds per call of each part of an application of a
    :class:`~petsc_htp.twolevel.composed.TwoLevelPC` ``setup`` in the form in use, and of one MatMult of A
    (``matmult``), timed back to back over ``reps`` calls (collective)."""
    x, y = setup.mat.createVecs()
    x.setRandom()
    cs, forms = setup.coarse, setup.forms
    parts = {"matmult": lambda: setup.mat.mult(x, y), "leaf solve": lambda: setup.leafsolver.apply(x, forms.v),
             "coarse solve": lambda: cs.apply(cs.g, cs.c), "thin products": lambda: _thin(setup, x, y),
             "apply": lambda: forms.mult(x, y)}
    out = {}
    try:
        for name, call in parts.items():
            call()
            t0 = time.perf_counter()
            for _ in range(reps):
                call()
            out[name] = 1e3 * (time.perf_counter() - t0) / reps
    finally:
        x.destroy()
        y.destroy()
    if forms.form() != "deflated":
        out["coarse solve"] *= 2
    return out
