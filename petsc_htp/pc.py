"""PETSc integration: HTPPC, a ``PCPYTHON`` preconditioner.

Use it from the command line of any petsc4py program::

    -ksp_type cg -ksp_norm_type unpreconditioned -pc_type python -pc_python_type petsc_htp.HTPPC

or in code::

    pc = ksp.getPC()
    pc.setType("python")
    pc.setPythonContext(petsc_htp.HTPPC())

The default (the two-level method) takes a matrix on any number of ranks as it is; the paper's variant needs
one rank per block (``-pc_type bjacobi -sub_pc_type python -sub_pc_python_type petsc_htp.HTPPC``, whose
options then carry the ``sub_`` prefix).

Like Firedrake's preconditioners, :class:`HTPPC` is configured only through its options prefix,
``pc.getOptionsPrefix() + "htp_"``: the options of :class:`~petsc_htp.pcoptions.HTPOptions` (``-help`` lists
them with their defaults), read in ``setFromOptions`` and again in ``setUp`` (a PCPYTHON context may be set up
without ``setFromOptions`` ever running). Geometry can be supplied with :func:`attach`; without it the leaves
come from the matrix alone.

Setup has two steps, like Firedrake's ``initialize``/``update``: the analysis (leaves, structure;
:mod:`petsc_htp.variants`) runs when the nonzero pattern, the attached coordinates or a pattern option changed;
the numeric step (factors, coarse space, products) when only the values did. PETSc calls ``setUp`` only when the
operator's state changed, so ``-ksp_reuse_preconditioner`` skips both. ``-log_view`` shows an event per phase
(:mod:`petsc_htp.events`), ``-ksp_view`` the inner solvers.
"""
from __future__ import annotations

import contextlib
import time

import numpy as np
from petsc4py import PETSc

from .checks import check_message
from .collective import Collective
from .events import event
from .keptcolumns import KeptColumns, kept_columns
from .pcoptions import HTPOptions
from .pcview import Inspection
from .ranksplit import crossing
from .validation import check_attached, check_layout, check_matrix, check_size
from .petscmat import VERSION_ATTR, aij_operator, attach, attached, local_rows, post_solve
from .threads import set_threads
from .twolevel.consistency import ESTIMATE
from .variants import variant_class

__all__ = ["HTPPC", "attach"]


def give_back(ksp, changed) -> None:
    """Give ``ksp`` back the settings a start ``changed`` (initial-guess flag, divergence tolerance); returns None."""
    changed = changed or {}
    if "guess" in changed:
        ksp.setInitialGuessNonzero(changed["guess"])
    if "divtol" in changed:
        ksp.setTolerances(divtol=changed["divtol"])


def unwinding(presolve):
    """``presolve`` that, where it raises, first runs PETSc's PCPostSolve (:func:`.petscmat.post_solve`), whose
    Python side then has no solve to tell (:attr:`HTPPC._started` None)."""
    def wrapped(self, pc, ksp, b, x):
        try:
            return presolve(self, pc, ksp, b, x)
        except Exception:
            self._started = None
            post_solve(pc, ksp)
            raise
    wrapped.__doc__ = presolve.__doc__
    return wrapped


class HTPPC(Inspection):
    """petsc4py ``PCPYTHON`` context applying an HTP preconditioner.

    Constructed without arguments (``-pc_python_type petsc_htp.HTPPC``);
    configured through ``<prefix>htp_*`` options (see the module docstring).

    Attributes
    ----------
    opts : HTPOptions
        The options of the last setup.
    setup : object or None
        The current preconditioner (numeric step of the variant).
    analysis_count, numeric_count : int
        How many analyses (new pattern) and numeric steps (new values) ran.
    setup_ms : float
        Wall time of the last numeric step, in ms.
    fallback_active : bool
        True while ``-htp_fallback jacobi`` replaced M by ``D^-1``.
    """

    def __init__(self):
        self.opts, self.variant, self.analysis, self.setup = HTPOptions(), None, None, None
        self.analysis_count = self.numeric_count = 0
        self.setup_ms, self.fallback_active, self.fallback_reason = float("nan"), False, ""
        self.n = self.inv_diag = self._pattern = self._values = self._coords = self._changed = self.cut = None
        self._started, self._csr, self.threads_note, self._help_shown = 0.0, (None, None, None), "", False
        self._aij, self._retired = None, []     # an AIJ copy of a BAIJ/SBAIJ operator; earlier ones still in use
        self.columns = KeptColumns()            # A' where Dirichlet rows keep their columns (MatZeroRows)
        self._ev_setup, self._ev_apply = event("HTPSetup"), event("HTPApply")

    def setFromOptions(self, pc):
        """Read the options; with ``-help`` print them with their defaults."""
        self.opts = HTPOptions.from_petsc(pc.getOptionsPrefix() or "")
        if not self._help_shown and PETSc.Options().hasName("help"):
            self._help_shown = True
            PETSc.Sys.Print(self.opts.help_text("-" + (pc.getOptionsPrefix() or "") + "htp_"), comm=pc.getComm())

    def setUp(self, pc):
        """Analyse a new pattern, then run the numeric step for new values (each only when needed)."""
        self.prefix = pc.getOptionsPrefix() or ""
        opts = self.opts = HTPOptions.from_petsc(self.prefix)
        P = pc.getOperators()[1]
        coords, density = attached(P)
        values = (P.getId(), P.stateGet(), P.getAttr(VERSION_ATTR), opts)
        if values == self._values and self.setup is not None:
            return
        self._ev_setup.begin()
        try:
            self._values = None
            self._threads(opts)
            check_size(P)
            check_attached(P, coords, density)
            P = self._operator(P)
            with _checked_rows(self, P, opts.variant) as (P, A):    # this rank's rows (all on one rank)
                self._setup(P, A, coords, density, opts)
            _check(self, pc, opts)
            self._values = values
        finally:
            self._ev_setup.end()

    def _operator(self, P):
        """``P`` when it is AIJ, else its AIJ copy refreshed with the new values (:func:`.petscmat.aij_operator`);
        a copy that gives way stays alive until the analysis that holds it is freed (a failed new analysis
        leaves the previous preconditioner as it was)."""
        M = aij_operator(P, self._aij)
        if self._aij is not None and M is not self._aij:
            self._retired.append(self._aij)
        self._aij = None if M is P else M
        return M

    def _threads(self, opts):
        """This process's BLAS, OpenMP and torch threads as ``-htp_threads`` says (:mod:`petsc_htp.threads`)."""
        changed = set_threads(opts.threads)
        if changed is not None:
            self.threads_note = f"set process-wide to {opts.threads} by -{self.prefix}htp_threads (was {changed})"

    def _setup(self, P, A, coords, density, opts):
        """Analyse when the pattern, coordinates or a pattern option changed, then the numeric step.

        A new analysis and its first numeric step are built aside and swapped in only when both succeed
        (a failure leaves the previous preconditioner as it was); a failed numeric step on the current
        analysis frees it (the PC is then cleanly empty). New values of the same pattern that call for new
        leaves (the variant's ``moved``, on any rank; the multilevel V-cycles make theirs in the numeric step) free the
        current analysis first: the new one reuses its memory
        (built beside it, a 1M-row DMDA frame's setup took 4.1 against 2.7 s, the difference first touches of
        new pages), and a failure leaves the PC empty, as a failed numeric step does.
        """
        pattern = (P.getId(), opts.pattern_key())
        nonzero = A.data != 0
        changed = (pattern != self._pattern or self.analysis is None or not _same_array(coords, self._coords)
                   or not (_same_array(A.indptr, self._csr[0]) and _same_array(A.indices, self._csr[1])
                           and _same_array(nonzero, self._csr[2])))
        coll = Collective(P.getComm())
        moved = not changed and self.variant.moved(self.analysis, A)     # values that call for new leaves
        if coll.any(changed or moved):
            if not coll.any(changed):
                self._free()
            variant = self.variant
            if variant is None or variant.opts.pattern_key() != opts.pattern_key():
                variant = variant_class(opts.variant)(opts, self.prefix)
                self._threads(opts)
            variant.opts = opts
            analysis = variant.analyse(P, A, coords)
            try:            # the row split's cut where leaves stay within a rank (not a whole-matrix factor's)
                cut = None if getattr(analysis, "whole", False) else crossing(P, A, coll, nonzero)
                t0 = time.perf_counter()
                setup = variant.numeric(analysis, P, A, density, None)
            except Exception:
                variant.destroy(analysis)
                raise
            self._free()
            self.variant, self.analysis, self.setup, self.cut = variant, analysis, setup, cut
            self._coords = None if coords is None else coords.copy()
            self._csr = (A.indptr.copy(), A.indices.copy(), nonzero)
            self._pattern = pattern
            self.analysis_count += 1
        else:
            self.variant.opts = opts
            t0 = time.perf_counter()
            try:
                self.setup = self.variant.numeric(self.analysis, P, A, density, self.setup)
            except Exception:
                self._free()
                raise
        self.setup_ms = 1e3 * (time.perf_counter() - t0)
        self.numeric_count += 1
        self.n = A.shape[0]
        if opts.fallback == "jacobi":
            self.inv_diag = 1.0 / A.diagonal(k=P.getOwnershipRange()[0])

    def apply(self, pc, x, y, transpose=False):
        """y = M x (or D^-1 x under an active Jacobi fallback); ``transpose``: M^T x (:mod:`.keptcolumns`)."""
        if self.setup is None:          # a second KSPSetFromOptions's new context, which PCSetUp skips (see preSolve)
            self.setUp(pc)
        self._ev_apply.begin()
        try:
            size = x.getLocalSize()
            if size != self.n:
                raise ValueError(f"vector has {size} local entries but the HTP preconditioner "
                                 f"was set up for a matrix with {self.n} rows (size mismatch)")
            if self.fallback_active:
                y.array_w[...] = self.inv_diag * x.array_r
            else:
                self.columns.apply(lambda a, b: self.variant.apply(self.setup, a, b), x, y, transpose)
        finally:
            self._ev_apply.end()

    def applyTranspose(self, pc, x, y):
        """M^T x: M, symmetric but where Dirichlet rows keep their columns."""
        self.apply(pc, x, y, transpose=True)

    @unwinding
    def preSolve(self, pc, ksp, b, x):
        """Before each KSPSolve: the variant's start (the deflated form corrects x0); settings a raised solve kept
        are given back first; the context made ready for this solve (:func:`_ready`)."""
        self._changed, self._started = give_back(ksp, self._changed), time.perf_counter()
        check_layout(pc.getOperators()[0], b, x)
        _ready(self, pc, ksp)
        self._changed = self.columns.start(ksp, b, x, self._aij)     # x0 = D^-1 b on such rows: before the variant's
        if not self.fallback_active:
            amat, pmat = pc.getOperators()
            stale = ((self._values is not None and pmat.stateGet() != self._values[1])
                     or amat.handle != pmat.handle       # M made from a Pmat other than the solved Amat
                     or (self.columns.copy is not None and not self.columns.started))   # or A without columns
            # that the KSP's A keeps, where x_D was not set (KSPs outside keptcolumns.STARTED_KSPS)
            started = self.variant.presolve(self.setup, ksp, b, x, stale) or {}
            self._changed = {**started, **(self._changed or {})}       # the flag as the caller had it

    def postSolve(self, pc, ksp, b, x):
        """After each KSPSolve: tell the variant its iterations; give the KSP back the settings its start changed
        (initial-guess flag, divergence tolerance)."""
        if (self.setup is not None and not self.fallback_active and self._started is not None
                and not (ksp.getOptionsPrefix() or "").endswith(ESTIMATE)):      # not Chebyshev's estimate's 10
            self.variant.solved(self.setup, ksp.getIterationNumber(), time.perf_counter() - self._started)
        self._changed, self.columns.started = give_back(ksp, self._changed), False

    def _free(self):
        """Free the analysis and its setups (PETSc objects included)."""
        if self.analysis is not None and self.variant is not None:
            self.variant.destroy(self.analysis)
        self.analysis = self.setup = self._pattern = self._values = None
        for mat in self._retired:
            mat.destroy()
        self._retired = []

    def reset(self, pc):
        """Drop the analysis, the factors, an AIJ copy of the operator and the variant's PREONLY choice (the network
        stays loaded)."""
        self._free()
        self.columns.free()
        if self.variant is not None:
            self.variant.exact_only = None
        if self._aij is not None:
            self._aij.destroy()
            self._aij = None

    def destroy(self, pc):
        """Free everything when PETSc destroys the PC."""
        self.reset(pc)


@contextlib.contextmanager
def _checked_rows(ctx, P, variant):
    """This rank's rows of the AIJ operator ``P`` (the whole matrix on one rank; a copy for the paper's ``variant``)
    checked (:func:`.validation.check_matrix`: a named error on every rank, or none), then (operator, its rows) of
    what the HTPPC context ``ctx`` preconditions: ``P``, or a copy where Dirichlet rows keep their columns
    (:func:`.keptcolumns.kept_columns`), which becomes ``ctx.columns`` where the block succeeds (else it is freed, and
    the previous preconditioner stays as it was)."""
    with local_rows(P, copy=variant == "paper") as A:
        check_matrix(P, A, empty_ok=variant in ("twolevel", "multilevel"))
        columns = kept_columns(P, A, ctx.columns)
        if columns.copy is None:
            with _committed(ctx, columns):
                yield P, A
            return
    with _committed(ctx, columns), local_rows(columns.copy, copy=variant == "paper") as A:
        yield columns.copy, A


@contextlib.contextmanager
def _committed(ctx, columns):
    """``columns`` replaces ``ctx.columns`` (freed) where the block succeeds; a new one is freed where it fails."""
    try:
        yield
    except BaseException:
        if columns is not ctx.columns:
            columns.free()
        raise
    if columns is not ctx.columns:
        ctx.columns.free()
        ctx.columns = columns


def _check(ctx, pc, opts):
    """The setup's own checks on the HTPPC context ``ctx``; switch to Jacobi when asked to."""
    reason = ctx.fallback_reason = ctx.setup.check(opts.probes)
    ctx.fallback_active = bool(reason) and opts.fallback == "jacobi"
    if reason:
        PETSc.Sys.Print(check_message(pc.getOptionsPrefix() or "", reason, ctx.fallback_active), comm=pc.getComm())


def _ready(ctx, pc, ksp):
    """Set the HTPPC context ``ctx`` up where it is set up nowhere yet (a second KSPSetFromOptions makes a new one,
    PETSc skipping PCSetUp), then anew where its variant's ``once`` says that ``ksp`` calls for another choice (a
    PREONLY KSP: PCSetUp ran before, so its first solve makes the choice twice)."""
    if ctx.setup is None:
        ctx.setUp(pc)
    if ctx.variant.once(ksp, pc, ctx.setup):
        ctx._free()
        ctx.setUp(pc)


def _same_array(a, b) -> bool:
    """Both None, or equal arrays."""
    return (a is None and b is None) or (a is not None and b is not None and np.array_equal(a, b))
