"""PETSc integration: HTP as a ``PCPYTHON`` preconditioner.

Use it from the command line of any petsc4py program::

    -ksp_type cg -ksp_norm_type unpreconditioned \\
    -pc_type python -pc_python_type petsc_htp.HTPPC [-htp_checkpoint model.pt ...]

or in code::

    pc = ksp.getPC()
    pc.setType("python")
    pc.setPythonContext(petsc_htp.HTPPC())

Under MPI, wrap it in block Jacobi so that every rank preconditions its own
diagonal block (a SeqAIJ matrix on ``COMM_SELF``)::

    -pc_type bjacobi -sub_pc_type python -sub_pc_python_type petsc_htp.HTPPC

(the options are then read with the ``sub_`` prefix, e.g. ``-sub_htp_checkpoint``).

Like Firedrake's preconditioners, :class:`HTPPC` is configured only through its
options prefix, ``pc.getOptionsPrefix() + "htp_"``:

=====================  ============  =======================================================
option                 default       meaning
=====================  ============  =======================================================
``-htp_checkpoint``    shipped       HTP checkpoint file (``petsc_htp/checkpoints/htp_default.pt``)
``-htp_device``        auto          cpu, cuda[:k] or auto (cuda when available)
``-htp_ordering``      auto          auto, morton, rcm, natural (auto: Morton with coordinates,
                                     RCM without, the given order when it already is Morton)
``-htp_shift``         0             add ``shift * D^-1`` to M (SPD safety margin)
``-htp_spd_guard``     true          estimate lambda_min(D^1/2 M D^1/2) by Lanczos at setup and,
                                     when negative, add ``1.2 |lambda_min| D^-1`` (M becomes SPD)
``-htp_threads``       1             torch CPU threads per rank (PETSc parallelism is MPI;
                                     raise it for large N on otherwise idle cores)
``-htp_fallback``      none          none or jacobi: use ``D^-1`` when the factors are not
                                     finite or the Rayleigh probe proves M indefinite
``-htp_probe``         4             random Rayleigh-quotient probes of M at setup (0: none)
=====================  ============  =======================================================

The options are read in ``setFromOptions`` and again in ``setUp`` (a PCPYTHON
context may be set up without ``setFromOptions`` ever running). ``-help`` lists
them. Geometry can be supplied with :func:`attach`; without it the features
come from the matrix alone and the ordering is RCM.

``setUp`` runs the network only when the operator changed (PETSc object state
and id of the preconditioning matrix, the attached arrays and the options);
the loaded network is kept across setups and shared between contexts that
use the same checkpoint file and device. ``PETSc.Log`` events ``HTPSetup``
and ``HTPApply`` appear in ``-log_view``.
"""
from __future__ import annotations

import itertools
import math
import os
from pathlib import Path

import numpy as np
import scipy.sparse as sp
from petsc4py import PETSc

from . import checkpoint as _checkpoint
from .inference import HTP, resolve_device
from .ordering import METHODS as _ORDERINGS

__all__ = ["HTPPC", "attach", "OPTIONS"]

COORDS_ATTR = "petsc_htp_coords"
DENSITY_ATTR = "petsc_htp_density"
VERSION_ATTR = "petsc_htp_attached"     # bumped by every attach(), part of the setup cache key
FALLBACKS = ("none", "jacobi")

# name, kind, default, one-line description (shown by -help)
OPTIONS = (
    ("checkpoint", "string", "", "HTP checkpoint file (empty: the shipped petsc_htp/checkpoints/htp_default.pt)"),
    ("device", "string", "auto", "torch device for the network and the apply: cpu, cuda[:k] or auto"),
    ("ordering", "string", "auto", "row ordering: auto (Morton with coordinates, else RCM), morton, rcm or natural"),
    ("shift", "real", 0.0, "add shift * D^-1 to M (SPD safety margin)"),
    ("spd_guard", "bool", True, "Lanczos estimate of lambda_min(D^1/2 M D^1/2) at setup; if < 0, shift M to SPD"),
    ("threads", "int", 1, "torch CPU threads per rank (PETSc parallelism is MPI)"),
    ("fallback", "string", "none", "none or jacobi: apply D^-1 when the factors are non-finite or M is indefinite"),
    ("probe", "int", 4, "random Rayleigh-quotient probes of M at setup (0: skip the check)"),
)

_EVENTS = {}
_ATTACHED = itertools.count(1)
_NETS = {}          # (checkpoint path, mtime, size, device) -> HTP, shared between contexts


def _event(name: str) -> PETSc.Log.Event:
    """The PETSc log event ``name`` (registered once per process)."""
    if name not in _EVENTS:
        _EVENTS[name] = PETSc.Log.Event(name)
    return _EVENTS[name]


# ------------------------------------------------------------------ attach

def _local_rows(mat, values, what, width):
    """Rows of ``values`` owned by this rank of ``mat`` (given global or local arrays)."""
    arr = np.ascontiguousarray(values, dtype=np.float64)
    n_global = mat.getSize()[0]
    start, end = mat.getOwnershipRange()
    shape_tail = () if width is None else (width,)
    if arr.shape == (n_global, *shape_tail):
        return arr[start:end].copy()
    if arr.shape == (end - start, *shape_tail):
        return arr.copy()
    raise ValueError(f"{what} must have shape ({n_global}{', %d' % width if width else ''}) (global) or "
                     f"({end - start}{', %d' % width if width else ''}) (this rank's rows), got {arr.shape}")


def attach(mat, coords=None, density=None):
    """Store per-row geometry on a PETSc Mat for :class:`HTPPC`.

    Parameters
    ----------
    mat : petsc4py.PETSc.Mat
        The preconditioning matrix (sequential or distributed AIJ).
    coords : array_like, shape (N, 2) or (n_local, 2), optional
        Point coordinates of the rows (global array, or this rank's rows).
        With coordinates HTP uses the Morton ordering (or keeps rows already in
        Morton order) and geometric features.
    density : array_like, shape (N,) or (n_local,), optional
        Per-row density (material coefficient) feature.

    The arrays are kept with ``Mat.setAttr`` in the PETSc object's own Python
    dictionary, so they survive new Python wrappers of the same Mat (e.g. the
    one ``pc.getOperators()`` returns). For a parallel matrix this rank's rows
    are also attached to its diagonal block (``Mat.getDiagonalBlock``), which
    is the matrix PETSc's one-block-per-rank block Jacobi hands to a
    ``-sub_pc_type python -sub_pc_python_type petsc_htp.HTPPC``. Sub-matrices
    that PETSc extracts itself (several blocks per rank) carry nothing, and HTP
    falls back to matrix-only features and RCM there. Passing ``None`` removes
    a previously attached array. The Mat's object state is increased, so a KSP
    that was already set up runs HTP's setup again at its next solve. Call it
    on every rank of a parallel matrix. Returns ``mat``.
    """
    local = {}
    for attr, values, what, width in ((COORDS_ATTR, coords, "coords", 2), (DENSITY_ATTR, density, "density", None)):
        local[attr] = None if values is None else _local_rows(mat, values, what, width)
        if local[attr] is not None and not np.all(np.isfinite(local[attr])):
            raise ValueError(f"{what} must be finite")
    targets = [mat]
    if mat.getComm().getSize() > 1:
        try:
            targets.append(mat.getDiagonalBlock())
        except PETSc.Error:
            pass
    version = next(_ATTACHED)
    for target in targets:
        for attr, arr in local.items():
            target.setAttr(attr, arr)
        target.setAttr(VERSION_ATTR, version)
        target.stateIncrease()          # PETSc then sets up the preconditioner again
    return mat


def _attached(mat):
    """(coords, density) stored by :func:`attach` on ``mat``, each possibly None."""
    return mat.getAttr(COORDS_ATTR), mat.getAttr(DENSITY_ATTR)


# -------------------------------------------------------------------- helpers

def _read_csr(mat) -> sp.csr_matrix:
    """This (sequential) matrix as a scipy CSR matrix."""
    if mat.getComm().getSize() > 1:
        raise ValueError(
            f"HTPPC needs a sequential matrix but got a parallel '{mat.getType()}' matrix on "
            f"{mat.getComm().getSize()} ranks; precondition each rank's block with "
            "-pc_type bjacobi -sub_pc_type python -sub_pc_python_type petsc_htp.HTPPC")
    rows, cols = mat.getSize()
    if rows != cols:
        raise ValueError(f"HTPPC needs a square matrix, got {rows} x {cols} (non-square)")
    if rows == 0:
        raise ValueError("HTPPC got an empty matrix (0 x 0)")
    src = mat
    if mat.getType() not in ("seqaij", "mpiaij"):
        try:
            src = mat.convert("seqaij")
        except PETSc.Error as exc:
            raise ValueError(f"HTPPC needs an assembled AIJ matrix; cannot convert a "
                             f"'{mat.getType()}' matrix to seqaij") from exc
    indptr, indices, data = src.getValuesCSR()
    A = sp.csr_matrix((np.asarray(data, dtype=np.float64).copy(), np.asarray(indices).copy(),
                       np.asarray(indptr).copy()), shape=(rows, cols))
    if A.nnz == 0:
        raise ValueError(f"HTPPC got an empty matrix ({rows} x {cols} with no nonzeros)")
    bad = int(np.count_nonzero(~np.isfinite(A.data)))
    if bad:
        raise ValueError(f"matrix contains {bad} NaN or Inf entries; HTPPC needs a finite SPD matrix")
    return A


def _checkpoint_path(text: str) -> Path:
    return Path(text).expanduser().resolve() if text else _checkpoint.DEFAULT


def _load_network(path: Path, device: str, threads: int) -> HTP:
    """Load (or reuse) the network of ``path`` on ``device``."""
    try:
        st = os.stat(path)
    except OSError:
        raise _checkpoint.CheckpointError(f"checkpoint {path} does not exist or cannot be read") from None
    dev = str(resolve_device(device))
    key = (str(path), st.st_mtime_ns, st.st_size, dev)
    net = _NETS.get(key)
    if net is None:
        net = HTP.load(path, device=dev, threads=threads or None)
        if len(_NETS) >= 8:
            _NETS.pop(next(iter(_NETS)))
        _NETS[key] = net
    elif threads:
        import torch
        torch.set_num_threads(int(threads))
    return net


# ----------------------------------------------------------------------- PC

class HTPPC:
    """petsc4py ``PCPYTHON`` context applying the learned HTP preconditioner.

    Constructed without arguments (``-pc_python_type petsc_htp.HTPPC``);
    configured through ``<prefix>htp_*`` options (see the module docstring).

    Attributes
    ----------
    setup_count : int
        Number of times the network was run (new operator, values or options).
    setup : petsc_htp.inference.Setup or None
        The current preconditioner.
    setup_ms : float
        Wall time of the last network setup (inference), in ms.
    fallback_active : bool
        True while ``-htp_fallback jacobi`` replaced M by ``D^-1``.
    """

    def __init__(self):
        self.opts = {name: default for name, _, default, _ in OPTIONS}
        self.htp = None
        self.setup = None
        self.setup_count = 0
        self.setup_ms = float("nan")
        self.fallback_active = False
        self.fallback_reason = ""
        self.probe_min = None
        self.finite = None
        self.n = None
        self.inv_diag = None
        self.checkpoint = None
        self._key = None
        self._help_shown = False
        self._ev_setup = _event("HTPSetup")
        self._ev_apply = _event("HTPApply")

    # ---------------------------------------------------------- options
    @staticmethod
    def _prefix(pc) -> str:
        return (pc.getOptionsPrefix() or "") + "htp_"

    def _read_options(self, pc) -> dict:
        """Read and validate the ``<prefix>htp_*`` options."""
        db = PETSc.Options(self._prefix(pc))
        get = {"string": db.getString, "real": db.getReal, "int": db.getInt, "bool": db.getBool}
        out = {}
        for name, kind, default, _ in OPTIONS:
            out[name] = get[kind](name, default)
        opt = "-" + self._prefix(pc)
        if out["ordering"] not in _ORDERINGS:
            raise ValueError(f"{opt}ordering {out['ordering']!r} unknown; use one of {', '.join(_ORDERINGS)}")
        if out["fallback"] not in FALLBACKS:
            raise ValueError(f"{opt}fallback {out['fallback']!r} unknown; use none or jacobi")
        if out["device"] not in ("auto", "cpu", "cuda") and not out["device"].startswith("cuda:"):
            raise ValueError(f"{opt}device {out['device']!r} unknown; use cpu, cuda or auto")
        if not math.isfinite(out["shift"]) or out["shift"] < 0:
            raise ValueError(f"{opt}shift must be a finite non-negative number, got {out['shift']}")
        if out["threads"] < 1:
            raise ValueError(f"{opt}threads must be >= 1, got {out['threads']}")
        if out["probe"] < 0:
            raise ValueError(f"{opt}probe must be >= 0, got {out['probe']}")
        self.opts = out
        return out

    def _print_help(self, pc):
        opt = "-" + self._prefix(pc)
        lines = [f"HTPPC options (learned Hierarchical Transformer Preconditioner, prefix {opt}) -----"]
        for name, kind, default, text in OPTIONS:
            now = self.opts.get(name, default)
            shown = default if default != "" else str(_checkpoint.DEFAULT)
            now = now if now != "" else str(_checkpoint.DEFAULT)
            lines.append(f"  {opt}{name} <{kind}> <now {now} : formerly {shown}>: {text} (HTPPC)")
        PETSc.Sys.Print("\n".join(lines), comm=pc.getComm())

    def setFromOptions(self, pc):
        """Read the options; with ``-help`` print them with their defaults."""
        self._read_options(pc)
        if not self._help_shown and PETSc.Options().hasName("help"):
            self._help_shown = True
            self._print_help(pc)

    # ------------------------------------------------------------ setup
    def setUp(self, pc):
        """Run the network for the current preconditioning matrix (only when it changed)."""
        opts = self._read_options(pc)
        P = pc.getOperators()[1]
        coords, density = _attached(P)
        ckpt = _checkpoint_path(opts["checkpoint"])
        key = (P.getId(), P.stateGet(), P.getAttr(VERSION_ATTR), str(ckpt),
               opts["device"], opts["ordering"], opts["shift"], opts["spd_guard"], opts["fallback"], opts["probe"])
        if key == self._key and self.setup is not None:
            return
        self._ev_setup.begin()
        try:
            self._key = None
            A = _read_csr(P)
            self.htp = _load_network(ckpt, opts["device"], opts["threads"])
            self.checkpoint = ckpt
            setup = self.htp.setup(A, coords=coords, density=density,
                                   ordering=opts["ordering"], shift=opts["shift"], spd_guard=opts["spd_guard"])
            self.setup = setup
            self.setup_ms = setup.setup_ms
            self.setup_count += 1
            self.n = A.shape[0]
            self.inv_diag = 1.0 / A.diagonal()
            self._check(pc, opts)
            self._key = key
        finally:
            self._ev_setup.end()

    def _check(self, pc, opts):
        """Finite factors and Rayleigh probe; switch to Jacobi when asked to."""
        self.finite = self.setup.factors_finite()
        self.probe_min = None
        reason = ""
        if not self.finite:
            reason = "HTP factors are not finite (NaN/Inf)"
        elif opts["probe"]:
            self.probe_min = self.setup.min_rayleigh(probes=opts["probe"])
            if not math.isfinite(self.probe_min):
                reason = "HTP apply is not finite"
            elif self.probe_min <= 0:
                reason = f"Rayleigh probe found M indefinite (min r^T M r / r^T r = {self.probe_min:.3e})"
        self.fallback_reason = reason
        self.fallback_active = bool(reason) and opts["fallback"] == "jacobi"
        name = pc.getOptionsPrefix() or ""
        if self.fallback_active:
            PETSc.Sys.Print(f"HTPPC{' (' + name + ')' if name else ''}: {reason}; "
                            f"-{self._prefix(pc)}fallback jacobi: applying Jacobi (D^-1) instead", comm=pc.getComm())
        elif reason:
            PETSc.Sys.Print(f"HTPPC{' (' + name + ')' if name else ''}: WARNING: {reason}; "
                            f"Krylov methods will break down (use -{self._prefix(pc)}fallback jacobi)", comm=pc.getComm())

    # ------------------------------------------------------------ apply
    def apply(self, pc, x, y):
        """y = M x (or D^-1 x under an active Jacobi fallback)."""
        self._ev_apply.begin()
        try:
            if self.setup is None:
                raise RuntimeError("HTPPC.apply called before setUp")
            r = x.array_r
            if r.shape[0] != self.n:
                raise ValueError(f"vector has {r.shape[0]} local entries but the HTP preconditioner "
                                 f"was set up for a matrix with {self.n} rows (size mismatch)")
            if self.fallback_active:
                y.array_w[...] = self.inv_diag * r
            else:
                y.array_w[...] = self.setup.apply(r)
        finally:
            self._ev_apply.end()

    def applyTranspose(self, pc, x, y):
        """M is symmetric: same as :meth:`apply`."""
        self.apply(pc, x, y)

    # ------------------------------------------------------------- view
    def view(self, pc, viewer):
        """ASCII description: model, checkpoint, partition, memory, ordering, device, timing, fallback."""
        if viewer.getType() != PETSc.Viewer.Type.ASCII:
            return
        out = []
        opts = self.opts
        if self.htp is None:
            out.append("HTP (learned Hierarchical Transformer Preconditioner): not set up yet")
            out.append(f"  checkpoint: {_checkpoint_path(opts['checkpoint'])}")
        else:
            cfg = self.htp.net.cfg
            out.append("HTP (learned Hierarchical Transformer Preconditioner)")
            out.append(f"  model: d={cfg.d}, n_l={cfg.n_layers}, L={cfg.leaf}, L_s={cfg.coarse}, "
                       f"heads={cfg.heads}, highways={'yes' if cfg.highways else 'no'}; "
                       f"{self.htp.net.n_params()} parameters")
            out.append(f"  checkpoint: {self.checkpoint}")
        if self.setup is not None:
            part = self.setup.op.part
            out.append(f"  operator: N={part.n}, L={part.leaf}, K={part.n_leaves} leaves, "
                       f"M_H={part.n_tiles} tiles; factor memory {self.setup.op.nbytes / 2**20:.2f} MB")
            import torch
            out.append(f"  SPD guard: {'on' if opts['spd_guard'] else 'off'}; guard shift added: "
                       f"{self.setup.guard_shift:.3g} * D^-1")
            out.append(f"  ordering: {self.setup.ordering}; device: {self.htp.device}; shift: {opts['shift']:g}; "
                       f"torch threads: {torch.get_num_threads()}")
            out.append(f"  last setup (inference): {self.setup_ms:.1f} ms; setups: {self.setup_count}")
            probe = ("not run" if self.probe_min is None
                     else f"min r^T M r / r^T r = {self.probe_min:.3e} over {opts['probe']} vectors")
            out.append(f"  checks: factors {'finite' if self.finite else 'NOT FINITE'}; Rayleigh probe {probe}")
            if self.fallback_active:
                out.append(f"  fallback: jacobi ACTIVE ({self.fallback_reason}); applying D^-1")
            elif self.fallback_reason:
                out.append(f"  fallback: {opts['fallback']}; WARNING: {self.fallback_reason}")
            else:
                out.append(f"  fallback: {opts['fallback']} (not needed; applying HTP)")
        viewer.printfASCII("".join(f"  {line}\n" for line in out))

    def reset(self, pc):
        """Drop the factors (the network stays loaded)."""
        self.setup = None
        self._key = None
