"""The two-level variant inside HTPPC, composed from PETSc parts, so it runs on any number of ranks.

    M = Q + (I - QA) B (I - AQ),   Q = W (W^T A W)^-1 W^T

- leaves: each rank's rows cut into leaves of about ``leaf`` rows (Morton with coordinates,
  METIS of the rank's block otherwise; :func:`petsc_htp.leaves.choose_leaves`);
- B: exact leaf solves, one sparse Cholesky factor per rank of D = blockdiag(A_kk) (A without its
  couplings between leaves), applied by ``PCBJACOBI`` on D with one block per rank;
- W: a parallel AIJ matrix with r columns per leaf, the coarse space of each leaf's local Neumann
  matrix (its block with every off-leaf coupling, to other leaves and other ranks, folded into the
  diagonal, so a leaf sees the same matrix whatever the number of ranks): the coarse space is global.
  'eig' vectors come from :mod:`petsc_htp.leafmodes` (one sparse factor for all leaves);
- W^T A W: W^T (A W) by ``MatTransposeMatMult`` (A W and the explicit transposes serve the apply),
  solved by a redundant Cholesky on every rank. When A has the constant
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

from . import leafmodes, twolevel
from .checks import rayleigh_reason
from .coarsenet import learned_basis
from .leaves import Leaves, choose_leaves


COARSE_TEXT = {"const": "each leaf's constant",
               "eig": "one inverse-iteration step of each leaf's Neumann matrix from r smooth seeds",
               "learned": "the coarse network's r vectors per leaf, refined by the same step as eig"}


def _has_constant_null(mat) -> bool:
    """True when A 1 = 0 to 1e-10 of the largest diagonal entry (a Neumann operator)."""
    ones, prod = mat.createVecs()
    ones.set(1.0)
    mat.mult(ones, prod)
    return prod.norm(PETSc.NormType.INFINITY) <= 1e-10 * mat.getDiagonal().norm(PETSc.NormType.INFINITY)


@dataclass
class Analysis:
    """Per-pattern state of this rank's rows.

    ``leaf_of`` is each local row's leaf; ``entry_row`` each stored entry's local row; ``inside``
    the stored entries that couple two rows of one leaf, and ``D_indptr``/``D_indices`` their CSR
    structure (local columns); ``pos``/``mask`` the padded (K, Lmax) layout; ``local`` the torch
    analysis that the learned coarse network reads (None for const and eig).
    """

    leaves: Leaves
    leaf_of: np.ndarray
    entry_row: np.ndarray
    inside: np.ndarray
    D_indptr: np.ndarray
    D_indices: np.ndarray
    pos: np.ndarray
    mask: torch.Tensor
    local: twolevel.TwoLevelAnalysis | None
    coords: np.ndarray | None
    contiguous: bool
    first_leaf: int
    n_leaves_total: int
    analysis_ms: float

    @property
    def ordering(self) -> str:
        """Fill-reducing ordering for the leaf factors: the rows' own when leaves are row blocks."""
        return "natural" if self.contiguous else "nd"


def analyse(mat, rows, coords=None, layout="auto", leaf=128, device="cpu", learned=False) -> Analysis:
    """Leaves of this rank's rows (``rows``: scipy CSR, global columns) and the maps the numeric step uses."""
    t0 = time.perf_counter()
    start, end = mat.getOwnershipRange()
    n = end - start
    pattern = rows[:, start:end].tocsr()
    leaves = choose_leaves(pattern, coords, layout, leaf)
    leaf_of = np.empty(n, dtype=np.int64)
    leaf_of[leaves.perm] = np.repeat(np.arange(leaves.n_leaves), leaves.sizes)
    entry_row = np.repeat(np.arange(n), np.diff(rows.indptr))
    col = rows.indices.astype(np.int64) - start
    inside = (col >= 0) & (col < n)
    inside[inside] = leaf_of[entry_row[inside]] == leaf_of[col[inside]]
    pos = np.empty(n, dtype=np.int64)
    pos[leaves.perm] = twolevel._padded_positions(leaves)
    mask = torch.zeros(leaves.n_leaves * leaves.max_size, dtype=torch.float64)
    mask[pos] = 1.0
    local = twolevel.analyse(pattern, leaves, device) if learned else None
    mpi = mat.getComm().tompi4py()
    first = mpi.exscan(leaves.n_leaves) or 0
    in_order = np.array_equal(leaves.perm, np.arange(n))             # leaves are blocks of the rows
    contiguous = mpi.allreduce(int(not in_order)) == 0
    return Analysis(leaves, leaf_of, entry_row, inside,
                    np.concatenate(([0], np.cumsum(np.bincount(entry_row[inside], minlength=n)))),
                    col[inside], pos, mask.view(leaves.n_leaves, leaves.max_size), local, coords, contiguous,
                    first, mpi.allreduce(leaves.n_leaves), 1e3 * (time.perf_counter() - t0))


def _with_exact_constants(P, mask):
    """Basis whose first column on every leaf is the leaf's normalised constant, the rest orthonormal to it."""
    const = mask / mask.sum(1, keepdim=True).sqrt()
    rest = P - const[:, :, None] * torch.einsum("kl,klr->kr", const, P)[:, None, :]
    q, _ = torch.linalg.qr(rest[:, :, 1:] if P.shape[2] > 1 else rest[:, :, :0])
    return torch.cat([const[:, :, None], q * mask[:, :, None]], dim=2)


def _local_neumann_block(mat, rows) -> sp.csr_matrix:
    """This rank's diagonal block of ``mat`` with its couplings to other ranks added to the diagonal."""
    start, end = mat.getOwnershipRange()
    block = rows[:, start:end].tocsr()
    outside = np.asarray(rows.sum(axis=1)).ravel() - np.asarray(block.sum(axis=1)).ravel()
    block = (block + sp.diags(outside)).tocsr()
    block.sort_indices()
    return block


def _kept(theta, diag, leaf_of, sizes, base, tol) -> np.ndarray:
    """Vectors each leaf keeps (at most its rows): the ``base`` first, and with ``tol`` > 0 also every
    extra one whose Ritz value is at most ``tol`` times the leaf's mean diagonal."""
    K = theta.shape[0]
    count = np.full(K, base)
    if tol > 0:
        scale = np.bincount(leaf_of, np.abs(diag), minlength=K) / sizes
        count += (theta[:, base:].numpy() <= tol * scale[:, None]).sum(1)
    return np.minimum(count, sizes).astype(np.int64)


class _Defaults:
    """Options under ``prefix`` that the user did not give, set for one setup and removed after it."""

    def __init__(self, prefix: str, values: dict):
        self.db, self.values = PETSc.Options(prefix), values

    def __enter__(self):
        self.added = [name for name in self.values if not self.db.hasName(name)]
        for name in self.added:
            self.db.setValue(name, self.values[name])

    def __exit__(self, *exc):
        for name in self.added:
            self.db.delValue(name)


class Composed:
    """The numeric step: W, W^T A W and its redundant Cholesky, the leaf factor, work vectors.

    ``coarse`` is const, eig (``rank`` vectors) or learned (the basis of ``net``, a
    :class:`~petsc_htp.coarsenet.CoarseNet`, from the matrix, the analysis' coordinates and ``density``).
    ``basis``, the ``P`` of an earlier step on the same analysis (``age`` steps old), replaces it.
    """

    def __init__(self, analysis: Analysis, mat, rows, coarse: str, rank: int, prefix: str = "htp_",
                 net=None, density=None, basis=None, age=0, tol=0.0):
        t0 = time.perf_counter()
        a = self.analysis = analysis
        self.coarse, self.A, self.age, self.tol = coarse, mat, age, tol
        n = a.leaf_of.size
        D = sp.csr_matrix((rows.data[a.inside], a.D_indices, a.D_indptr), shape=(n, n))
        self.null = _has_constant_null(mat)
        if basis is not None:
            P, counts = basis
        elif coarse == "const":
            P = (a.mask / a.mask.sum(1, keepdim=True).sqrt())[:, :, None]
            counts = np.ones(a.leaves.n_leaves, dtype=np.int64)
        else:
            seeds = None
            if coarse == "learned":
                seeds = learned_basis(net, a.local, _local_neumann_block(mat, rows), a.coords, density).cpu()
            S = leafmodes.neumann_matrix(D, np.bincount(a.entry_row, rows.data, minlength=n), a.leaf_of)
            base = rank if seeds is None else seeds.shape[2]
            P, theta = leafmodes.modes(S, a.pos, a.mask, base, a.ordering, seeds, base if tol > 0 else 0)
            counts = _kept(theta, S.diagonal(), a.leaf_of, a.leaves.sizes, base, tol)
        if basis is None and self.null:
            P = _with_exact_constants(P, a.mask)
        self.P, self.counts, self.rank = P, counts, P.shape[2]
        t1 = time.perf_counter()
        self.W = self._space(mat, P.numpy(), counts)
        self.AW = mat.matMult(self.W)
        self.E = self.W.transposeMatMult(self.AW)
        self.Wt, self.AWt = self.W.transpose(PETSc.Mat()), self.AW.transpose(PETSc.Mat())
        self.coarse_ksp = PETSc.KSP().create(mat.getComm())
        self.coarse_ksp.setOptionsPrefix(prefix + "cs_")
        self.coarse_ksp.setOperators(self.E, self.E)
        self.coarse_ksp.setType("preonly")
        self.coarse_ksp.getPC().setType("redundant")
        with _Defaults(prefix + "cs_", {"redundant_pc_type": "cholesky", "redundant_pc_factor_shift_type": "nonzero",
                                        "redundant_pc_factor_mat_ordering_type": "nd"}):
            self.coarse_ksp.setFromOptions()
            self.coarse_ksp.setUp()
        t2 = time.perf_counter()
        start = mat.getOwnershipRange()[0]
        self.D = PETSc.Mat().createAIJ(size=(mat.getSizes()[0], mat.getSizes()[0]), comm=mat.getComm(),
                                       csr=(a.D_indptr.astype(PETSc.IntType),
                                            (a.D_indices + start).astype(PETSc.IntType), D.data))
        self.B = PETSc.PC().create(mat.getComm())
        self.B.setOptionsPrefix(prefix + "leaf_")
        self.B.setOperators(self.D, self.D)
        self.B.setType("bjacobi")
        with _Defaults(prefix + "leaf_", {"sub_ksp_type": "preonly", "sub_pc_type": "cholesky",
                                          "sub_pc_factor_shift_type": "nonzero",
                                          "sub_pc_factor_mat_ordering_type": a.ordering}):
            self.B.setFromOptions()
            self.B.setUp()
            self.B.setUpOnBlocks()
        t3 = time.perf_counter()
        self.times = {"coarse_space": 1e3 * (t1 - t0), "coarse_operator": 1e3 * (t2 - t1),
                      "leaf": 1e3 * (t3 - t2)}
        self.c1, self.c2, self.c3 = (self.E.createVecLeft() for _ in range(3))
        self.u, self.v = mat.createVecLeft(), mat.createVecLeft()
        self.setup_ms = 1e3 * (t3 - t0)

    def _space(self, mat, P, counts) -> PETSc.Mat:
        """W: rank-local rows, columns (global leaf, vector) for the first ``counts[k]`` vectors of leaf k,
        one leaf's constant left out under a null space."""
        a = self.analysis
        K, r = a.leaves.n_leaves, P.shape[2]
        start, end = mat.getOwnershipRange()
        mpi = mat.getComm().tompi4py()
        local = int(counts.sum())
        first, total = mpi.exscan(local) or 0, mpi.allreduce(local)
        drop = self.null and a.first_leaf + K == a.n_leaves_total      # the globally last leaf lives here
        vals = P.reshape(-1, r)[a.pos]                   # (n_local, r) in the rank's row order
        leaf_col = first + np.concatenate(([0], np.cumsum(counts)[:-1]))
        cols = leaf_col[a.leaf_of][:, None] + np.arange(r)[None, :]
        keep = np.arange(r)[None, :] < counts[a.leaf_of][:, None]
        if drop:
            last = a.leaf_of[:, None] == K - 1
            keep &= ~(last & (np.arange(r)[None, :] == 0))
            cols = cols - last
        rows = np.broadcast_to(np.arange(end - start)[:, None], cols.shape)
        local_W = sp.csr_matrix((vals[keep], (rows[keep], cols[keep])), shape=(end - start, total - self.null))
        local_W.sort_indices()
        W = PETSc.Mat().createAIJ(size=((end - start, mat.getSize()[0]), (local - drop, local_W.shape[1])),
                                  nnz=(np.diff(local_W.indptr).astype(PETSc.IntType), r), comm=mat.getComm())
        W.setValuesCSR(local_W.indptr.astype(PETSc.IntType), local_W.indices.astype(PETSc.IntType),
                       local_W.data)
        W.assemble()
        return W

    def mult(self, x, y):
        """y = M x = Q x + v - Q A v with v = B (x - A Q x), through AW and the explicit transposes."""
        self.Wt.mult(x, self.c1)
        self.coarse_ksp.solve(self.c1, self.c2)           # c2 = E^-1 W^T x
        self.AW.mult(self.c2, self.u)
        self.u.aypx(-1.0, x)                              # u = x - A Q x
        self.B.apply(self.u, self.v)
        self.AWt.mult(self.v, self.c1)
        self.coarse_ksp.solve(self.c1, self.c3)           # c3 = E^-1 W^T A v
        self.c3.aypx(-1.0, self.c2)
        self.W.mult(self.c3, y)
        y.axpy(1.0, self.v)

    def check(self, probes: int) -> str:
        """Empty when M is finite and positive on ``probes`` random vectors (collective)."""
        x, y = self.A.createVecs()
        rng = PETSc.Random().create(self.A.getComm())
        quotients = []
        for _ in range(probes):
            x.setRandom(rng)
            self.mult(x, y)
            quotients.append(x.dot(y) / x.dot(x))
        rng.destroy()
        return rayleigh_reason(np.min(quotients) if quotients else None, "two-level")

    @property
    def nbytes(self) -> int:
        """Bytes held on this rank: W, A W, their transposes, W^T A W, the leaf Cholesky factor (8 bytes a value)."""
        held = sum(m.getInfo()["nz_used"] for m in (self.W, self.Wt, self.AW, self.AWt, self.E))
        held += sum(sub.getPC().getFactorMatrix().getInfo()["nz_used"] for sub in self.B.getBJacobiSubKSP())
        return int(8 * held)

    def describe(self) -> list:
        """Short lines for ``-ksp_view``."""
        a, lv, t = self.analysis, self.analysis.leaves, self.times
        n = self.A.getSize()[0]
        return [f"leaves: {lv.kind}, {a.n_leaves_total} in all ({lv.n_leaves} on this rank), sizes "
                f"{lv.sizes.min()}-{lv.max_size}; exact solves by one Cholesky factor of blockdiag(A_kk) per rank "
                f"(PCBJACOBI, {a.ordering} ordering)",
                f"coarse: {self.coarse} ({COARSE_TEXT[self.coarse]}), "
                + (f"r={self.rank}" if np.all(self.counts == self.rank) else
                   f"r={self.counts.min()}-{self.counts.max()} per leaf (mean {self.counts.mean():.2f}; more where "
                   f"Ritz values are at most {self.tol:g} x the leaf's mean diagonal)")
                + f", global size {self.E.getSize()[0]}"
                + ("; A's constant null space left out of W" if self.null else "")
                + (f"; space kept from {self.age} numeric setup{'s' if self.age > 1 else ''} ago" if self.age else ""),
                f"setup ms: analysis {a.analysis_ms:.1f} (once per pattern; leaves {lv.build_ms:.1f}); "
                f"coarse space {t['coarse_space']:.1f}, coarse operator {t['coarse_operator']:.1f}, "
                f"leaf {t['leaf']:.1f}",
                "apply: float64 in PETSc (a linear operator to working precision: any KSP, any rtol)",
                f"memory on this rank: {self.nbytes / max(n // self.A.getComm().getSize(), 1):.0f} bytes per unknown"]

    def destroy(self):
        """Free the PETSc objects."""
        for obj in (self.W, self.Wt, self.AW, self.AWt, self.E, self.coarse_ksp, self.B, self.D,
                    self.c1, self.c2, self.c3, self.u, self.v):
            obj.destroy()
