"""From a sparse operator to a ready-to-apply HTP preconditioner (no PETSc needed).

    htp = HTP.load()                         # the shipped checkpoint
    pre = htp.setup(A, coords=xy)            # ordering, partition, network, factors
    y = pre.apply(r)                         # y = M r, float64 in and out

Setup comes in two steps, like a sparse direct solver's symbolic and numeric
factorisations: :meth:`HTP.analyse` (ordering, partition, structural features;
once per nonzero pattern and geometry) and :meth:`HTP.numeric` (network and
factors; on every change of values)::

    ana = htp.analyse(A, coords=xy)          # once
    pre = htp.numeric(ana, A, density=rho)   # every frame, new values
"""
from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import torch

from ..training import checkpoint
from . import weights
from ..checks import probe_reason
from .apply import HTPOperator
from .features import InputStructure, input_structure, input_values
from .model import HTPNet
from ..ordering import choose_ordering, permuted_pattern
from .partition import Partition


def resolve_device(device: str = "auto") -> torch.device:
    """'auto' -> cuda when available, else cpu; unknown names raise ValueError."""
    if device == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    if device not in ("cpu", "cuda") and not device.startswith("cuda:"):
        raise ValueError(f"unknown device {device!r}; use cpu, cuda or auto")
    if device.startswith("cuda") and not torch.cuda.is_available():
        raise ValueError(f"device {device!r} requested but CUDA is not available")
    return torch.device(device)


BARE = ["WARNING: no coordinates attached: the network, trained on cells with their coordinates, reads none and "
        "may take more iterations than no preconditioner (a 2-D Laplacian of 4 096 rows: 267 against 198); attach "
        "them (petsc_htp.attach) or use -htp_variant twolevel"]


@dataclass
class Analysis:
    """The per-pattern half of an HTP setup: ordering, partition and structural features.

    Attributes
    ----------
    perm : numpy.ndarray
        ``A[perm][:, perm]`` is the operator HTP works on.
    ordering : str
        The ordering's name.
    part : Partition
        The partition for N.
    structure : InputStructure
        Pattern and geometry features.
    indptr, indices : numpy.ndarray
        The analysed pattern in the caller's order.
    data_map : numpy.ndarray
        Permuted values are ``A.data[data_map]``.
    permuted_indptr : numpy.ndarray
        Row pointers of the permuted pattern.
    analysis_ms : float
        Wall time of the analysis.
    bare : bool
        No coordinates came with the matrix.
    """

    perm: np.ndarray
    ordering: str
    part: Partition
    structure: InputStructure
    indptr: np.ndarray
    indices: np.ndarray
    data_map: np.ndarray
    permuted_indptr: np.ndarray
    analysis_ms: float
    bare: bool = False

    @property
    def n(self) -> int:
        """Problem size N."""
        return self.part.n

    def same_pattern(self, A) -> bool:
        """True when CSR ``A`` has exactly the analysed nonzero pattern."""
        return (A.shape == (self.n, self.n) and np.array_equal(A.indptr, self.indptr)
                and np.array_equal(A.indices, self.indices))

    def permuted(self, A) -> sp.csr_matrix:
        """``A[perm][:, perm]`` for a matrix with the analysed pattern (a gather of its values)."""
        if not self.same_pattern(A):
            raise ValueError(f"the operator's nonzero pattern (N={A.shape[0]}, {A.nnz} entries) differs from "
                             f"the analysed one (N={self.n}, {self.indices.size} entries); analyse it again")
        return sp.csr_matrix((A.data[self.data_map], self.structure.cols, self.permuted_indptr), shape=A.shape)


@dataclass
class Setup:
    """An HTP preconditioner bound to one operator (the numeric half of a setup)."""

    op: HTPOperator
    analysis: Analysis
    setup_ms: float
    shift: float
    guard_shift: float = 0.0

    @property
    def n(self) -> int:
        """Problem size N."""
        return self.op.part.n

    @property
    def perm(self) -> np.ndarray:
        """The analysis' permutation."""
        return self.analysis.perm

    @property
    def ordering(self) -> str:
        """The analysis' ordering name."""
        return self.analysis.ordering

    @property
    def nbytes(self) -> int:
        """Bytes held by the factors."""
        return self.op.nbytes

    def describe(self) -> list:
        """Short lines for ``-ksp_view``: partition, memory, ordering, guard, times."""
        part = self.op.part
        return [f"operator: N={part.n}, L={part.leaf}, K={part.n_leaves} leaves, M_H={part.n_tiles} tiles; "
                f"factor memory {self.op.nbytes / 2**20:.2f} MB ({self.op.nbytes / part.n:.0f} bytes per unknown)",
                f"ordering: {self.ordering}; shift: {self.shift:g}; SPD guard shift added: "
                f"{self.guard_shift:.3g} * D^-1",
                "apply: float32 (M is linear only to about 1e-7: use CG or FGMRES, not plain GMRES, "
                "below rtol 1e-6)",
                f"setup: analysis {self.analysis.analysis_ms:.1f} ms (once per pattern), "
                f"numeric {self.setup_ms:.1f} ms (network, factors, guard)"] + BARE * self.analysis.bare

    def check(self, probes: int) -> str:
        """Empty when M looks usable, else the reason: non-finite factors or apply, or M indefinite."""
        if not self.factors_finite():
            return "HTP factors are not finite (NaN/Inf)"
        return probe_reason(self.apply, self.n, probes, "HTP")

    def apply(self, r: np.ndarray) -> np.ndarray:
        """Return M r in the caller's ordering (float64)."""
        y = np.empty(self.n)
        y[self.perm] = self.op.apply(np.asarray(r, dtype=np.float64)[self.perm])
        return y

    def factors_finite(self) -> bool:
        """True when every packed factor is finite."""
        return bool(torch.isfinite(self.op.packed).all())

    def min_scaled_eigenvalue(self, diag: np.ndarray, seed: int = 0) -> float:
        """Smallest eigenvalue of D^1/2 M D^1/2 to 1 % by Lanczos on M's device (20 to 100 applies)."""
        op, n = self.op, self.n
        sd = torch.as_tensor(np.sqrt(diag), dtype=op.r.dtype, device=op.r.device)

        def scaled(v):
            op.r[:n, 0] = sd * v
            return sd * op.apply_()[:n, 0]

        return smallest_ritz_value(scaled, n, seed=seed, dtype=op.r.dtype, device=op.r.device)

def smallest_ritz_value(matvec, n: int, max_steps: int = 100, rtol: float = 1e-2, seed: int = 0,
                        dtype=torch.float64, device="cpu") -> float:
    """Smallest eigenvalue of a symmetric operator by Lanczos with full reorthogonalisation.

    Runs on the operator's device; the host sees only the tridiagonal coefficients, every
    10 steps from step 20, where it stops once the smallest Ritz value's residual bound
    ``beta_j |s_j|`` is below ``rtol`` times its magnitude. Ritz values lie inside the spectrum.

    Parameters
    ----------
    matvec : callable
        ``v -> A v`` for torch vectors of length ``n`` (``dtype`` on ``device``).
    n : int
        Operator size.
    max_steps : int
        Step limit (capped at ``n``).
    rtol : float
        Relative accuracy of the returned value.
    seed : int
        Seed of the random start vector.
    dtype, device
        Where the Lanczos vectors live.
    """
    steps = min(max_steps, n)
    V = torch.zeros(steps + 1, n, dtype=dtype, device=device)
    alpha = torch.zeros(steps, dtype=dtype, device=device)
    beta = torch.zeros_like(alpha)
    v = torch.as_tensor(np.random.default_rng(seed).standard_normal(n), dtype=dtype, device=device)
    V[0] = v / torch.linalg.vector_norm(v)
    for j in range(steps):
        w = matvec(V[j])
        alpha[j] = V[j] @ w
        for _ in range(2):                                  # twice is enough (Kahan)
            w = w - V[:j + 1].T @ (V[:j + 1] @ w)
        beta[j] = torch.linalg.vector_norm(w)
        V[j + 1] = w / beta[j]
        k = j + 1
        if k == steps or (k >= 20 and k % 10 == 0):
            a, b = alpha[:k].double().cpu().numpy(), beta[:k].double().cpu().numpy()
            tiny = np.flatnonzero(~(b > 1e-6 * np.nanmax(np.abs(a))))
            if tiny.size:                                   # invariant subspace: T is exact there
                m = tiny[0] + 1
                return float(_tridiagonal_eig(a[:m], b[:m - 1])[0][0])
            theta, s_ = _tridiagonal_eig(a, b[:-1])
            if k == steps or b[-1] * abs(s_[-1, 0]) <= rtol * abs(theta[0]):
                return float(theta[0])
    raise AssertionError("unreachable")


def _tridiagonal_eig(alpha, beta):
    return np.linalg.eigh(np.diag(alpha) + np.diag(beta, 1) + np.diag(beta, -1))


class HTP:
    """A loaded HTP network ready to build preconditioners for any N."""

    def __init__(self, net: HTPNet, provenance: dict | None = None, device="auto", threads: int | None = None):
        self.device = resolve_device(device)
        if threads:
            torch.set_num_threads(int(threads))
        self.net = net.to(self.device).eval()
        self.provenance = provenance or {}

    @classmethod
    def load(cls, path=None, device="auto", threads=None) -> "HTP":
        """Load a checkpoint (the shipped one when ``path`` is None)."""
        net, prov = weights.load(path)
        return cls(net, prov, device, threads)

    @classmethod
    def cached(cls, path=None, device="auto") -> "HTP":
        """Load ``path`` on ``device`` once per process (until the file changes); shared by callers."""
        device = str(resolve_device(device))
        return checkpoint.cached(path, checkpoint.DEFAULT, lambda p: cls.load(p, device=device), device)

    def analyse(self, A, coords=None, ordering="auto") -> Analysis:
        """The per-pattern step: ordering, partition and structural features of ``A``.

        Parameters
        ----------
        A : scipy sparse (N, N)
            Only its nonzero pattern is used.
        coords : optional (N, 2) per-row coordinates (caller's ordering)
        ordering : auto, morton, rcm or natural
        """
        t0 = time.perf_counter()
        A = sp.csr_matrix(A)
        A.sum_duplicates()
        perm, name = choose_ordering(A, coords, ordering)
        Ap, data_map = permuted_pattern(A, perm)
        part = self.net.cfg.partition(A.shape[0])
        st = input_structure(Ap, part, None if coords is None else np.asarray(coords)[perm])
        return Analysis(perm, name, part, st, A.indptr.copy(), A.indices.copy(), data_map, Ap.indptr,
                        1e3 * (time.perf_counter() - t0), coords is None)

    @torch.no_grad()
    def numeric(self, analysis: Analysis, A, density=None, shift: float = 0.0, spd_guard: bool = True,
                into: Setup | None = None) -> Setup:
        """The per-values step: run the network on ``A``'s values and bind the factors.

        Parameters
        ----------
        analysis : Analysis
            From :meth:`analyse` on ``A``'s pattern.
        A : scipy sparse (N, N)
            The operator (same pattern as analysed).
        density : optional (N,) per-row density (caller's ordering)
        shift : extra diagonal term ``shift * D^-1`` added to M (SPD safety margin)
        spd_guard : estimate the most negative eigenvalue of D^1/2 M D^1/2 by Lanczos and, when
            it is negative, add ``1.2 |lambda_min| D^-1`` so that M is SPD (``Setup.guard_shift``)
        into : Setup, optional
            A previous setup of this analysis whose buffers are reused (its factors are replaced).
        """
        t0 = time.perf_counter()
        A = sp.csr_matrix(A)
        A.sum_duplicates()
        Ap = analysis.permuted(A)
        part = analysis.part
        inp = input_values(analysis.structure, Ap,
                           None if density is None else np.asarray(density)[analysis.perm]).to(self.device)
        packed = self.net(inp, part)
        if shift:
            packed[-part.n_pad:] += shift * inp.inv_diag
        if into is not None and into.analysis is analysis:
            into.op.load_(packed)
            pre, into.shift, into.guard_shift = into, shift, 0.0
        else:
            pre = Setup(HTPOperator(packed, part), analysis, 0.0, shift)
        if spd_guard and part.n > 1 and pre.factors_finite():
            lam = pre.min_scaled_eigenvalue(Ap.diagonal())
            if lam < 0:
                pre.guard_shift = 1.2 * -lam
                pre.op.f.g.add_(pre.guard_shift * inp.inv_diag)
        if self.device.type == "cuda":
            torch.cuda.synchronize()
        pre.setup_ms = 1e3 * (time.perf_counter() - t0)
        return pre

    def setup(self, A, coords=None, density=None, ordering="auto", shift: float = 0.0,
              spd_guard: bool = True) -> Setup:
        """Both steps at once: :meth:`analyse` then :meth:`numeric` (see them for the parameters)."""
        return self.numeric(self.analyse(A, coords, ordering), A, density, shift, spd_guard)
