"""The fast-path preconditioners (none, jacobi, bjacobi, htp), their factory and apply microbenchmark."""
from __future__ import annotations

import time

import numpy as np
import scipy.sparse as sp
import torch

from ..pcoptions import HTPOptions
from ..twolevel.sizing import LEAF
from .timing import capture, device_of, sync, timed

METHODS = ("none", "jacobi", "bjacobi", "htp", "twolevel_const", "twolevel_eig", "twolevel_learned")
# (leaf size, coarse vectors per leaf) of the two-level coarse spaces: options/cg_twolevel_const.opts, HTPPC's
# defaults (options/cg_htp.opts) and options/cg_twolevel_learned.opts (the network's rank)
SETTINGS = {"const": (16, 1), "eig": (LEAF[2], HTPOptions.coarse_rank), "learned": (128, None)}


def constant_null(A) -> bool:
    """True when A's row sums vanish (the two-level method's rule): constants span a null space."""
    from ..twolevel.nullspace import null_regions

    return bool(null_regions(A, np.zeros(A.shape[0], dtype=np.int64)).all())


class Preconditioner:
    """Identity preconditioner and the protocol every method follows.

    ``setup`` computes (or recomputes in place, for a new operator of the same
    N) the device data; ``apply_(r, z)`` writes ``z = M r`` into the float32
    length-N buffer ``z`` with device ops only. ``perm`` (None = identity) is
    the ordering the solver must run in.
    """


    def __init__(self, A, coords=None, density=None, device="auto"):
        self.A, self.coords, self.density = sp.csr_matrix(A), coords, density
        self.n = self.A.shape[0]
        self.device = device_of(device)
        self.perm = None
        self.setup_ms = None

    def setup(self, A=None, coords=None, density=None) -> float:
        """(Re)compute for ``A`` (default: the bound operator); return and store the milliseconds."""
        if A is not None:
            if A.shape != (self.n, self.n):
                raise ValueError(f"operator has shape {A.shape}; this preconditioner was built for N={self.n}")
            self.A, self.coords, self.density = sp.csr_matrix(A), coords, density
        t0 = time.perf_counter()
        self._setup()
        sync(self.device)
        self.setup_ms = 1e3 * (time.perf_counter() - t0)
        return self.setup_ms

    def _setup(self):
        pass

    def apply_(self, r: torch.Tensor, z: torch.Tensor):
        """z = M r in place."""
        z.copy_(r)


class Jacobi(Preconditioner):
    """z = D^-1 r."""

    inv_diag = None

    def _setup(self):
        inv = torch.from_numpy(1.0 / self.A.diagonal()).to(self.device, torch.float32)
        if self.inv_diag is None:
            self.inv_diag = inv
        else:
            self.inv_diag.copy_(inv)

    def apply_(self, r, z):
        torch.mul(r, self.inv_diag, out=z)


class BlockJacobi(Preconditioner):
    """Exact inverses of A's contiguous ``block`` x ``block`` diagonal blocks, one batched GEMM per apply.

    The last block is padded with the identity; one batched float64 Cholesky
    gives the inverses, stored in float32. A singular whole-matrix block
    (N <= block, A 1 = 0) gets the rank-one term max(diag) 11^T / N, so its
    inverse is exact on mean-zero vectors.
    """

    block = 128
    inv = None

    def _setup(self):
        b, n = self.block, self.n
        nb = -(-n // b)
        coo = self.A.tocoo()
        keep = coo.row // b == coo.col // b
        dense = np.zeros((nb, b, b))
        np.add.at(dense, (coo.row[keep] // b, coo.row[keep] % b, coo.col[keep] % b), coo.data[keep])
        pad = np.arange(n, nb * b)
        dense[pad // b, pad % b, pad % b] = 1.0
        blocks = torch.from_numpy(dense).to(self.device)
        if n <= b and constant_null(self.A):  # one singular block: invert A + max(diag) 11^T / n
            blocks[0, :n, :n] += self.A.diagonal().max() / n
        inv = torch.cholesky_inverse(torch.linalg.cholesky(blocks)).float()
        if self.inv is None:
            self.inv = inv
            self.rp = torch.zeros(nb * b, device=self.device)
            self.zp = torch.zeros_like(self.rp)
        else:
            self.inv.copy_(inv)

    def apply_(self, r, z):
        nb, b = self.inv.shape[:2]
        self.rp[:self.n].copy_(r)
        torch.bmm(self.inv, self.rp.view(nb, b, 1), out=self.zp.view(nb, b, 1))
        z.copy_(self.zp[:self.n])


class HTPPreconditioner(Preconditioner):
    """The learned preconditioner: ``htp.analyse`` once, ``htp.numeric`` per operator, on fixed buffers.

    The solver runs in the HTP ordering ``perm``; a new operator's factors land
    in the first operator's buffers so a captured graph stays valid. A new
    pattern or new coordinates get a new analysis.
    """

    op = None
    analysis = None
    _coords = None

    def __init__(self, A, htp, coords=None, density=None, device="auto"):
        super().__init__(A, coords, density, device)
        if device_of(htp.device) != self.device:
            raise ValueError(f"the HTP network lives on {htp.device}, not on {self.device}")
        self.htp = htp
        self.last = None

    def _setup(self):
        same_xy = (self.coords is None) == (self._coords is None) and (
            self.coords is None or np.array_equal(self.coords, self._coords))
        if self.analysis is None or not same_xy or not self.analysis.same_pattern(self.A):
            self.analysis, self.last = self.htp.analyse(self.A, self.coords), None
            self._coords = None if self.coords is None else np.array(self.coords)
        self.last = self.htp.numeric(self.analysis, self.A, self.density, into=self.last)
        if self.op is None:
            self.op = self.last.op
        elif self.last.op is not self.op:
            self.op.load_(self.last.op.packed)
        self.perm = self.last.perm

    def apply_(self, r, z):
        self.op.r[:self.n, 0].copy_(r)
        self.op.apply_()
        z.copy_(self.op.y[:self.n, 0])


class TwoLevelPreconditioner(Preconditioner):
    """The two-level variant (:mod:`petsc_htp.twolevel.batched`): analysis once, factor per operator, float64 inside.

    The solver runs in the leaves' ordering ``perm``; the float32 solver vectors are widened for
    the float64 apply, whose buffers stay fixed so a captured graph stays valid. The leaf size and rank
    of each coarse space are those of HTPPC's options files (:data:`SETTINGS`).
    """

    def __init__(self, A, coarse="eig", rank=None, coords=None, density=None, device="auto"):
        from ..twolevel.batched import analyse
        from ..twolevel.leaves import choose_leaves

        super().__init__(A, coords, density, device)
        leaf, default_rank = SETTINGS[coarse]
        self.coarse, self.rank = coarse, rank or default_rank
        self.analysis = analyse(self.A, choose_leaves(self.A, coords, leaf=leaf), self.device)
        self.perm = self.analysis.leaves.perm
        self.op = None
        self.r64 = torch.zeros(self.n, dtype=torch.float64, device=self.device)
        self.z64 = torch.zeros_like(self.r64)

    def _setup(self):
        from ..twolevel.batched import factor

        if self.coarse == "learned":                   # the network's vectors, refined as in HTPPC
            from ..twolevel.coarsenet import cached, learned_vectors

            basis = learned_vectors(cached()[0], self.analysis, self.A, self.coords, self.density)
            new = factor(self.analysis, self.A, "seeded", basis=basis)
        else:
            new = factor(self.analysis, self.A, self.coarse, self.rank)
        if self.op is None:
            self.op = new
        else:
            self.op.load_(new)

    def apply_(self, r, z):
        self.r64.copy_(r)
        self.op.apply_(self.r64, self.z64)
        z.copy_(self.z64)


def make_preconditioner(method, A, htp=None, coords=None, density=None, device="auto") -> Preconditioner:
    """Build (without setting up) preconditioner ``method`` (one of :data:`METHODS`) for ``A``."""
    classes = {"none": Preconditioner, "jacobi": Jacobi, "bjacobi": BlockJacobi}
    if method.startswith("twolevel_"):
        return TwoLevelPreconditioner(A, method.split("_", 1)[1], None, coords, density, device)
    if method == "htp":
        if htp is None:
            raise ValueError("method 'htp' needs a loaded HTP network (htp=None given)")
        return HTPPreconditioner(A, htp, coords, density, device)
    if method not in classes:
        raise ValueError(f"unknown method {method!r}; expected one of {', '.join(METHODS)}")
    return classes[method](A, coords, density, device)


def apply_microbench(precond: Preconditioner, n_apply: int = 50) -> float:
    """Microseconds per ``precond.apply_`` (one CUDA Graph of ``n_apply`` applies on GPU)."""
    dev = precond.device
    r = torch.randn(precond.n, device=dev)
    z = torch.empty_like(r)

    def run():
        for _ in range(n_apply):
            precond.apply_(r, z)

    if dev.type == "cuda":
        graph, _ = capture(run, warmup=1)
        _, ms = timed(graph.replay, dev)
    else:
        precond.apply_(r, z)
        _, ms = timed(run, dev)
    return 1e3 * ms / n_apply
