"""The inner PETSc solvers of the two-level method (leaf factor, coarse solver): made with their defaults set
through PETSc's API, then ``setFromOptions`` under their own prefix, so the user's options win.

A default is a PETSc option name and value under the solver's prefix (:mod:`petsc_htp.twolevel.sizing` keeps
them so). The ones PETSc's Python API can set are set through it (PC type, factor ordering and shift, a PCKSP's
inner KSP type, tolerance and PC); the few it cannot (GAMG's aggressive coarsening, PCREDUNDANT's inner
solver, which exists only once set up) sit in the options database for the ``setFromOptions`` or set-up that
reads them, and are taken out again: a setup leaves the database as it found it. A user's own ``pc_type`` replaces
the type and with it the defaults set for it (that type gets PETSc's own, as any PC would).
"""
from __future__ import annotations

import contextlib

import numpy as np
from petsc4py import PETSc

from ..collective import Collective

FACTOR_PCS = ("lu", "cholesky", "icc", "ilu")       # PC types that hold a factor
UNIT_PIVOT = 100 * float(np.finfo(np.float64).eps)  # PETSc's zero pivot and nonzero shift, right for unit entries
PIVOTED = {"lu": "", "ilu": "", "redundant": "redundant_", "gamg": "mg_coarse_sub_"}   # where an LU pivots
SHIFTS = {"none": PETSc.Mat.FactorShiftType.NONE, "nonzero": PETSc.Mat.FactorShiftType.NONZERO,
          "positive_definite": PETSc.Mat.FactorShiftType.POSITIVE_DEFINITE,
          "inblocks": PETSc.Mat.FactorShiftType.INBLOCKS}


@contextlib.contextmanager
def scoped(prefix, defaults, names=None):
    """``defaults`` in PETSc's options database under ``prefix`` where the user set nothing, for the block only;
    ``names``: the database's names, where given, in which the name itself must be (PETSc's lookup of a level's
    ``mg_levels_0_`` name otherwise finds the user's ``mg_levels_`` one)."""
    db = PETSc.Options(prefix)
    added = [name for name in defaults if (prefix + name not in names if names is not None else not db.hasName(name))]
    for name in added:
        db.setValue(name, defaults[name])
    try:
        yield
    finally:
        for name in added:
            db.delValue(name)


def set_up(pc, prefix, rest):
    """Set ``pc`` up with the defaults its set-up still has to find (``rest``, :func:`configured_pc`) under
    ``prefix``, and pivots scaled to its operator (:func:`scaled_pivots`); PCREDUNDANT, whose inner solver reads
    them then, factors at its first apply: that is done here."""
    with scoped(prefix, {**scaled_pivots(pc, prefix), **rest}):
        pc.setUp()
        if pc.getType() == "redundant":
            x, y = pc.getOperators()[0].createVecs()
            x.set(0.0)
            pc.apply(x, y)
            x.destroy()
            y.destroy()


def scaled_pivots(pc, prefix) -> dict:
    """Zero pivot and nonzero shift of the LU in ``pc`` (its own, PCREDUNDANT's, GAMG's coarsest) scaled to the
    operator where its typical diagonal entry m (the least over the ranks of each rank's median |a_ii|) is below one:
    PETSc's LU calls a pivot zero below 100 eps times the sum of its row's |multipliers| (order one) and |U| entries, an
    absolute test for small entries (a pressure matrix in SI units, 1e-15 A: 177 CG iterations against 32 at A, the
    coarse LU's pivots shifted). Set through the API for an LU, else returned as options (the user's win); empty
    otherwise. Collective."""
    kind = pc.getType()
    if kind not in PIVOTED or (kind == "redundant" and PETSc.Options(prefix).getString("redundant_pc_type", "lu")
                               not in ("lu", "ilu")):
        return {}
    diag = pc.getOperators()[1].getDiagonal()
    local = np.abs(diag.getArray(readonly=True))
    m = float(Collective(pc.getComm()).min_array(np.array([np.median(local) if local.size else np.inf]))[0])
    diag.destroy()
    if not 0 < m < 1:
        return {}
    values = {"pc_factor_zeropivot": UNIT_PIVOT * m, "pc_factor_shift_amount": UNIT_PIVOT * m}
    if kind in ("lu", "ilu"):
        db = PETSc.Options(prefix)
        if not db.hasName("pc_factor_zeropivot"):
            pc.setFactorPivot(zeropivot=values["pc_factor_zeropivot"])
        if not db.hasName("pc_factor_shift_amount"):
            pc.setFactorShift(amount=values["pc_factor_shift_amount"])
        return {}
    return {PIVOTED[kind] + k: str(v) for k, v in values.items()}


def through_api(pc, defaults) -> dict:
    """Set on ``pc`` the ``defaults`` its API can set; returns the others."""
    rest = dict(defaults)
    kind = rest.pop("pc_type", None)
    if kind is not None:
        pc.setType(kind)
    if kind in FACTOR_PCS:
        ordering = rest.pop("pc_factor_mat_ordering_type", None)
        if ordering is not None:
            pc.setFactorOrdering(ordering)
        shift = rest.pop("pc_factor_shift_type", None)
        if shift is not None:
            pc.setFactorShift(SHIFTS[shift])
    if kind == "python" and "pc_python_type" in rest:
        pc.setPythonType(rest.pop("pc_python_type"))
    if kind == "ksp":
        inner = pc.getKSP()
        if "ksp_ksp_type" in rest:
            inner.setType(rest.pop("ksp_ksp_type"))
        if "ksp_ksp_rtol" in rest:
            inner.setTolerances(rtol=float(rest.pop("ksp_ksp_rtol")))
        sub = {k[len("ksp_"):]: rest.pop(k) for k in list(rest) if k.startswith("ksp_pc_")}
        rest.update({"ksp_" + k: v for k, v in through_api(inner.getPC(), sub).items()})
    return owned(pc, rest)


def owned(pc, rest) -> dict:
    """``rest`` without the factor defaults of an inner PC (PCREDUNDANT's, PCBJACOBI's or PCASM's blocks') whose type
    the user chose under ``pc``'s prefix (``redundant_pc_type``, ``sub_pc_type``): that type takes PETSc's own, as a
    user's ``pc_type`` does (the positive_definite shift chosen for ICC(0) made PETSc's LU crash with SEGV)."""
    db = PETSc.Options(pc.getOptionsPrefix() or "")
    for inner in ("redundant_", "sub_"):
        key = inner + "pc_type"
        if key in rest and db.hasName(key) and db.getString(key) != rest[key]:
            rest = {k: v for k, v in rest.items() if not k.startswith(inner + "pc_factor_")}
    return rest


def configured_pc(comm, mat, prefix, defaults) -> tuple:
    """A PC on ``mat`` with ``defaults`` (:func:`through_api`) and, winning over them, the options under
    ``prefix``. Returns (the PC, the defaults its set-up still has to find in the options database)."""
    pc = PETSc.PC().create(comm)
    try:
        pc.setOptionsPrefix(prefix)
        pc.setOperators(mat, mat)
        rest = through_api(pc, defaults)
        with scoped(prefix, rest):
            pc.setFromOptions()
    except Exception:
        pc.destroy()
        raise
    return pc, rest


def multigrid(pc) -> bool:
    """Whether ``pc`` is GAMG, also inside a PCKSP."""
    kind = pc.getType()
    return kind == "gamg" or (kind == "ksp" and multigrid(pc.getKSP().getPC()))


def held(pc) -> int:
    """Values a solver holds on this rank besides its operator: a factor's, or a multigrid hierarchy's coarser
    operators and interpolations, also inside a PCKSP (0 for other PC types, such as PCREDUNDANT's gathered
    copy)."""
    kind = pc.getType()
    if kind == "ksp":
        return held(pc.getKSP().getPC())
    if kind in FACTOR_PCS:
        return int(pc.getFactorMatrix().getInfo()["nz_used"])
    if kind == "python":                        # a factor of the project's own (BandPC's band)
        return int(getattr(pc.getPythonContext(), "values", 0))
    if kind not in ("gamg", "mg"):
        return 0
    levels = pc.getMGLevels()
    mats = [pc.getMGSmoother(level).getOperators()[0] for level in range(levels - 1)]
    mats += [pc.getMGInterpolation(level) for level in range(1, levels)]
    return int(sum(m.getInfo()["nz_used"] for m in mats))


def text(pc, cycles=1) -> str:
    """What the solver ``pc`` does, in a few words (``cycles``: a multigrid PC's V-cycles an application)."""
    kind = pc.getType()
    if kind in ("gamg", "mg"):
        count = {1: "one", 2: "two"}.get(cycles, str(cycles))
        return f"{count} {kind.upper()} V-cycle{'s' if cycles > 1 else ''} ({pc.getMGLevels()} levels)"
    if kind == "ksp":
        inner = pc.getKSP()
        return (f"{inner.getType().upper()} to rtol {inner.getTolerances()[0]:g} preconditioned by "
                f"{inner.getPC().getType().upper()}")
    if kind == "redundant":
        return f"LU on each of the {pc.getComm().getSize()} ranks (redundant)"
    return kind.upper() if kind in FACTOR_PCS else kind


def view(pc, viewer, label):
    """``label`` then PCView of ``pc``, indented, on ``viewer`` (a solver on COMM_SELF: rank 0's, as PCBJACOBI
    shows its first block)."""
    viewer.printfASCII(f"  {label}\n")
    viewer.pushASCIITab()
    viewer.pushASCIITab()
    try:
        if pc.getComm().getSize() == viewer.getComm().getSize():
            pc.view(viewer)
        else:
            sub = viewer.getSubViewer(PETSc.COMM_SELF)
            if viewer.getComm().getRank() == 0:
                pc.view(sub)
            viewer.restoreSubViewer(sub)
    finally:
        viewer.popASCIITab()
        viewer.popASCIITab()
