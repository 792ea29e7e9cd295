"""The two-level variant inside HTPPC, composed from PETSc parts, so it runs on any number of ranks.

    M = Q + (I - QA) B (I - AQ),   Q = W (W^T A W)^-1 W^T

- leaves: each rank's rows cut into leaves of about ``leaf`` rows (Morton with coordinates,
  METIS of the rank's block otherwise; :func:`petsc_htp.leaves.choose_leaves`);
- B: exact Cholesky solves on the leaves: ``PCBJACOBI`` when the leaves are contiguous blocks of
  the rank's rows (the given order is the leaves' order), else ``PCASM`` with one non-overlapping
  subdomain per leaf;
- W: a parallel AIJ matrix with r columns per leaf, the coarse space of :mod:`petsc_htp.twolevel`
  computed on the rank's local Neumann block (couplings to other ranks folded into the diagonal,
  so a leaf sees the same local matrix whatever the number of ranks): the coarse space is global;
- W^T A W: ``MatPtAP``, solved by a redundant Cholesky on every rank. When A has the constant
  null space, every leaf's first column is its exact constant and one leaf's is left out, so W
  spans A's range part of the same space and W^T A W is nonsingular.

This is PCDEFLATION's composition (deflation space W, additional PC B) in the symmetric balanced
form, which needs no special initial guess. Apply and setup run in PETSc's compiled kernels.
"""
from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import torch
from petsc4py import PETSc

from . import twolevel
from .coarsenet import learned_basis
from .leaves import Leaves, choose_leaves


def local_neumann_block(mat, rows) -> sp.csr_matrix:
    """This rank's diagonal block of ``mat`` with its couplings to other ranks added to the diagonal.

    ``rows`` are this rank's rows of ``mat`` as scipy CSR with global columns.
    """
    start, end = mat.getOwnershipRange()
    block = rows[:, start:end].tocsr()
    outside = np.asarray(rows.sum(axis=1)).ravel() - np.asarray(block.sum(axis=1)).ravel()
    block = (block + sp.diags(outside)).tocsr()
    block.sort_indices()
    return block


def _has_constant_null(mat) -> bool:
    """True when A 1 = 0 to 1e-10 of the largest diagonal entry (a Neumann operator)."""
    ones, prod = mat.createVecs()
    ones.set(1.0)
    mat.mult(ones, prod)
    return prod.norm(PETSc.NormType.INFINITY) <= 1e-10 * mat.getDiagonal().norm(PETSc.NormType.INFINITY)


@dataclass
class Analysis:
    """Per-pattern state: the rank's leaves, their index sets, the torch analysis of the local block."""

    leaves: Leaves
    local: twolevel.TwoLevelAnalysis
    coords: np.ndarray | None
    contiguous: bool
    subdomains: list
    first_leaf: int
    n_leaves_total: int
    analysis_ms: float


def analyse(mat, rows, coords=None, layout="auto", leaf=128, device="cpu") -> Analysis:
    """Leaves of this rank's rows and the pattern analysis of its local Neumann block."""
    t0 = time.perf_counter()
    block = local_neumann_block(mat, rows)
    leaves = choose_leaves(block, coords, layout, leaf)
    start = mat.getOwnershipRange()[0]
    subdomains = [PETSc.IS().createGeneral(np.sort(leaves.perm[a:b]).astype(PETSc.IntType) + start,
                                           comm=PETSc.COMM_SELF)
                  for a, b in zip(leaves.offsets[:-1], leaves.offsets[1:])]
    mpi = mat.getComm().tompi4py()
    first = mpi.exscan(leaves.n_leaves) or 0
    in_order = np.array_equal(leaves.perm, np.arange(leaves.n))      # leaves are blocks of the rows
    contiguous = mpi.allreduce(int(not in_order)) == 0               # (on every rank: one PC type)
    return Analysis(leaves, twolevel.analyse(block, leaves, device), coords, contiguous, subdomains, first,
                    mpi.allreduce(leaves.n_leaves), 1e3 * (time.perf_counter() - t0))


def _with_exact_constants(P, mask):
    """Basis whose first column on every leaf is the leaf's normalised constant, the rest orthonormal to it."""
    const = mask / mask.sum(1, keepdim=True).sqrt()
    rest = P - const[:, :, None] * torch.einsum("kl,klr->kr", const, P)[:, None, :]
    q, _ = torch.linalg.qr(rest[:, :, 1:] if P.shape[2] > 1 else rest[:, :, :0])
    return torch.cat([const[:, :, None], q * mask[:, :, None]], dim=2)


class Composed:
    """The numeric step: W, W^T A W and its redundant Cholesky, the ASM leaf solves, work vectors.

    ``coarse`` is const, eig (``rank`` vectors) or learned (the basis of ``net``, a
    :class:`~petsc_htp.coarsenet.CoarseNet`, from the matrix, the analysis' coordinates and ``density``).
    """

    def __init__(self, analysis: Analysis, mat, rows, coarse: str, rank: int, prefix: str = "htp_",
                 net=None, density=None):
        t0 = time.perf_counter()
        self.analysis, self.coarse = analysis, coarse
        self.A = mat
        block = local_neumann_block(mat, rows)
        lv, local = analysis.leaves, analysis.local
        if coarse == "learned":
            basis = learned_basis(net, local, block, analysis.coords, density)
            P = twolevel.coarse_space(local, block, "given", basis=basis)
        else:
            P = twolevel.coarse_space(local, block, coarse, rank)
        self.null = _has_constant_null(mat)
        if self.null:
            P = _with_exact_constants(P, local.mask)
        self.rank = P.shape[2]
        t1 = time.perf_counter()
        self.W = self._space(mat, P.cpu().numpy(), lv, local)
        self.E = mat.ptap(self.W)
        db = PETSc.Options(prefix)
        for name, value in (("cs_redundant_pc_type", "cholesky"), ("cs_redundant_pc_factor_shift_type", "nonzero"),
                            ("leaf_sub_ksp_type", "preonly"), ("leaf_sub_pc_type", "cholesky"),
                            ("leaf_sub_pc_factor_shift_type", "nonzero")):
            if not db.hasName(name):                      # defaults; -<prefix>htp_cs_* / leaf_* override
                db.setValue(name, value)
        self.coarse_ksp = PETSc.KSP().create(mat.getComm())
        self.coarse_ksp.setOptionsPrefix(prefix + "cs_")
        self.coarse_ksp.setOperators(self.E, self.E)
        self.coarse_ksp.setType("preonly")
        self.coarse_ksp.getPC().setType("redundant")
        self.coarse_ksp.setFromOptions()
        self.coarse_ksp.setUp()
        t2 = time.perf_counter()
        self.B = PETSc.PC().create(mat.getComm())
        self.B.setOptionsPrefix(prefix + "leaf_")
        self.B.setOperators(mat, mat)
        if analysis.contiguous:                           # PCBJACOBI's own equal split is the leaves
            self.B.setType("bjacobi")
            PETSc.Options(prefix + "leaf_").setValue("pc_bjacobi_local_blocks", lv.n_leaves)
        else:
            self.B.setType("asm")
            self.B.setASMLocalSubdomains(len(analysis.subdomains), analysis.subdomains)
            self.B.setASMOverlap(0)
            self.B.setASMType(PETSc.PC.ASMType.BASIC)
        self.B.setFromOptions()
        self.B.setUp()
        self.B.setUpOnBlocks()
        t3 = time.perf_counter()
        self.times = {"coarse_space": 1e3 * (t1 - t0), "coarse_operator": 1e3 * (t2 - t1),
                      "leaf": 1e3 * (t3 - t2)}
        self.c1, self.c2 = self.E.createVecs()
        self.t, self.u, self.v = (mat.createVecLeft() for _ in range(3))
        self.setup_ms = 1e3 * (t3 - t0)

    def _space(self, mat, P, lv: Leaves, local) -> PETSc.Mat:
        """W: rank-local rows, columns (global leaf, vector), one leaf's constant left out under a null space."""
        K, L = local.shape
        r = P.shape[2]
        a = self.analysis
        start, end = mat.getOwnershipRange()
        drop = self.null and a.first_leaf + K == a.n_leaves_total      # the globally last leaf lives here
        pos = local.pos.cpu().numpy()                    # padded slot of every permuted local row
        leaf = pos // L
        vals = P.reshape(K * L, r)[pos]                   # (n_local, r), rows in permuted order
        cols = ((a.first_leaf + leaf) * r)[:, None] + np.arange(r)[None, :]
        keep = np.ones(cols.shape, dtype=bool)
        if drop:
            last = leaf[:, None] == K - 1
            keep &= ~(last & (np.arange(r)[None, :] == 0))
            cols = cols - last
        rows = np.broadcast_to(lv.perm[:, None], cols.shape)
        local_W = sp.csr_matrix((vals[keep], (rows[keep], cols[keep])),
                                shape=(end - start, a.n_leaves_total * r - self.null))
        local_W.sort_indices()
        W = PETSc.Mat().createAIJ(size=((end - start, mat.getSize()[0]), (K * r - drop, local_W.shape[1])),
                                  nnz=(np.diff(local_W.indptr).astype(PETSc.IntType), r), comm=mat.getComm())
        W.setValuesCSR(local_W.indptr.astype(PETSc.IntType), local_W.indices.astype(PETSc.IntType),
                       local_W.data)
        W.assemble()
        return W

    def _q(self, x, out):
        """out = W (W^T A W)^-1 W^T x."""
        self.W.multTranspose(x, self.c1)
        self.coarse_ksp.solve(self.c1, self.c2)
        self.W.mult(self.c2, out)

    def mult(self, x, y):
        """y = M x = t + v - Q A v with t = Q x, v = B (x - A t)."""
        self._q(x, self.t)
        self.A.mult(self.t, self.u)
        self.u.aypx(-1.0, x)
        self.B.apply(self.u, self.v)
        self.A.mult(self.v, self.u)
        self.u.aypx(-1.0, x)
        self._q(self.u, y)                                # Q (x - A v) = t - Q A v
        y.axpy(1.0, self.v)

    def check(self, probes: int) -> str:
        """Empty when M is finite and positive on ``probes`` random vectors (collective)."""
        x, y = self.A.createVecs()
        rng = PETSc.Random().create(self.A.getComm())
        worst = np.inf
        for _ in range(probes):
            x.setRandom(rng)
            self.mult(x, y)
            worst = min(worst, x.dot(y) / x.dot(x))
        rng.destroy()
        if not np.isfinite(worst):
            return "two-level apply is not finite"
        if worst <= 0:
            return f"Rayleigh probe found M indefinite (min r^T M r / r^T r = {worst:.3e})"
        return ""

    @property
    def nbytes(self) -> int:
        """Bytes held on this rank: W, W^T A W, and the leaf Cholesky factors (8 bytes a value)."""
        held = self.W.getInfo()["nz_used"] + self.E.getInfo()["nz_used"]
        subs = self.B.getBJacobiSubKSP() if self.analysis.contiguous else self.B.getASMSubKSP()
        held += sum(sub.getPC().getFactorMatrix().getInfo()["nz_used"] for sub in subs)
        return int(8 * held)

    def describe(self) -> list:
        """Short lines for ``-ksp_view``."""
        a, lv, t = self.analysis, self.analysis.leaves, self.times
        n = self.A.getSize()[0]
        return [f"leaves: {lv.kind}, {a.n_leaves_total} in all ({lv.n_leaves} on this rank), sizes "
                f"{lv.sizes.min()}-{lv.max_size}; exact Cholesky on each "
                f"({'PCBJACOBI' if a.contiguous else 'PCASM, no overlap'})",
                f"coarse: {self.coarse}, r={self.rank}, global size {self.E.getSize()[0]}"
                + ("; A's constant null space left out of W" if self.null else ""),
                f"setup ms: analysis {a.analysis_ms:.1f} (once per pattern; leaves {lv.build_ms:.1f}); "
                f"coarse space {t['coarse_space']:.1f}, coarse operator {t['coarse_operator']:.1f}, "
                f"leaf {t['leaf']:.1f}",
                "apply: float64 in PETSc (a linear operator to working precision: any KSP, any rtol)",
                f"memory on this rank: {self.nbytes / max(n // self.A.getComm().getSize(), 1):.0f} bytes per unknown"]

    def destroy(self):
        """Free the PETSc objects."""
        for obj in (self.W, self.E, self.coarse_ksp, self.B, self.c1, self.c2, self.t, self.u, self.v):
            obj.destroy()
