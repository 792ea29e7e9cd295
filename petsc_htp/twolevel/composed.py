"""The two-level variant inside HTPPC, composed from PETSc parts, on any number of ranks.

    M = Q + (I - QA) B (I - AQ)  (balanced)   or   M = Q + (I - QA) B  (deflated),   Q = W (W^T A W)^-1 W^T

B = D^-1 solves the leaves exactly: D, A's leaf blocks in the leaves' row order, is one sparse matrix per
rank with one Cholesky factor (natural ordering: the leaves are contiguous; ICC(0) by default in 3-D, where
B only approximates D^-1 and the forms go through A W; :mod:`petsc_htp.twolevel.sizing`). W holds the coarse vectors
of every leaf (:mod:`petsc_htp.twolevel.coarsespace`), E = W^T A W is solved by a sparse direct factor. Because
D B = I, W^T A B x = W^T x + C^T B x with C = (A - D) W, the couplings between leaves times W (a few
rows per leaf); so the deflated form is y = v - W E^-1 C^T v with v = B x: one leaf solve, one coarse
solve and two thin products per application. Started so that W^T r0 = 0 (:meth:`TwoLevelPC.presolve`),
CG with the deflated M takes the iterations of the balanced one, which is SPD and costs a second
coarse solve and three more thin products (for KSPs that need a symmetric M).

Construction is the analysis: leaves, index maps, pieces and components, every matrix with its final
nonzero pattern (W holds each leaf's largest count of vectors), symbolic factorisations and products.
:meth:`TwoLevelPC.numeric` then only moves values: new values into D, the Neumann matrix and O,
numeric factorisations, the coarse space, and the products A W-free ``C = O W`` and ``E = W^T A W`` with
PETSc's reuse. One global coarse space serves every rank; a Neumann operator's null space is handled
per connected component (:mod:`petsc_htp.twolevel.nullspace`).
"""
from __future__ import annotations

import contextlib
import dataclasses
import time
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import torch
from petsc4py import PETSc

from . import coarsespace, nullspace, sizing
from ..checks import rayleigh_reason
from .leaflayout import layout
from .leafsolvers import ExactLeaves, OverlappingLeaves, seqaij
from .aggregation import THETA
from .graphshape import graph_shape
from .leaves import choose_leaves

FACTOR_PCS = ("lu", "cholesky", "icc", "ilu")       # PC types that hold a factor
WEAK_GROWTH = 2.0       # aggregation leaves are made anew once they hold this many times their weak couplings
SYMMETRIC_KSPS = ("minres", "symmlq", "cr", "pipecr", "qcg", "stcg", "gltr", "nash")   # need a symmetric M
COARSE_TEXT = {"const": "the constant of each piece of each leaf",
               "eig": "piece constants and one inverse-iteration step of each leaf's Neumann matrix from smooth seeds",
               "learned": "piece constants and the coarse network's vectors refined by the same step as eig"}


@dataclass(frozen=True)
class Config:
    """What the two-level variant is made of (HTPPC's ``-htp_*`` options).

    Attributes
    ----------
    leaf : int
        Rows per leaf; 0: by the problem's dimension (:mod:`petsc_htp.twolevel.sizing`).
    ordering : str
        Leaf layout: auto, morton, metis, natural or rcm (:func:`petsc_htp.twolevel.leaves.choose_leaves`).
    coarse : str
        const, eig, learned or auto (by the problem's dimension).
    rank : int
        Vectors per leaf r: the piece constants and r - 1 more (eig; learned takes the network's r).
    tol : float
        With tol > 0, r more seeds per leaf, kept by their Ritz value (see :mod:`petsc_htp.twolevel.coarsespace`).
    form : str
        auto (deflated, or balanced under a KSP that needs a symmetric M), deflated or balanced.
    overlap : int
        0: exact leaf solves; k > 0: additive Schwarz on leaves grown by k layers (:mod:`petsc_htp.twolevel.leafsolvers`).
    solver : str
        Coarse solver: lu, gamg or auto (by the coarse operator's size and dimension).
    """

    leaf: int = 0
    ordering: str = "auto"
    coarse: str = "auto"
    rank: int = 4
    tol: float = 0.0
    form: str = "auto"
    overlap: int = 0
    solver: str = "auto"


class _Collective:
    """The few collectives the analysis needs, through mpi4py only on more than one rank."""

    def __init__(self, comm):
        self.size = comm.getSize()
        self.mpi = comm.tompi4py() if self.size > 1 else None

    def exscan(self, value: int) -> int:
        return 0 if self.mpi is None else (self.mpi.exscan(int(value)) or 0)

    def sum(self, value: int) -> int:
        return int(value) if self.mpi is None else self.mpi.allreduce(int(value))

    def max_array(self, values: np.ndarray) -> np.ndarray:
        if self.mpi is None:
            return values
        from mpi4py import MPI

        out = np.empty_like(values)
        self.mpi.Allreduce(np.ascontiguousarray(values), out, op=MPI.MAX)
        return out

    def gather_rows(self, values: np.ndarray) -> np.ndarray:
        """Every rank's rows of a 2-column int array, concatenated in rank order."""
        if self.mpi is None:
            return values
        return np.concatenate(self.mpi.allgather(values)).reshape(-1, values.shape[1])


def _coo_aij(comm, rows, cols, shape, local, col_block=1) -> PETSc.Mat:
    """An AIJ on ``comm`` with the COO pattern (global ``rows``, ``cols``); values come by ``setValuesCOO``."""
    mat = PETSc.Mat().create(comm=comm)
    mat.setSizes(((local[0], shape[0]), (local[1], shape[1])))
    mat.setBlockSizes(1, col_block)
    mat.setType(PETSc.Mat.Type.AIJ)
    mat.setPreallocationCOO(rows.astype(PETSc.IntType), cols.astype(PETSc.IntType))
    return mat


@contextlib.contextmanager
def _scoped(prefix, defaults):
    """``defaults`` in PETSc's options database under ``prefix`` where the user set nothing, for the block only."""
    db = PETSc.Options(prefix)
    added = [name for name in defaults if not db.hasName(name)]
    for name in added:
        db.setValue(name, defaults[name])
    try:
        yield
    finally:
        for name in added:
            db.delValue(name)


def configured_pc(comm, mat, prefix, defaults) -> PETSc.PC:
    """A PC on ``mat`` configured from ``defaults`` and, winning over them, the options under ``prefix``."""
    pc = PETSc.PC().create(comm)
    pc.setOptionsPrefix(prefix)
    pc.setOperators(mat, mat)
    with _scoped(prefix, defaults):
        pc.setFromOptions()
    return pc


def _ms(t0) -> float:
    return 1e3 * (time.perf_counter() - t0)


class TwoLevelPC:
    """The two-level preconditioner of one matrix pattern; :meth:`numeric` takes each frame's values.

    Parameters
    ----------
    mat : petsc4py.PETSc.Mat
        The operator (AIJ, any number of ranks); products with it are reused frame after frame.
    rows : scipy.sparse.csr_matrix
        This rank's rows of ``mat`` (global columns, sorted).
    coords : numpy.ndarray (n, 2), optional
        This rank's row coordinates (Morton leaves).
    cfg : Config
    prefix : str
        Options prefix of the inner solvers: ``<prefix>leaf_`` (leaf factor) and ``<prefix>cs_`` (coarse).
    net : CoarseNet, optional
        The coarse network (``cfg.coarse == 'learned'``).
    """

    def __init__(self, mat, rows, coords, cfg: Config, prefix="htp_", net=None):
        try:
            self._analyse(mat, rows, coords, cfg, prefix, net)
        except Exception:
            self.destroy()                       # what was built so far
            raise

    def _analyse(self, mat, rows, coords, cfg, prefix, net):
        t0 = time.perf_counter()
        self.mat, self.net, self.coords = mat, net, coords
        self.comm, self.coll = mat.getComm(), _Collective(mat.getComm())
        start, end = mat.getOwnershipRange()
        block = rows if self.coll.size == 1 else rows[:, start:end].tocsr()
        N = mat.getSize()[0]
        self.shape = graph_shape(block) if coords is None else None
        local = sizing.dimension(None if coords is None else coords.shape[1], self.shape)
        self.dim = int(self.coll.max_array(np.array([local]))[0])
        self.auto = [name for name, unset in (("leaf", cfg.leaf == 0), ("coarse", cfg.coarse == "auto")) if unset]
        self.cfg = cfg = self.resolved(cfg)
        self.leaves = choose_leaves(block, coords, cfg.ordering, cfg.leaf)
        self.lay = layout(rows, start, self.leaves)
        self._torch_analysis = None
        if cfg.coarse == "learned":                                   # the network's layout: pattern only
            from . import batched as twolevel

            self._torch_analysis = twolevel.analyse(block, self.leaves)
        self._components(rows)
        self._columns()
        self._matrices(rows, prefix)
        self.times, self.age, self.kept, self._forced, self._dense = {}, 0, None, None, None
        self.numeric_count = 0
        if self.leaves.kind == "aggregation":             # where each off-diagonal entry of D and its diagonals sit
            lay = self.lay
            r = np.repeat(np.arange(lay.n), np.diff(lay.d_indptr))
            off = r != lay.d_indices
            self._weak_src = lay.d_src[off]
            self._weak_row, self._weak_col = lay.d_src[lay.d_diag[r[off]]], lay.d_src[lay.d_diag[lay.d_indices[off]]]
            self.weak_made = self._weak_inside(rows.data)
        self.analysis_ms = _ms(t0)

    def _weak_inside(self, data) -> int:
        """Weak couplings (:data:`aggregation.THETA`) inside the leaves, for values ``data`` of the analysed pattern."""
        vals = data[self._weak_src]
        return int(np.count_nonzero((vals * vals < THETA * THETA * np.abs(data[self._weak_row] * data[self._weak_col]))
                                    & (vals != 0)))

    def moved(self, rows) -> bool:
        """Whether new values ``rows`` (same pattern) moved away from aggregation leaves: they now hold more than
        :data:`WEAK_GROWTH` times the weak couplings they held when made (plus 0.1 % of the rows), so leaves made
        anew would follow the couplings better (a coefficient jump that moved; 5x on a DMDA frame with new
        inclusions, which then takes 45 CG iterations against 26). Always False for other leaves."""
        if self.lay.leaves.kind != "aggregation":
            return False
        return self._weak_inside(rows.data) > WEAK_GROWTH * self.weak_made + 1e-3 * self.lay.n

    def resolved(self, cfg) -> Config:
        """``cfg`` with its problem-sized fields (leaf 0, coarse auto) set for this matrix (:mod:`.sizing`)."""
        return dataclasses.replace(cfg, leaf=cfg.leaf or sizing.leaf_size(self.dim, self.mat.getSize()[0]),
                                   coarse=sizing.COARSE[self.dim] if cfg.coarse == "auto" else cfg.coarse)

    # ------------------------------------------------------------------ analysis
    def _components(self, rows):
        """Global piece numbering and the connected components of A over all ranks."""
        lay, coll = self.lay, self.coll
        pc = lay.pieces
        self.piece_offset = coll.exscan(pc.n_pieces)
        self.n_pieces = coll.sum(pc.n_pieces)
        row_piece = pc.label[lay.iperm] + self.piece_offset          # global piece of each of A's local rows
        self.isolated = np.zeros(self.n_pieces, dtype=bool)
        self.isolated[self.piece_offset:self.piece_offset + pc.n_pieces] = lay.isolated
        if coll.size == 1:                                            # A's own components, read off its rows
            self.n_comp, labels = nullspace.graph_components(rows)
            self.comp_of_row = labels
            self.comp_of_piece = np.zeros(self.n_pieces, dtype=np.int64)
            self.comp_of_piece[row_piece] = labels
            return
        o_rows, o_cols = lay.o_rows, rows.indices[lay.o_src].astype(np.int64)
        start, n = lay.start, lay.n
        local = (o_cols >= start) & (o_cols < start + n)
        other = np.zeros(o_cols.size, dtype=np.int64)
        other[local] = row_piece[o_cols[local] - start]
        if not local.all():
            other[~local] = self._ghost_pieces(row_piece, o_cols[~local])
        key = np.unique(row_piece[o_rows] * self.n_pieces + other)
        edges = np.stack([key // self.n_pieces, key % self.n_pieces], 1)
        self.n_comp, self.comp_of_piece = nullspace.components(self.n_pieces, coll.gather_rows(edges))
        self.comp_of_row = self.comp_of_piece[row_piece]              # of A's local rows
        self.isolated = coll.max_array(self.isolated.astype(np.int64)) > 0

    def _ghost_pieces(self, row_piece, cols) -> np.ndarray:
        """Global piece of other ranks' rows ``cols`` (one scatter, at analysis)."""
        owned = self.mat.createVecLeft()
        owned.getArray()[:] = row_piece
        want, where = np.unique(cols, return_inverse=True)
        ghost = PETSc.Vec().createSeq(want.size, comm=PETSc.COMM_SELF)
        index = PETSc.IS().createGeneral(want.astype(PETSc.IntType), comm=PETSc.COMM_SELF)
        scatter = PETSc.Scatter().create(owned, index, ghost, None)
        scatter.scatter(owned, ghost, PETSc.InsertMode.INSERT, PETSc.ScatterMode.FORWARD)
        out = ghost.getArray().astype(np.int64)[where]
        for obj in (owned, ghost, index, scatter):
            obj.destroy()
        return out

    def _columns(self):
        """Coarse columns of every leaf (modes, extras, then one per piece but decoupled ones), their global numbers
        and W's structure. A leaf of decoupled rows alone has no column."""
        lay, cfg = self.lay, self.cfg
        lv, pc = lay.leaves, lay.pieces
        self.q = 0 if cfg.coarse == "const" else (self.net.cfg.rank if cfg.coarse == "learned" else cfg.rank) - 1
        self.extra = (self.q + 1) if cfg.tol > 0 and cfg.coarse != "const" else 0
        lead = self.q + self.extra
        self.has_col = ~lay.decoupled
        before = np.cumsum(self.has_col) - self.has_col                  # pieces with a column before each one
        index = np.where(self.has_col, before - before[pc.first][pc.leaf], -1)      # its column among its leaf's
        count = np.bincount(pc.leaf[self.has_col], minlength=lv.n_leaves)
        self.ncols = np.where(count > 0, lead + count, 0)
        live = self.ncols[self.ncols > 0]
        sizes = self.coll.max_array(np.array([live.max(initial=0), -live.min(initial=2 ** 40)]))
        self.col_block = int(sizes[0]) if sizes[0] == -sizes[1] else 1     # W's columns come in equal blocks per leaf
        first = self.coll.exscan(self.ncols.sum())
        self.m = self.coll.sum(self.ncols.sum())
        self.leaf_col = first + np.concatenate(([0], np.cumsum(self.ncols)[:-1]))
        self.piece_col = np.where(self.has_col, self.leaf_col[pc.leaf] + lead + index, -1)
        per_row = self.ncols[lay.leaf[lay.iperm]]                     # W entries of each of A's rows
        row = np.repeat(np.arange(lay.n), per_row)
        j = np.arange(row.size) - np.repeat(np.cumsum(per_row) - per_row, per_row)
        p = lay.iperm[row]                                            # the row in the leaves' order
        self.w_rows = row + lay.start
        self.w_cols = self.leaf_col[lay.leaf[p]] + j
        self.w_local_col = self.w_cols - first                        # W's columns of this rank's rows are its own
        # aggregation leaves: numpy and unpadded (coarsespace.flat); other leaves keep the padded basis, whose
        # rounding the stability map and the back-ends' parity were measured with (contrast 1e6 sits at the edge)
        self.flat = lv.kind == "aggregation" and self.q <= 1 and not self.extra
        if self.flat:
            self.w_p, self.w_lead = p, j < lead
            piece = pc.label[p]
            mine = ~self.w_lead & (j - lead == index[piece])
            self.w_fixed = np.where(mine, 1.0 / np.sqrt(pc.size[piece]), 0.0)
        else:                                                         # the padded basis of coarsespace.basis
            self.constants = coarsespace.piece_constants(lay, index)
            self.w_src = lay.pos[p] * (lead + self.constants.shape[2]) + j
        if lead:
            self.seeds = coarsespace.seeds(lay.leaf, lv.offsets, lv.sizes, 1, lead)

    def _matrices(self, rows, prefix):
        """Every matrix with its final pattern, the solvers and the work vectors."""
        lay, comm = self.lay, self.comm
        n, N = lay.n, self.mat.getSize()[0]
        self.d_values = np.zeros(lay.d_src.size)
        opts = sizing.leaf_factor(self.dim, lay.leaves.kind)
        factor = lambda m: configured_pc(PETSc.COMM_SELF, m, prefix + "leaf_", opts)     # noqa: E731
        if self.cfg.overlap:
            self.leafsolver = OverlappingLeaves(lay, rows, self.cfg.overlap, factor)
        else:
            self.leafsolver = ExactLeaves(lay, self.d_values, factor, lay.identity and self.coll.size == 1)
        self.s_values, self.S, self.S_factor, self.S_csr = None, None, None, None
        if self.q + self.extra:
            self.s_values = np.zeros(lay.d_src.size)
            self.S = seqaij(lay.d_indptr, lay.d_indices, self.s_values, n)
            self.S_factor = factor(self.S)
            self.S_csr = sp.csr_matrix((self.s_values, lay.d_indices, lay.d_indptr), shape=(n, n))
        self.o_values = np.zeros(lay.o_src.size)
        self.o_perm_rows = lay.iperm[lay.o_rows]                     # O's rows in the leaves' order
        self.O = _coo_aij(comm, lay.o_rows + lay.start, rows.indices[lay.o_src], (N, N), (n, n))
        self.w_values = np.zeros(self.w_rows.size)
        self.W = _coo_aij(comm, self.w_rows, self.w_cols, (N, self.m), (n, int(self.ncols.sum())), self.col_block)
        self.C = self.E = self.F = self.AW = self.Eb = None
        self.coarse_prefix = prefix + "cs_"
        self.coarse = None
        self.solver = self.cfg.solver if self.cfg.solver != "auto" else sizing.coarse_solver(self.dim, self.m)
        self.v, self.t = self.mat.createVecLeft(), self.mat.createVecLeft()

    # ------------------------------------------------------------------ numeric
    def numeric(self, rows, density=None, keep_space=False):
        """New values (``rows``: this rank's rows, the analysed pattern); ``keep_space`` keeps W."""
        lay, T = self.lay, {}
        data = rows.data
        t0 = time.perf_counter()
        np.take(data, lay.o_src, out=self.o_values)
        self.O.setValuesCOO(self.o_values)
        null, drop, ground = self._null(data)
        np.take(data, lay.d_src, out=self.d_values)
        if ground.any():
            nullspace.ground(self.d_values, lay.d_diag, nullspace.first_rows(lay.pieces.label, ground))
        self.leafsolver.numeric(data)
        T["leaf"] = _ms(t0)
        t0 = time.perf_counter()
        if not (keep_space and self.kept is not None):
            self.kept = self._space(rows, density)
            self.age = 0
        else:
            self.age += 1
        self._dropped = self.piece_col[drop[self.piece_offset:self.piece_offset + lay.pieces.n_pieces] & self.has_col]
        values = self.w_values
        if self._dropped.size:
            values = values.copy()
            values[self._zeroed(self._dropped)] = 0.0
        self.W.setValuesCOO(values)
        T["coarse_space"] = _ms(t0)
        t0 = time.perf_counter()
        self._products()
        T["products"] = _ms(t0)
        t0 = time.perf_counter()
        with _scoped(self.coarse_prefix, self._coarse_defaults):    # PCREDUNDANT's inner solver reads them now
            self.coarse.setUp()
            if self.coarse.getType() == "redundant":               # it factors at its first apply: do that here
                self.g.set(0.0)
                self.coarse.apply(self.g, self.c)
        T["coarse_factor"] = _ms(t0)
        self.times, self.null_components = T, int(null.sum())
        self.numeric_count += 1

    def _zeroed(self, dropped) -> np.ndarray:
        """W's entries in the columns ``dropped`` (cached: the null space rarely changes)."""
        key = dropped.tobytes()
        if getattr(self, "_zeroed_key", None) != key:
            gone = np.zeros(int(self.ncols.sum()), dtype=bool)
            gone[dropped - self.leaf_col[0]] = True
            self._zeroed_key, self._zeroed_at = key, np.flatnonzero(gone[self.w_local_col])
        return self._zeroed_at

    def _null(self, data) -> tuple:
        """Null components (attached MatNullSpace, else A's row sums), and the pieces to drop and to ground."""
        nsp = self.mat.getNullSpace()
        reduce = self.coll.max_array if self.coll.size > 1 else None
        if nsp.handle:
            null = nullspace.null_from_vectors([z.getArray(readonly=True) for z in nsp.getVecs()], nsp.hasConstant(),
                                               self.comp_of_row, self.n_comp, reduce)
        else:
            diag = data[self.lay.d_src[self.lay.d_diag]]
            rowsum = np.bincount(self.lay.entry_row, data, minlength=self.lay.n)
            null = nullspace.null_by_rowsums(rowsum, diag, self.comp_of_row, self.n_comp, reduce)
        drop, ground = nullspace.dropped(null, self.comp_of_piece, self.isolated)
        return null, drop, ground[self.piece_offset:self.piece_offset + self.lay.pieces.n_pieces]

    def _space(self, rows, density) -> np.ndarray:
        """The coarse vectors into ``w_values``; returns the vectors kept per leaf."""
        lay = self.lay
        start = diag = None
        if self.q + self.extra:                        # one inverse-iteration step of the leaves' Neumann matrices
            outside = np.bincount(self.o_perm_rows, self.o_values, minlength=lay.n)
            diag = coarsespace.neumann_diagonal(self.d_values[lay.d_diag], outside, lay.leaf, lay.leaves.sizes)
            np.copyto(self.s_values, self.d_values)
            self.s_values[lay.d_diag] = diag
            self.S.stateIncrease()
            self.S_factor.setUp()
            start = self.seeds if self.cfg.coarse != "learned" else self._learned_seeds(rows, density)
        if self.flat:
            np.copyto(self.w_values, self.w_fixed)
            if not self.q:
                return self.ncols
            y, ok = coarsespace.flat(self._solve_neumann(start)[:, 0], lay.leaf, lay.pieces)
            self.w_values[self.w_lead] = y[self.w_p[self.w_lead]]
            return self.ncols - ((self.ncols > 0) & ~ok)
        P, kept = coarsespace.basis(lay, self.constants, start, self._solve_neumann, self.extra,
                                    self.S_csr, diag, self.cfg.tol)
        np.take(P.numpy().reshape(-1), self.w_src, out=self.w_values)
        return kept

    def _learned_seeds(self, rows, density) -> np.ndarray:
        """The coarse network's vectors (constant column left out) as seeds, plus the cosine extras."""
        from .coarsenet import learned_vectors

        block = rows if self.coll.size == 1 else _folded_block(rows, self.lay.start, self.lay.n)
        P = learned_vectors(self.net, self._torch_analysis, block, self.coords, density).cpu()
        K, L = self.lay.shape
        net = P.reshape(K * L, -1)[torch.as_tensor(self.lay.pos)].numpy()
        return np.asfortranarray(np.hstack([net, self.seeds[:, self.q:]]) if self.extra else net)

    def _solve_neumann(self, X) -> np.ndarray:
        """S^-1 X for an (n, q) array, one multi-vector triangular solve (a view of a work array)."""
        if self._dense is None or self._dense[0].shape != X.shape:
            self._free_dense()
            rhs = np.empty(X.shape, order="F")
            out = np.empty(X.shape, order="F")
            self._dense = (rhs, out, PETSc.Mat().createDense(X.shape, array=rhs, comm=PETSc.COMM_SELF),
                           PETSc.Mat().createDense(X.shape, array=out, comm=PETSc.COMM_SELF))
        rhs, out, R, Y = self._dense
        np.copyto(rhs, X)
        R.stateIncrease()
        self.S_factor.getFactorMatrix().matSolve(R, Y)
        return out

    def _free_dense(self):
        if self._dense is not None:
            self._dense[2].destroy()
            self._dense[3].destroy()
        self._dense = None

    def _products(self):
        """C = O W, E = W^T A W (lifted on unused columns), F = W^T C for the balanced form; symbolic once."""
        first = self.C is None
        self.C = self.O.matMult(self.W, result=self.C)
        if not self.leafsolver.exact:
            self.AW = self.mat.matMult(self.W, result=self.AW)
        if first and self.coll.size == 1:           # PETSc's 'rap' PtAP is about 1.5x faster here than its default
            with _scoped(self.mat.getOptionsPrefix() or "", {"matptap_via": "rap"}):
                self.E = self.mat.ptap(self.W)
        else:
            self.E = self.mat.ptap(self.W, result=self.E)
        if self.F is not None or (self.form() == "balanced" and self.leafsolver.exact):
            self.F = self.W.transposeMatMult(self.C, result=self.F)
        lift = self.E.createVecLeft() if first else self._lift
        diag = self.E.getDiagonal()
        top = self.coll.max_array(np.array([np.abs(diag.getArray()).max(initial=0.0)]))[0]
        lift.getArray()[:] = coarsespace.lift(np.append(diag.getArray(), top))[:-1]      # the global top sets the scale
        self.E.setDiagonal(lift, addv=PETSc.InsertMode.ADD_VALUES)
        diag.destroy()
        self._lift = lift
        if self.col_block > 1 and self.solver == "lu":     # block LU kernels: a third faster to factor and to apply
            self.Eb = self.E.convert(PETSc.Mat.Type.BAIJ, out=self.Eb or PETSc.Mat())
        if first:
            defaults = sizing.coarse_options(self.dim, self.coll.size > 1, self.solver, self.lay.leaves.kind)
            if self.col_block > 1:                  # BAIJ factors shift only within the diagonal blocks
                defaults = {k: "inblocks" if k.endswith("shift_type") else v for k, v in defaults.items()}
            self.coarse = configured_pc(self.comm, self.Eb or self.E, self.coarse_prefix, defaults)
            self._coarse_defaults = defaults
            self.g, self.c, self.c2 = (self.E.createVecLeft() for _ in range(3))

    # ------------------------------------------------------------------ apply
    def form(self, ksp_type=None) -> str:
        """The form in use: the configured one, or for 'auto' the one the last :meth:`presolve` chose (deflated
        unless ``ksp_type`` needs a symmetric M)."""
        if self._forced or self.cfg.form != "auto":
            return self._forced or self.cfg.form
        return "balanced" if ksp_type in SYMMETRIC_KSPS else getattr(self, "_auto", "deflated")

    def mult(self, x, y):
        """y = M x in the form in use."""
        B = self.leafsolver
        if self.form() == "deflated":
            B.apply(x, self.v)                                 # v = B x
            if B.exact:
                self.C.multTranspose(self.v, self.g)           # g = C^T v = (A W)^T B x - W^T x
                self.g.scale(-1.0)
            else:
                self.W.multTranspose(x, self.g)
                self.g.scale(-1.0)
                self.AW.multTransposeAdd(self.v, self.g, self.g)
                self.g.scale(-1.0)                             # g = W^T x - (A W)^T B x
            self.coarse.apply(self.g, self.c)
            self.W.multAdd(self.c, self.v, y)                  # y = v + W E^-1 (W^T x - (A W)^T v)
            return
        self.W.multTranspose(x, self.g)
        self.coarse.apply(self.g, self.c)                      # c1 = E^-1 W^T x
        if not B.exact:
            self.AW.mult(self.c, self.t)
            self.t.aypx(-1.0, x)                               # u = x - A W c1
            B.apply(self.t, self.v)                            # v = B u
            self.AW.multTranspose(self.v, self.g)
            self.coarse.apply(self.g, self.c2)
            self.c2.aypx(-1.0, self.c)
            self.W.multAdd(self.c2, self.v, y)                 # y = v + W (c1 - E^-1 (A W)^T v)
            return
        self.C.mult(self.c, self.t)
        self.t.aypx(-1.0, x)                                   # x - C c1
        B.apply(self.t, self.v)                                # s = B (x - C c1)
        self.C.multTranspose(self.v, self.g)
        self.F.mult(self.c, self.c2)
        self.g.axpy(-1.0, self.c2)                             # C^T s - W^T C c1
        self.coarse.apply(self.g, self.c2)
        self.c2.scale(-1.0)
        self.W.multAdd(self.c2, self.v, y)                     # y = s - W E^-1 (C^T s - W^T C c1)

    def presolve(self, ksp, b, x, stale=False):
        """Start the deflated form on W^T r0 = 0: x0 += Q (b - A x0). Returns the KSP's initial-guess flag when
        this changed it, else None. Under 'auto' the solve takes the balanced form when the KSP needs a symmetric
        M or the preconditioner is ``stale`` (reused on new values: D B = I no longer holds for A)."""
        kind = ksp.getType()
        if self.cfg.form == "auto":
            self._auto = "balanced" if kind in SYMMETRIC_KSPS or stale else "deflated"
            if self._auto == "balanced":
                self._need_F()
        if self.form(kind) != "deflated" or kind == PETSc.KSP.Type.PREONLY:
            return None
        nonzero = ksp.getInitialGuessNonzero()
        if nonzero:
            self.mat.mult(x, self.t)
            self.t.aypx(-1.0, b)
        else:
            b.copy(self.t)
            x.set(0.0)
        nsp = ksp.getOperators()[0].getTransposeNullSpace()
        if nsp:                       # KSPSolve projects b only after this call: start on the projected residual
            nsp.remove(self.t)
        self.W.multTranspose(self.t, self.g)
        self.coarse.apply(self.g, self.c)
        self.W.multAdd(self.c, x, x)
        ksp.setInitialGuessNonzero(True)
        return nonzero

    def _need_F(self):
        """F = W^T C, which the balanced form with exact leaves needs (made on first use, then kept up to date)."""
        if self.F is None and self.leafsolver.exact:
            self.F = self.W.transposeMatMult(self.C)

    # ------------------------------------------------------------------ checks and views
    def check(self, probes=0) -> str:
        """Empty when every factorisation succeeded, the coarse space is finite and ``probes`` random Rayleigh
        quotients of the balanced M are positive, else why not (collective)."""
        bad = []
        for name, pc in (("leaf", self.leafsolver.pc), ("Neumann", self.S_factor), ("coarse", self.coarse)):
            if pc is not None and pc.getFailedReason() != PETSc.PC.FailedReason.NOERROR:
                bad.append(f"{name} factorisation failed ({pc.getFailedReason()})")
        if not np.all(np.isfinite(self.w_values)):
            bad.append("the coarse space is not finite")
        if self.coll.sum(1 if bad else 0) and not bad:
            bad.append("a factorisation failed on another rank")
        if bad or not probes:
            return "; ".join(bad)
        return rayleigh_reason(self._min_rayleigh(probes), "two-level")

    def _min_rayleigh(self, probes) -> float:
        """Smallest x^T M x / x^T x of the balanced (symmetric) M over random x."""
        self._need_F()
        x, y = self.mat.createVecs()
        rng = PETSc.Random().create(self.comm)
        self._forced = "balanced"
        quotients = []
        try:
            for _ in range(probes):
                x.setRandom(rng)
                self.mult(x, y)
                quotients.append(x.dot(y) / x.dot(x))
        finally:
            self._forced = None
            for obj in (x, y, rng):
                obj.destroy()
        return float(np.min(quotients))

    def apply_costs(self, reps=20) -> dict:
        """Milliseconds per call of each part of an application in the form in use, and of one MatMult of A
        (``matmult``), timed back to back over ``reps`` calls (collective)."""
        x, y = self.mat.createVecs()
        x.setRandom()
        exact, deflated = self.leafsolver.exact, self.form() == "deflated"
        parts = {"matmult": lambda: self.mat.mult(x, y), "leaf solve": lambda: self.leafsolver.apply(x, self.v),
                 "coarse solve": lambda: self.coarse.apply(self.g, self.c),
                 "thin products": lambda: (self.C.multTranspose(self.v, self.g) if exact and deflated else
                                           self._thin_balanced(x, exact, deflated), self.W.multAdd(self.c, self.v, y)),
                 "apply": lambda: self.mult(x, y)}
        out = {}
        for name, call in parts.items():
            call()
            t0 = time.perf_counter()
            for _ in range(reps):
                call()
            out[name] = 1e3 * (time.perf_counter() - t0) / reps
        if not deflated:
            out["coarse solve"] *= 2
        x.destroy()
        y.destroy()
        return out

    def _thin_balanced(self, x, exact, deflated):
        """The thin products of an application other than the exact deflated one, but W's (for timing)."""
        self.W.multTranspose(x, self.g)
        other = self.C if exact else self.AW
        if not deflated:
            other.mult(self.c, self.t)
        other.multTranspose(self.v, self.g)
        if exact and not deflated:
            self.F.mult(self.c, self.c2)

    @property
    def nbytes(self) -> int:
        """Bytes held on this rank: D and its factor, W, C, the coarse operator and its factor (8 bytes a value)."""
        mats = [m for m in (self.W, self.C, self.E, self.F, self.AW) if m is not None]
        if self.S is not None:
            mats += [self.S, self.S_factor.getFactorMatrix()]
        held = sum(m.getInfo()["nz_used"] for m in mats) + self.leafsolver.nnz() + _held(self.coarse)
        return int(8 * held)

    def describe(self) -> list:
        """Short lines for ``-ksp_view``."""
        lay, t, cfg = self.lay, self.times, self.cfg
        lv = lay.leaves
        kept = self.kept if self.kept is not None else self.ncols
        q = (f"{kept.min()}-{kept.max()} per leaf (mean {kept.mean():.2f})" if kept.min() != kept.max()
             else f"{kept.min()} per leaf")
        n = self.mat.getSize()[0]
        auto = f" ({' and '.join(self.auto)} by the problem: {self.dim}-D)" if self.auto else ""
        size = f"mean {lv.sizes.mean():.1f} rows" if lv.kind == "aggregation" else f"L={cfg.leaf}"
        lone = self.coll.sum(int(lay.decoupled.sum()))
        shape = [f"{self.shape.describe()} (this rank's rows)"] if self.shape is not None else []
        return shape + [
                f"leaves: {lv.kind}, {size}{auto}, {self.coll.sum(lv.n_leaves)} in all ({lv.n_leaves} on this rank), "
                f"sizes {lv.sizes.min()}-{lv.max_size}; {self.n_pieces} pieces"
                + (f", {lone} of them decoupled rows (no coarse vector)" if lone else "")
                + f"; {self.leafsolver.describe()}",
                f"coarse: {cfg.coarse} ({COARSE_TEXT[cfg.coarse]}), {q}"
                + (f" (up to {self.extra} more where Ritz values are at most {cfg.tol:g} x the mean diagonal)"
                   if self.extra else "")
                + f"; global size {self.m}, {self.null_components} null component(s) left out"
                + (f"; space kept from {self.age} numeric setup{'s' if self.age > 1 else ''} ago" if self.age else ""),
                self._solver_text(),
                f"form: {self.form()} (" + ("y = v - W E^-1 C^T v, v = B x; started so that W^T r0 = 0"
                                            if self.form() == "deflated" else "symmetric balanced form") + ")",
                f"setup ms: analysis {self.analysis_ms:.1f} (once per pattern; leaves {lv.build_ms:.1f}); "
                + ", ".join(f"{k.replace('_', ' ')} {v:.1f}" for k, v in t.items()),
                "apply: float64 in PETSc (a linear operator to working precision: any KSP, any rtol)",
                f"memory on this rank: {self.nbytes / max(n // self.coll.size, 1):.0f} bytes per unknown"]

    def _solver_text(self) -> str:
        """The coarse solver, and why it was chosen."""
        kind = self.coarse.getType()
        if kind in ("gamg", "mg"):
            text = f"one {kind.upper()} V-cycle ({self.coarse.getMGLevels()} levels)"
        elif kind == "ksp":
            inner = self.coarse.getKSP()
            text = (f"{inner.getType().upper()} to rtol {inner.getTolerances()[0]:g} preconditioned by "
                    f"{inner.getPC().getType().upper()}")
        elif kind == "redundant":
            text = f"LU on each of the {self.coll.size} ranks (redundant)"
        else:
            text = kind.upper() if kind in FACTOR_PCS else kind
        why = ""
        if self.cfg.solver == "auto":
            limit = sizing.COARSE_DIRECT_MAX[self.dim]
            direct = f"direct up to {limit}" if limit else "always direct"
            why = f" (by the problem: {self.m} rows; {direct} in {self.dim}-D)"
        return f"coarse solve: {text}{why}; options -{self.coarse_prefix}*"

    def destroy(self):
        """Free every PETSc object (also of a construction that failed part of the way)."""
        if getattr(self, "_dense", None) is not None:
            self._free_dense()
        if getattr(self, "leafsolver", None) is not None:
            self.leafsolver.destroy()
        for name in ("S", "S_factor", "O", "W", "C", "E", "Eb", "F", "AW", "coarse", "v", "t", "_lift", "g", "c", "c2"):
            obj = getattr(self, name, None)
            if obj is not None:
                obj.destroy()
                setattr(self, name, None)
        self.leafsolver = None


def _held(pc) -> int:
    """Values a coarse solver holds on this rank besides its operator: a factor's, or a multigrid hierarchy's
    coarser operators and interpolations, also inside a PCKSP (0 for other PC types, such as PCREDUNDANT's
    gathered copy)."""
    kind = pc.getType()
    if kind == "ksp":
        return _held(pc.getKSP().getPC())
    if kind in FACTOR_PCS:
        return int(pc.getFactorMatrix().getInfo()["nz_used"])
    if kind not in ("gamg", "mg"):
        return 0
    levels = pc.getMGLevels()
    mats = [pc.getMGSmoother(level).getOperators()[0] for level in range(levels - 1)]
    mats += [pc.getMGInterpolation(level) for level in range(1, levels)]
    return int(sum(m.getInfo()["nz_used"] for m in mats))


def _folded_block(rows, start, n) -> sp.csr_matrix:
    """A rank's diagonal block with its couplings to other ranks added to the diagonal."""
    block = rows[:, start:start + n].tocsr()
    outside = np.asarray(rows.sum(axis=1)).ravel() - np.asarray(block.sum(axis=1)).ravel()
    block = (block + sp.diags(outside)).tocsr()
    block.sort_indices()
    return block
