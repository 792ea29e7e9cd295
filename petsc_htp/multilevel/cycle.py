"""PETSc's PCMG on a :class:`~.hierarchy.Hierarchy`: the V-cycle, its smoothers and its coarse solve.

Options under ``<prefix>`` (HTPPC's ``-htp_ml_``) are PCMG's own: ``-htp_ml_pc_mg_cycle_type w``,
``-htp_ml_mg_levels_ksp_type``, ``-htp_ml_mg_coarse_pc_type`` and so on; the user's win over the defaults below, which
sit in the options database (under the generic ``mg_levels_``, which PETSc reads for every level) for the whole
set-up, so that PCBJACOBI's blocks and PCREDUNDANT's inner LU, made at set-up, find theirs. Where the user sets none
of the levels' options, each level's up smoother is a KSP of its own sharing the down one's PC (one factor), so that
the down one starts from zero and needs no product with A; any ``mg_levels_`` option of the user's leaves the up
smoother under the down one's prefix, so that it reaches both (Gauss-Seidel then sweeps both ways each time).

Three smoothers (:data:`SMOOTHERS`, ``-htp_ml_smoother``): ``gs``, one Gauss-Seidel sweep of each rank's rows
(PCSOR), forward down and backward up, unscaled; ``jacobi``, one Richardson step with D^-1 (no factor, no
leaf-block matrix: the levels' options of the user's then act on the level's operator); ``leaves``, one with the
exact solves of the level's leaf blocks; these two scaled by Lanczos (the finest level's Jacobi step by its
Gershgorin bound where that is at most :data:`DOMINANT`). On 2-D graphs, and 3-D ones without positive couplings,
Gauss-Seidel takes the fewest iterations for the work, on other 3-D ones the leaf solves (see
:func:`smoother`).
"""
from __future__ import annotations

import contextlib

import numpy as np
from petsc4py import PETSc

from ..twolevel.inner import scoped, set_up

DAMPING = 1.5           # the smoother's Richardson scale takes the largest eigenvalue of s M^-1 A down to this
LANCZOS_STEPS = 6       # CG steps for that eigenvalue (each: a product with A and one with M^-1), as PETSc's Chebyshev
SAFETY = 1.1            # ... and the factor on CG's estimate
DOMINANT = 2.0 * SAFETY  # the finest level's Gershgorin bound of D^-1 A up to which it stands for that eigenvalue
COARSE_BAND = 4_000_000  # most values (rows x (bandwidth + 1)) of a coarsest operator's band that LAPACK's banded
# Cholesky factors in place of the sparse LU (32 MB; see banded)
SMOOTHER = {"ksp_type": "richardson", "ksp_max_it": "1", "ksp_norm_type": "none"}
SMOOTHERS = ("jacobi", "leaves", "gs")
DIAGONAL = {"pc_type": "jacobi"}
SWEEPS = ({"pc_type": "sor", "pc_sor_local_forward": ""}, {"pc_type": "sor", "pc_sor_local_backward": ""})
SYMMETRIC_SWEEP = {"pc_type": "sor"}    # PCSOR's own default: the forward sweep then the backward one, each way
LEAF_SOLVE = {1: {"pc_type": "cholesky", "pc_factor_mat_ordering_type": "natural", "pc_factor_shift_type": "nonzero"},
              2: {"pc_type": "bjacobi", "sub_pc_type": "cholesky", "sub_pc_factor_mat_ordering_type": "natural",
                  "sub_pc_factor_shift_type": "nonzero"}}
COARSE = {1: {"ksp_type": "preonly", "pc_type": "lu", "pc_factor_mat_ordering_type": "nd",
              "pc_factor_shift_type": "nonzero"},
          2: {"ksp_type": "preonly", "pc_type": "redundant", "redundant_pc_type": "lu",
              "redundant_pc_factor_mat_ordering_type": "nd", "redundant_pc_factor_shift_type": "nonzero"}}


def smoother(given, dim, signed) -> str:
    """The smoother ``given`` (``-htp_ml_smoother``), or where that is 'auto' the one for a graph of dimension ``dim``:
    Gauss-Seidel in 2-D, or in 3-D where not ``signed()`` (positive couplings: :func:`.choice.signed`, asked only
    there), a forward sweep down and a backward one up (the V-cycle stays symmetric; no eigenvalue estimate): fewer
    iterations than Jacobi, a sweep costing somewhat more than its step (one rank, CG to 1e-8, setup + solve ms over
    three runs in turn, 2026-11-28, results/gs-20261128/run.txt: 65 536 rows dmda2d 129-155 against 132-174 (14 against
    17 iterations), lognormal 105-192 / 112-163 (13 / 15), free_surface 90-99 / 110-140 (11 / 14), neumann 124-182 /
    134-207 (11 / 14); 1 048 576 rows dmda2d 3 070-3 301 / 2 804-3 240 (17 / 20); Jacobi had beaten the leaf solves:
    dmda2d at 1M 2 208 / 2 908 ms); the leaf solves otherwise (262 144 rows, fem_tet 58 against Jacobi's 34 iterations;
    65 536 rows, 28 against Gauss-Seidel's 35). On the 3-D DMDA matrix Gauss-Seidel took 0.6-0.8 x the two-level
    method's time (results/threed-20261129/run.txt), the leaf solves 1.4 x at 1M rows
    (results/multilevel-20261128b/dev.txt)."""
    if given != "auto":
        return given
    return "gs" if dim == 2 or not signed() else "leaves"


def defaults(prefix, ranks, smoother="leaves", lu=True, theirs=None, count=2) -> dict:
    """The PCMG's defaults under ``prefix`` on ``ranks`` (1, or 2 for several) with ``smoother`` (one of
    :data:`SMOOTHERS`), the coarse LU's where ``lu`` (else only KSPPREONLY: the banded factor's PC is set apart):
    PCMG's distinct up smoothers unless the user set a levels' option (Gauss-Seidel then sweeps both ways each time,
    so that the V-cycle stays symmetric). With ``count`` 1 level, PCMG's coarse solve is that level's
    (``mg_levels_0_``), and no smoother's are set (it had taken the smoother's one sweep: CG did not converge in
    10 000 iterations on a 64^2 DMDA, ``results/robust-20261128/ab.txt``)."""
    theirs = users_levels(prefix) if theirs is None else theirs
    sweep = SYMMETRIC_SWEEP if theirs else SWEEPS[0]
    solve = DIAGONAL if smoother == "jacobi" else sweep if smoother == "gs" else LEAF_SOLVE[ranks]
    out = {"mg_levels_" + k: v for k, v in {**SMOOTHER, **solve}.items()} if count > 1 else {}
    coarse = "mg_coarse_" if count > 1 else "mg_levels_0_"
    out.update({coarse + k: v for k, v in COARSE[ranks].items() if lu or k == "ksp_type"})
    if count == 1 and not lu:
        out[coarse + "pc_type"] = "python"             # the banded factor's, which a user's levels' type would replace
    if not theirs:
        out["pc_mg_distinct_smoothup"] = "true"
    return out


def users_levels(prefix, names=None) -> bool:
    """Whether the user set some levels' option (``mg_levels_``) under ``prefix`` (``names``: the options database's
    names, where read)."""
    names = PETSc.Options().getAll() if names is None else names
    return any(name.startswith(prefix + "mg_levels_") for name in names)


def multigrid(hierarchy, prefix, damping=DAMPING, smoother="leaves", ground=None):
    """A PCMG (set up) running V-cycles on ``hierarchy`` under the options ``prefix`` with ``smoother`` (one of
    :data:`SMOOTHERS`; ``leaves`` needs the hierarchy's leaf blocks), the coarsest operator's rows ``ground``
    grounded in its banded factor (:func:`banded`); returns (the PC, the Richardson scale of each smoothed level,
    finest first, :class:`Scale`)."""
    ops = hierarchy.operators()
    comm = ops[0].getComm()
    pc = PETSc.PC().create(comm)
    try:
        pc.setOptionsPrefix(prefix)
        pc.setOperators(ops[0], ops[0])
        pc.setType(PETSc.PC.Type.MG)
        count = len(ops)
        pc.setMGLevels(count)
        pc.setMGType(PETSc.PC.MGType.MULTIPLICATIVE)
        names = PETSc.Options().getAll()                   # the user's, before the defaults
        coarse = ("mg_coarse_pc_", "mg_coarse_redundant_") if count > 1 else ("mg_levels_0_pc_",)
        own = any(name.startswith(tuple(prefix + c for c in coarse)) for name in names)    # the user's coarse solver
        made = None if own else banded(ops[-1], ground)
        theirs = users_levels(prefix, names)
        finest = None if count < 2 or theirs else hierarchy.levels[0].bound
        with scoped(prefix, defaults(prefix, 1 if comm.getSize() == 1 else 2, smoother, made is None, theirs, count),
                    None if count > 1 else names):      # one level: its own options, not the user's smoothers
            pc.setFromOptions()
            for level in range(1, count):
                pc.setMGInterpolation(level, hierarchy.levels[count - 1 - level].W)
            coarse = pc.getMGCoarseSolve()
            coarse.setOperators(ops[-1], ops[-1])
            coarse.setFromOptions()
            if made is not None:
                from ..twolevel.band import BandPC

                coarse.getPC().setType(PETSc.PC.Type.PYTHON)
                coarse.getPC().setPythonContext(BandPC(made=made))
            for level in range(1, count):
                mine = hierarchy.levels[count - 1 - level]
                down, up = pc.getMGSmootherDown(level), pc.getMGSmootherUp(level)
                B = mine.A if mine.B is None else mine.B
                down.setOperators(mine.A, B)
                down.setFromOptions()
                if up.handle != down.handle:                    # distinct: the same step, from x, on down's PC
                    if smoother == "gs" and not theirs:         # ... or the backward sweep, its own
                        with scoped(up.getOptionsPrefix(), SWEEPS[1]):
                            up.getPC().setFromOptions()
                    else:
                        up.setPC(down.getPC())
                    up.setOperators(mine.A, B)
                    up.setType(PETSc.KSP.Type.RICHARDSON)
                    up.setTolerances(max_it=1)
                    up.setNormType(PETSc.KSP.NormType.NONE)
            if made is None:
                set_up(coarse.getPC(), coarse.getOptionsPrefix(), {})
            pc.setUp()
            scales = [_damped(pc, level, damping, finest if level == count - 1 else None)
                      for level in range(count - 1, 0, -1)]
    except Exception:
        pc.destroy()
        raise
    return pc, scales


@contextlib.contextmanager
def bare(A):
    """``A`` with its null space detached while the V-cycle runs: each smoother's KSPSolve would project its
    right-hand side on it, and on the transpose null space a symmetric matrix takes from it (a copy, a sum and a
    shift a step; PCMG's application on the bare Neumann square of 65 536 rows took 5.4 ms so, 3.6 without). The
    outer KSP projects M's output and the coarsest factor is grounded. Both are attached again after, a transpose null
    space other than the null space as it was (MatSetNullSpace sets the transpose one too on a symmetric matrix)."""
    null = A.getNullSpace()
    if not null.handle:
        yield A
        return
    transpose = A.getTransposeNullSpace()
    A.setNullSpace(PETSc.NullSpace())
    try:
        yield A
    finally:
        A.setNullSpace(null)
        if transpose.handle and transpose.handle != null.handle:
            A.setTransposeNullSpace(transpose)


def banded(A, ground=None):
    """The banded Cholesky factor of the coarsest operator ``A`` (LAPACK's, of its rows gathered on every rank; its rows
    ``ground`` grounded, :meth:`..twolevel.band.Band.factor`) as
    (:class:`..twolevel.band.Band`, rows grounded) for :class:`..twolevel.band.BandPC`, the coarse solve where there
    are levels and the user set no ``mg_coarse_pc_`` option (nor PCREDUNDANT's): where its band in its own or reverse
    Cuthill-McKee order holds at most :data:`COARSE_BAND` values and no rank's factor has a negative pivot; else None,
    the sparse LU in nested-dissection order (collective). Set-up against the LU's, one rank, 2026-11-28
    (``results/coarse-20261128/band.txt``): the 2-D DMDA's coarsest operators of 1 682 rows (65 536 fine rows, band
    146 wide) 3.9 against 14.3 ms, 3 202 (1M, 274 wide) 19 against 83, 1 658 (4M, 235) 9.6 against 69; the 3-D
    DMDA's (64^3, multilevel) 334 rows (279 wide) 3.4 against 25.6, 3 146 (1 098 wide) 110 against 2 898. A solve
    with the band costs no more than one with the LU up to there (0.61 against 0.70 ms; 5.1 against 5.4); 23 533 rows
    528 wide (12.4M values) took 345 against 1 622 ms but 27 against 11 ms a solve."""
    from ..collective import Collective
    from ..petscmat import gathered_rows, local_rows
    from ..twolevel.band import Band, ordering

    if 2 * A.getSize()[0] > COARSE_BAND:             # no band of coupled rows fits: nothing gathered
        return None
    mpi = A.getComm().tompi4py() if A.getComm().getSize() > 1 else None
    with local_rows(A) as mine:
        rows = mine if mpi is None else gathered_rows(mine, mpi)
        order = ordering(rows)
        if rows.shape[0] * (order[3] + 1) > COARSE_BAND:
            return None
        band = Band(rows, order)
        info, grounded = band.factor(rows.data, ground)
    ok = Collective(A.getComm()).min_array(np.array([info == 0], dtype=np.int64))[0]   # every rank alike
    return (band, grounded) if ok else None          # a negative pivot (a shifted problem's): the LU


def coarse_text(pc) -> str:
    """The coarse solver of the PCMG ``pc`` in a few words: its PC type, or the banded factor's description."""
    coarse = pc.getMGCoarseSolve().getPC()
    python = coarse.getType() == PETSc.PC.Type.PYTHON
    describe = getattr(coarse.getPythonContext(), "describe", None) if python else None
    return describe() if describe is not None else coarse.getType()


def described(pc, scales, damping) -> str:
    """What the smoothers of ``pc`` are, for ``-ksp_view``, with their ``scales``."""
    if pc.getMGLevels() < 2:
        return "none"
    ksp = pc.getMGSmootherDown(1)
    kind, solve = ksp.getType(), ksp.getPC().getType()
    A, P = ksp.getOperators()
    scaled = ", ".join(f"{s:.2f}" for s in scales) or "-"
    if kind != PETSc.KSP.Type.RICHARDSON:
        return f"{kind} (the user's options), scaled {scaled}"
    if solve == PETSc.PC.Type.SOR:
        if pc.getMGSmootherUp(1).getPC().handle != ksp.getPC().handle:
            return "one Gauss-Seidel sweep of each rank's rows (PCSOR), forward down and backward up, unscaled"
        return f"PCSOR of each rank's rows both ways (the user's options), scaled {scaled}"
    if solve == PETSc.PC.Type.JACOBI:
        what, op = "D^-1 (Jacobi)", "D^-1 A"
    elif P.handle != A.handle:                              # the leaf-block matrix
        what = "the leaf blocks' exact solves" if solve in ("cholesky", "bjacobi") else f"{solve} of the leaf blocks"
        op = "B^-1 A"
    else:
        what, op = f"{solve} of the level's operator (the user's options)", "M^-1 A"
    by = [s.by for s in scales]
    est = (": the finest level's Gershgorin bound" + (", Lanczos' on the others" if len(by) > 1 else "")
           if by[:1] == ["Gershgorin"] else ": Lanczos'" if "Lanczos" in by else "")
    est += "; the user's scale where given" if est and "" in by else ""
    return (f"one Richardson step with {what}, scaled {scaled} (largest eigenvalue of s {op} taken to "
            f"{damping:g}{est})")


class Scale(float):
    """A smoother's Richardson scale, :attr:`by` naming what gave the eigenvalue it takes to the damping: 'Gershgorin',
    'Lanczos', 'sweep' (Gauss-Seidel's, unscaled) or '' (the user's scale)."""

    def __new__(cls, value, by=""):
        scale = super().__new__(cls, value)
        scale.by = by
        return scale


def _damped(pc, level, damping, bound=None) -> Scale:
    """The Richardson scale min(1, ``damping`` / lambda), lambda the largest eigenvalue of the smoother's
    preconditioned operator (B^-1 A or D^-1 A: Lanczos, CG's extreme singular values after :data:`LANCZOS_STEPS`
    steps from a random b, times :data:`SAFETY`; the Gershgorin bound of D^-1 A damps coarse levels too much:
    1M-row dmda2d 35 against 24 iterations), given to the smoothers of ``level`` of ``pc`` unless the user set
    one; returns the down smoother's scale (1 for another KSP). Where ``bound``, the Gershgorin bound of D^-1 A
    (given for the finest level where the user set no levels' option), is at most :data:`DOMINANT` and the
    smoother is Jacobi, it is lambda: no Lanczos, whose CG steps on the finest level cost most of it. Weakly
    diagonally dominant rows bound it by 2, which a mesh's checkerboard mode nearly reaches, so that Lanczos' estimate
    times SAFETY lies about as high (the 2-D DMDA's 1.92 x 1.1; the finest operator's diagonal is positive:
    :mod:`..validation`)."""
    smoother = pc.getMGSmootherDown(level)
    if smoother.getType() != PETSc.KSP.Type.RICHARDSON:
        return Scale(1.0)
    generic = pc.getOptionsPrefix() + "mg_levels_ksp_richardson_scale"
    if PETSc.Options().hasName(generic):                   # the user's, for every level: no estimate
        return Scale(PETSc.Options().getReal(generic))
    if smoother.getPC().getType() == PETSc.PC.Type.SOR:     # Gauss-Seidel's sweeps: unscaled
        return Scale(1.0, "sweep")
    bounded = bound is not None and bound <= DOMINANT and smoother.getPC().getType() == PETSc.PC.Type.JACOBI
    top = bound if bounded else _largest(smoother)
    scale = min(1.0, damping / top) if top > 0 else 1.0
    for ksp in {smoother.handle: smoother, pc.getMGSmootherUp(level).handle: pc.getMGSmootherUp(level)}.values():
        with scoped(ksp.getOptionsPrefix(), {"ksp_richardson_scale": str(scale)}):
            ksp.setFromOptions()
    level_own = PETSc.Options(smoother.getOptionsPrefix())          # a scale the user gave this level wins
    if level_own.hasName("ksp_richardson_scale"):
        return Scale(level_own.getReal("ksp_richardson_scale"))
    return Scale(scale, "Gershgorin" if bounded else "Lanczos")


def _largest(smoother) -> float:
    """Lanczos' largest eigenvalue of the ``smoother``'s preconditioned operator, times :data:`SAFETY`."""
    A = smoother.getOperators()[0]
    est = PETSc.KSP().create(A.getComm())
    b, x = A.createVecs()
    try:
        est.setOperators(A, A)
        est.setPC(smoother.getPC())
        est.setType(PETSc.KSP.Type.CG)
        est.setNormType(PETSc.KSP.NormType.NONE)
        est.setTolerances(rtol=0.0, atol=0.0, max_it=LANCZOS_STEPS)
        est.setConvergenceTest(lambda *args: 0)
        est.setComputeSingularValues(True)
        start = A.getOwnershipRange()[0]            # numpy's generator: PETSc's VecSetRandom took 2.2 ms at 65 536 rows
        b.array_w[:] = np.random.default_rng(start + 1).random(b.getLocalSize())       # (six CG steps: 5)
        null = A.getNullSpace()
        if null.handle:             # b in A's range: KSPSolve projects it only where A is flagged symmetric, which
            null.remove(b)          # new values (MatSetValues) unset: a Neumann frame's estimate was 4.5 x too large
        est.solve(b, x)
        return SAFETY * est.computeExtremeSingularValues()[0]
    finally:
        for obj in (b, x, est):
            obj.destroy()
