"""A small matrix's preconditioner: one factor of the whole matrix, exact (sparse Cholesky, one iteration) or
incomplete (ICC(0)).

Below the sizes of :func:`petsc_htp.twolevel.sizing.whole_factor`, a factor of the whole matrix costs less than
building leaves, a coarse space and their products (sizing's docstring has the measurement). On one rank a singular
matrix (an attached null space, or vanishing row sums on a connected component; for ICC(0), whose shift takes a
null component among regular ones, only where every row sum vanishes: the components' search was 0.35 of the 1.2 ms
setup of PyAMG's 600-row bar) is grounded first: one diagonal entry of each null component is raised by its own
magnitude, so the factor exists and is exact on vectors
orthogonal to the component's constant, which is what a KSP with the null space attached hands over; and the
Cholesky factor's inertia checks that the matrix is positive (semi)definite: negative pivots are an error that says
so. ICC(0)'s shift keeps its pivots positive, so there an indefinite matrix is named by the KSP (CG stops with
DIVERGED_INDEFINITE_MAT or _PC). On several ranks PCREDUNDANT gathers the whole matrix on every rank and factors it
there (also where a rank owns no rows, up to :data:`.sizing.REDUNDANT_MAX` rows; above, HTPPC on the ranks
that own rows: :mod:`.telescope`); its factor's shift takes a singular matrix whose null space the KSP
removes, and its inertia is not at hand (PCREDUNDANT does not show its factor): an exact factor solves an
indefinite matrix as well, in one iteration.
"""
from __future__ import annotations

import time

import numpy as np
from petsc4py import PETSc

from . import directview, exactstart, nullspace, telescope
from ..collective import Collective
from .band import Band, BandPC
from .consistency import RangeCheck
from .csr import row_sums
from .inner import configured_pc, set_up
from .projection import Projection, drop, gathered

FACTORS = {"cholesky": {"pc_type": "cholesky", "pc_factor_mat_ordering_type": "nd", "pc_factor_shift_type": "nonzero"},
           "icc": {"pc_type": "icc", "pc_factor_mat_ordering_type": "natural",
                   "pc_factor_shift_type": "positive_definite"},
           "band": {"pc_type": "python", "pc_python_type": "petsc_htp.twolevel.band.BandPC"}}   # LAPACK's band
GATHERED = {"cholesky": {"pc_type": "lu", "pc_factor_mat_ordering_type": "nd", "pc_factor_shift_type": "nonzero"}}
# several ranks: the gathered exact factor is PETSc's LU (a 1 521-row 2-D matrix's takes 1.14 ms against its
# Cholesky's 1.58; the Cholesky's inertia is not at hand inside PCREDUNDANT)
BLOCKS = {"pc_type": "bjacobi", "sub_pc_type": "icc", "sub_pc_factor_shift_type": "positive_definite"}
OVERLAP = 4             # 'asm': layers each rank's block grows by (rotated anisotropy on 2 ranks, 262 144 rows: 1, 2, 4
# and 8 layers 141, 114, 99 and 87 CG iterations on the 30-degree case, where each block alone took 241)
GROWN = {"pc_type": "asm", "pc_asm_type": "basic", "pc_asm_overlap": str(OVERLAP), "sub_pc_type": "icc",
         "sub_pc_factor_shift_type": "positive_definite"}
BLOCKED = {"bjacobi": BLOCKS, "asm": GROWN}       # kinds of one ICC(0) per rank
INCOMPLETE = ("icc", *BLOCKED)                     # kinds chosen for the iterations they save
OWN = (*BLOCKED, "telescope", "band")   # kinds that PCREDUNDANT does not gather ('telescope': :mod:`.telescope`;
# 'band': :class:`.band.BandPC` gathers the rows itself)


def factor_options(kind: str, mat, rows) -> dict:
    """The factor's PETSc options (:data:`FACTORS`); on several ranks (:data:`GATHERED` where it differs) inside
    PCREDUNDANT, which gathers the whole
    matrix on every rank (a rank that owns no rows included) and factors it there, but for 'bjacobi' (diagonally
    dominant, shifted, wide or grid-aligned rows, a graph that is no mesh): ICC(0) of each rank's diagonal block
    (:data:`BLOCKS`), for 'asm' (strongly anisotropic rows) of each rank's block grown by :data:`OVERLAP` layers,
    additive and symmetric (:data:`GROWN`), and for 'telescope' HTPPC on the ranks that own rows (:mod:`.telescope`);
    ``mat`` the operator, ``rows`` this rank's (collective for 'telescope')."""
    if kind in BLOCKED:
        return dict(BLOCKED[kind])
    if kind == "telescope":
        return telescope.options(mat, rows)
    if mat.getComm().getSize() == 1 or kind == "band":
        return dict(FACTORS[kind])
    return {"pc_type": "redundant", **{"redundant_" + k: v for k, v in GATHERED.get(kind, FACTORS[kind]).items()}}


class DirectPC:
    """The whole matrix factored (the interface of :class:`~petsc_htp.twolevel.composed.TwoLevelPC`).

    Parameters
    ----------
    mat : petsc4py.PETSc.Mat
        An AIJ operator; on several ranks factored whole on every rank (:func:`factor_options`).
    rows : scipy.sparse.csr_matrix
        This rank's rows (the analysed pattern).
    kind : str
        cholesky, band (LAPACK's banded Cholesky in its own or reverse Cuthill-McKee order, :mod:`.band`) or icc
        (:data:`FACTORS`), or bjacobi or asm
        (ICC(0) of each rank's block, grown for asm: :func:`factor_options`), or telescope (HTPPC on the ranks that
        own rows: :mod:`.telescope`).
    prefix : str
        Options prefix of the factor: ``<prefix>leaf_`` (of the telescope: ``<prefix>``).
    why : str, optional
        Why the whole matrix is factored (None: it is small enough).
    holds : callable, optional
        (rows, start) -> bool, where the factor was chosen for what new values may lose (the rows' diagonal
        dominance, :func:`.dominance.holds`; their row sums, :func:`.incomplete.shifted`; their anisotropy,
        :func:`.incomplete.holds`; their weak couplings, :func:`.incomplete.wide` and :func:`.incomplete.aligned`):
        values that lose it call for a new analysis. These choices were made for a matrix that is not singular
        (dominant rows; rows that sum to a share of their diagonal; no null space and row sums that do not all
        vanish), so their factor skips the grounding test (0.3 s at 1M rows).
    made : petsc4py.PETSc.PC or .band.Band, optional
        What the choice made: the ICC(0) trial's PC, set up on the whole matrix (:func:`.incomplete.trial_drop`, one
        rank), applied as it is where no option is set under the prefix (at 64 000 rows its factor cost 16 ms of Q1
        hexahedra's setup); or the banded factor's order (reverse Cuthill-McKee's: 5 ms for a strip of 65 536 rows).
    """

    whole = True            # one factor of the whole matrix: no leaves, so the rows' split over the ranks costs nothing

    def __init__(self, mat, rows, kind, prefix, why=None, holds=None, made=None):
        t0 = time.perf_counter()
        self.mat, self.kind, self.why, self.holds = mat, kind, why, holds
        self.prefix = prefix + ("" if kind == "telescope" else "leaf_")           # (:mod:`.telescope`)
        self.trial, self.order = (None, made) if isinstance(made, Band) else (made, None)
        self.ranks = mat.getComm().getSize()
        self.n_comp, self.comp_of_row = 0, None          # the graph's components, found where grounding needs them
        self.G = self.pc = self.range = None       # range: the null constants b must not hold (:mod:`.consistency`)
        self.project = None                         # P off A's null space (:mod:`.projection`)
        self.rest, self.gathered = {}, 0
        self.age, self.times, self.null_components = 0, {}, 0
        self.analysis_ms = 1e3 * (time.perf_counter() - t0)

    def moved(self, rows, penalty=None) -> bool:
        """Whether new values ``rows`` (this rank's) call for a new analysis: only where the factor was chosen for
        what the rows have (:attr:`holds`) and this rank's rows lost it."""
        return self.holds is not None and not self.holds(rows, self.mat.getOwnershipRange()[0])

    def inner_pcs(self) -> dict:
        """The factor."""
        return {"factor": self.pc}

    def numeric(self, rows, density=None, keep_space=False, every=False):
        """Factor the new values (on one rank grounded where a component is null, ``every`` one where the factor
        had negative pivots: a null vector other than the constant, as D^-1 1 of a singular D A D; on several the
        KSP's null space and the factor's shift take a singular matrix)."""
        t0 = time.perf_counter()
        ground = self.ranks == 1 and (self.holds is None or every)     # see holds: chosen for a regular matrix
        self.range, self.project = None, drop(self.project)           # new values may have lost the null space
        target = self._grounded(rows, every) if ground else self.mat
        if self.ranks > 1 and self.holds is None:
            self.range, self.project = gathered(self.mat, rows)
        if self.pc is None:
            factor = factor_options(self.kind, self.mat, rows)
            self.pc, self.rest = self._adopted(target) or configured_pc(self.mat.getComm(), target, self.prefix, factor)
            if self.order is not None and self._band() is not None:
                self._band().band, self.order = self.order, None        # the choice's order (one rank)
            if self.ranks > 1 and self.kind not in OWN and self.pc.getType() != "redundant":   # -htp_leaf_pc_type is
                self.pc.setType("redundant")      # the leaf solver's: the gathered factor's is -htp_leaf_redundant_pc_type
            key = "pc_factor_mat_ordering_type"                # (each block's ICC(0) orders as PETSc's ICC does)
            self.ordering = None if self.kind in OWN or self.kind == "band" else PETSc.Options(
                self.prefix).getString(("redundant_" if self.ranks > 1 else "") + key, FACTORS[self.kind][key])
        else:
            self.pc.setOperators(target, target)
        try:
            (telescope.set_up_everywhere if self.kind == "telescope" else set_up)(self.pc, self.prefix, self.rest)
        except PETSc.Error:                                    # (several ranks: BandPC's own message, as cause)
            if self._band() is None or self._band().info <= 0:
                raise
            raise ValueError(f"HTPPC needs a symmetric positive (semi)definite matrix, but its banded Cholesky "
                             f"factor has a negative pivot in {self.mat.getSize()[0]} rows: the matrix is indefinite") from None
        self.times = {"factor": 1e3 * (time.perf_counter() - t0)}
        if self.ranks > 1 and self.kind not in OWN:   # the gathered values' bytes, read here (collective)
            self.gathered = int(8 * self.mat.getInfo(PETSc.Mat.InfoType.GLOBAL_SUM)["nz_used"])
        if self.pc.getType() == "cholesky" and self.pc.getFailedReason() == PETSc.PC.FailedReason.NOERROR:
            negative = self.pc.getFactorMatrix().getInertia()[0]
            if negative and self.ranks == 1 and not every:
                return self.numeric(rows, density, keep_space, every=True)
            if negative:
                raise ValueError(f"HTPPC needs a symmetric positive (semi)definite matrix, but its Cholesky factor "
                                 f"has {negative} negative pivot(s) in {rows.shape[0]} rows: the matrix is indefinite")

    def _band(self):
        """The banded factor's context (:class:`.band.BandPC`) where it is the factor on this rank, else None."""
        ctx = self.pc.getPythonContext() if self.pc.getType() == "python" else None
        return ctx if isinstance(ctx, BandPC) else None

    def _adopted(self, target):
        """(the trial's PC, no options left) where it may serve as the factor: ICC(0) of ``target`` itself, on one
        rank, with no option under the prefix; else None (the trial's PC freed)."""
        pc, self.trial = self.trial, None
        if pc is None:
            return None
        mine = [name for name in PETSc.Options().getAll() if name.lower().startswith(self.prefix.lower())]
        try:
            if self.kind != "icc" or self.ranks > 1 or mine or pc.getOperators()[1].handle != target.handle:
                pc.destroy()
                return None
            pc.setOptionsPrefix(self.prefix)
            pc.setFactorShift(shift_type=PETSc.Mat.FactorShiftType.POSITIVE_DEFINITE)   # FACTORS' (new values')
        except BaseException:
            pc.destroy()
            raise
        return pc, {}

    def _grounded(self, rows, every=False):
        """The operator, or its copy with one diagonal entry of each null component (``every`` component) raised (one
        rank)."""
        nsp, diag = self.mat.getNullSpace(), rows.diagonal()
        rowsum = None if nsp.handle else row_sums(rows.indptr, rows.data)       # (scipy's sum: 3 x the time)
        vanish = None if rowsum is None else nullspace.vanishing(rowsum, diag)
        if not every and vanish is not None and not (vanish.all() if self.kind == "icc" else vanish.any()):
            self.null_components = 0                     # no component can be null (ICC(0): where some row sum
            return self.mat                              # stays, its shift takes a null component; 0.35 of 1.2 ms)
        if self.comp_of_row is None:
            self.n_comp, self.comp_of_row = nullspace.graph_components(rows)
        if every:
            null = np.ones(self.n_comp, dtype=bool)
        elif nsp.handle:
            null = nullspace.null_from_vectors([z.getArray(readonly=True) for z in nsp.getVecs()], nsp.hasConstant(),
                                               self.comp_of_row, self.n_comp)
        else:
            null = nullspace.null_by_rowsums(rowsum, diag, self.comp_of_row, self.n_comp)
            if null.any():              # not those whose signs and row sums show them regular
                null &= ~nullspace.m_regular(rows, self.comp_of_row, self.n_comp, rowsum)
            if null.any():
                self.range = RangeCheck(rows, self.comp_of_row, null, Collective(self.mat.getComm()))
        self.null_components = int(null.sum())
        if not null.any():
            return self.mat
        if nsp.handle:
            self.project = Projection(self.mat, nsp)
        grounded = nullspace.first_rows(self.comp_of_row, null)
        if self.G is None:
            self.G = self.mat.duplicate(copy=True)
        else:
            self.mat.copy(self.G, structure=PETSc.Mat.Structure.SAME_NONZERO_PATTERN)
        for i, d in zip(grounded, rows.diagonal()[grounded]):
            self.G.setValue(int(i), int(i), abs(d), addv=PETSc.InsertMode.ADD_VALUES)
        self.G.assemble()
        return self.G

    def mult(self, x, y):
        """y = (grounded or shifted A)^-1 x, projected off A's null space where it has one (:mod:`.projection`)."""
        if self.project is None:
            self.pc.apply(x, y)
        else:
            self.project.apply(self.pc, x, y)

    def presolve(self, ksp, b, x, stale=False):
        """A named error where b holds a part along null constants the factor found (:mod:`.consistency`); where the
        factor is exact and made from the KSP's operator (not ``stale``), the start x0 += M r0 (:mod:`.exactstart`;
        not for PREONLY, which takes no guess). Returns the KSP settings to give back after the solve, or None."""
        if self.range is not None:
            self.range.check(ksp, b)
        if stale or ksp.getType() == PETSc.KSP.Type.PREONLY or not self._exact():
            return None
        return exactstart.start(ksp, b, x, self.mult)

    def _exact(self) -> bool:
        """Whether the PC made solves A: a factor (PCREDUNDANT's inner one on several ranks) or the banded one."""
        kind = self.pc.getType()
        kind = PETSc.Options(self.prefix).getString("redundant_pc_type", "lu") if kind == "redundant" else kind
        return kind in ("cholesky", "lu") or self._band() is not None

    def check(self, probes=0) -> str:
        """Empty when the factorisation succeeded."""
        reason = self.pc.getFailedReason()
        return "" if reason == PETSc.PC.FailedReason.NOERROR else f"the factorisation failed ({reason})"

    @property
    def nbytes(self) -> int:
        """Bytes of the factor (:func:`.directview.factor_bytes`)."""
        return directview.factor_bytes(self, BLOCKED, OWN)

    def describe(self) -> list:
        """Lines for ``-ksp_view`` (:func:`.directview.describe`)."""
        return directview.describe(self, OVERLAP)

    def destroy(self):
        """Free the factor, the grounded copy and a trial PC not taken."""
        for name in ("pc", "G", "trial"):
            obj = getattr(self, name, None)
            if obj is not None:
                obj.destroy()
                setattr(self, name, None)
        self.project = drop(self.project)
