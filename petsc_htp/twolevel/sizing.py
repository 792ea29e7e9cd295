"""The two-level method sized by the problem: its dimension and size pick the leaf size, coarse space, leaf
factor and coarse solver.

Chosen by time, one defaults sweep per dimension (``petsc-htp bench --studies defaults [--dim 3]``; README):

- A bare matrix (no coordinates): aggregation leaves (:mod:`petsc_htp.twolevel.aggregation`), whose size follows
  the graph, solved exactly; the dimension is what the graph shows (:mod:`petsc_htp.twolevel.graphshape`). In
  2-D with rows as sparse as a 5-point stencil's, few positive couplings or rows split at random over the ranks, the
  first pass's aggregates are paired and take the const space (:func:`aggregation`).
- 2-D: 32-row leaves, solved exactly (Cholesky), with the eig coarse space (r = 2).
- 3-D: an exact leaf factor fills in (separators grow as L^(2/3)), and the eig vectors cost more than
  they save: 64-row leaves solved by ICC(0), with the const coarse space (one vector per piece). The
  coarse operator's graph is 3-D too: nested dissection halves its LU's fill against QMD. A bare 3-D matrix's
  aggregation leaves are paired as well (:func:`aggregation`); their coarse operator, of N/10 rows, fills fast
  under an LU (2 289 rows of a 64 000-row DMDA matrix: 510 000 factor entries, 46 ms) and takes two GAMG
  V-cycles in the deflated form above :data:`COARSE_PAIRED_DIRECT_MAX_3D` rows (:func:`coarse_exact`). A coarse
  operator is ordered by nested dissection (:func:`coarse_options`); from :data:`COARSE_METIS_ROWS` rows its columns
  come ordered by METIS (:mod:`.coarseorder`).

The coarse operator is factored (LU, redundantly on every rank of a parallel matrix: PCREDUNDANT) while it
is small; in 2-D on several ranks above :data:`COARSE_REDUNDANT_MAX` rows (aggregation leaves), and on one
above :data:`COARSE_SCALAR_DIRECT_MAX` (aggregation leaves) or ``COARSE_DIRECT_MAX[2]``, two distributed GAMG
V-cycles replace the LU, taken by the deflated form (:func:`coarse_solver`). A 3-D coarse operator with more than
``COARSE_DIRECT_MAX[3]`` rows, whose LU grows superlinearly (N/64 rows at N in the millions), gets one GAMG
V-cycle instead; it makes a larger coarse space cheap, so the default leaves then shrink to :data:`LEAF_AMG` rows,
which keeps every frame within 40 iterations at 128^3 (sweeps over leaf size and coarse solver at 32^3 to 128^3:
LU wins at 4096 coarse rows, GAMG at 13824).

On one rank, a matrix whose bandwidth (its own order's or reverse Cuthill-McKee's) is at most :data:`BAND_WIDTH`
gets one banded Cholesky factor, LAPACK's (:mod:`.band`), among the small matrices and, bare, above them
(``petsc_htp.whole.WholeChoice._banded``; ``results/band-20261127``). Otherwise:
below :data:`DIRECT_MAX` rows one sparse Cholesky factor of the whole matrix (nested dissection) costs less
than the two-level setup: the foreign study's small-matrix sweep (``petsc-htp bench --studies foreign --methods
cg_htp_direct cg_htp_twolevel --foreign-scales 500 1000 2000 4000 8000 16000``; README) has the factor ahead up
to about 8000 rows in 2-D (15 against 21 ms at 7921) and 1000 in 3-D (3.5 against 4.9 ms; 12.5 against 6.8 at
2197), where its fill grows as N^(4/3). Where rows hold more than :data:`RICH_ROW` stored nonzeros (9-point
stencils, P1 triangles, anything 3-D) the exact factor's fill grows with them and ICC(0) of the whole matrix
with its CG iterations costs less (the same sweep with ``cg_icc``: a third to a seventh of the Cholesky time at
1000-8000 rows); on a bare 3-D matrix ICC(0) also beats the two-level method up to :data:`WHOLE_ICC_MAX` rows
(DMDA with coefficient jumps 1e3 to 1e10 and P1 tets: 8-13 against 18-20 ms at 20^3; at 25^3 a contrast of
1e10 already takes 198 ICC iterations, 47 against 36 ms). With coordinates attached, the project's multiphase
frames, the two-level method stays ahead (25.6 against 44.9 ms per frame at 32^3 in sequence mode).

A graph whose balls grow faster than any mesh's (growth exponent at least :data:`EXPANDER_GROWTH`, where meshes
give 1.6-2.7: a small-world network, such as a scale-free graph's Laplacian) gets ICC(0) of the whole matrix on one
rank at any size, on several ICC(0) of each rank's diagonal block (PCBJACOBI; the largest growth of the blocks
decides, or the whole graph's where a quarter of the couplings cross ranks: :mod:`.spread`): its coarse operator is
as small-world as the graph and costs more than it saves
(``results/expander-20261126/run.py``: Barabasi-Albert Laplacians + 0.01 I at 20 000-200 000 rows 25-205 against
124-2 737 ms of the two-level method, 14 against 18 iterations, GAMG 1.2-12.8 s up to 60 000; a random graph with
couplings of both signs at 20 000 and 60 000 rows 14 and 40 against 139 and 814 ms, 10 against 17 iterations;
``ranks.sh``: the scale-free graph on 2 ranks 95 and 199 against 2 058 and 40 679 ms at 60 000 and 200 000 rows,
the random graph of both signs 53 against 1 281 ms at 60 000).

Rows that are all diagonally dominant by a margin (a mass matrix plus a time step's stiffness) get ICC(0) of the
whole matrix at any size too, of each rank's block on several (:mod:`.dominance`).

On several ranks the same factor, of the whole matrix gathered on every rank (PCREDUNDANT), serves at the same
sizes, and wherever a rank owns no rows (the two-level method needs rows on every rank) up to :data:`REDUNDANT_MAX`
rows: ``mpiexec -n 2 python examples/dmda_poisson.py -n N -warmup`` with HTPPC as it comes (above 8 000 rows
``-htp_direct_max 100000``) against ``-htp_direct_max 0``, KSPSetUp + KSPSolve ms, 2026-11-26, 2 runs each: 2-D
(Cholesky) at 5 776 rows 24-26 against 33-125, 8 100 29-30 against 30-71, 12 100 33-105 against 35-37 (the
two-level method ahead); 3-D (``-dim 3``: 7 entries a row, ICC(0), 43-72 iterations) at 1 728 to 8 000 rows 8-21
against 25-115 ms.

PETSc-free (the fast path imports it).
"""
from __future__ import annotations

DIRECT_MAX = {2: 8000, 3: 1000}    # rows up to which one sparse Cholesky factor of the whole matrix is cheapest
WHOLE_ICC_MAX = {2: 8000, 3: 8000}  # bare matrices: rows up to which ICC(0) of the whole matrix beats the two-level
REDUNDANT_MAX = 8000                # a rank without rows: matrix rows up to which it is factored whole on every rank
RICH_ROW = 5.5                      # stored nonzeros per row above which ICC(0) replaces the small matrix's Cholesky
EXPANDER_GROWTH = 4.0               # ball growth exponent (graphshape) from which a graph is no mesh: ICC(0), any size
POSITIVE_MAX = 0.05                 # 2-D: share of positive off-diagonal couplings up to which rich rows are paired
SPLIT_PAIRED = 0.25                 # ... or share of couplings joining two ranks from which they are (a block falls
# apart there: .spread measures the whole graph's growth, .incomplete tries no ICC(0) for anisotropy)
LEAF = {2: 32, 3: 64}
COARSE = {2: "eig", 3: "const"}
EXACT_FACTOR = {"pc_type": "cholesky", "pc_factor_mat_ordering_type": "natural", "pc_factor_shift_type": "nonzero"}
FACTOR = {2: EXACT_FACTOR, 3: {**EXACT_FACTOR, "pc_type": "icc"}}
COARSE_FACTOR = {"pc_type": "lu", "pc_factor_shift_type": "nonzero"}   # ordered by coarse_options
COARSE_METIS_ROWS = 12000                   # coarse rows from which METIS orders the coarse columns
COARSE_METIS_SCALAR_ROWS = 40000            # ... where leaves take one column per piece (metis_ordered)
COARSE_DIRECT_MAX = {2: 400000, 3: 8192}    # coarse rows above which GAMG replaces the LU (coarse_solver)
COARSE_SCALAR_DIRECT_MAX = 131072           # ... one rank, 2-D aggregation leaves without near null vectors
COARSE_REDUNDANT_MAX = 16384                # 2-D on several ranks: coarse rows above which a V-cycle replaces the LU
COARSE_REDUNDANT_LU_MAX = 200000            # ... for Morton leaves and near null vectors, which keep the LU longer
SAFE_SMOOTHER = {"mg_levels_ksp_chebyshev_esteig": "0,0.1,0,1.5"}   # every coarse V-cycle's Chebyshev smoothers
# reach 1.5 x GAMG's estimate of the largest eigenvalue (PETSc's 1.1): on 3-D coefficient jumps of 1e6-1e10
# (scenes.foreign.cubes, 44^3 and 64^3 cells, the paired leaves' two V-cycles) the estimate fell short, the V-cycles'
# M went indefinite and CG stopped with DIVERGED_INDEFINITE_PC on 8 of 22 layouts; now none does (1.2 left 2 of them
# failing, 1.3 none). Elsewhere 0-2 more iterations. A better estimate (20 iterations in place of 10) mended the
# layouts too but took the foreign study's dmda3d at 262 144 rows from 29 to 39 iterations (results/jumps-20261127)
COARSE_AMG_2D = {"pc_type": "gamg", "pc_gamg_threshold": "0.02", "pc_gamg_aggressive_coarsening": "0",
                 "mg_levels_ksp_max_it": "2", "pc_mg_multiplicative_cycles": "2",
                 **SAFE_SMOOTHER}                                                    # two V-cycles, deflated form
# Chebyshev(2) on each level (PETSc's default; three served the one V-cycle of the balanced form before): the DMDA
# program's CG iterations stay (2 ranks: 1024^2 37, 2048^2 39, 512^2 36 against 35; one rank 2048^2 40) and the
# solve takes 0.86-0.93 of Chebyshev(3)'s at 1024^2 and 2048^2, as much at 512^2; the foreign study's free surface
# and log-normal matrices at 1M rows on 2 ranks: level (log-normal 42 against 40 iterations) (results/scale-20261126g);
# Chebyshev(1) took 42 iterations at 2048^2
LEAF_AMG = {2: 32, 3: 32}                   # default leaf size where the coarse solve at LEAF would be GAMG
COARSE_AMG = {"pc_type": "gamg", "pc_gamg_aggressive_coarsening": "0",  # plain aggregation: 3 fewer iterations
              **SAFE_SMOOTHER}
COARSE_AMG_3D = {"pc_type": "gamg", "pc_gamg_threshold": "0.02", **SAFE_SMOOTHER}   # aggregation leaves: balanced
COARSE_AMG_3D_PAIRED = {**COARSE_AMG_3D, "pc_mg_multiplicative_cycles": "2"}   # ... paired ones: two, deflated
COARSE_PAIRED_DIRECT_MAX_3D = 1536          # 3-D paired aggregation leaves: coarse rows from which GAMG serves
COARSE_NEAR_DIRECT_MAX_3D = 4096            # 3-D with near null vectors (a column per vector and leaf): the same
# (their coarse operator holds about 90 entries a row and its LU grows as the square of its rows): PETSc's snes ex17,
# P1 tetrahedra, rigid-body modes, 89 373 rows (4 807 coarse rows, LU fill 4.3M): 2.13 s setup + 0.43 solve (31
# iterations) with the LU against 1.02 + 0.50 (32) with GAMG's V-cycle, on 2 ranks 2.33 against 1.05 s setup; at
# 20 577 rows (1 183 coarse rows) level (30 iterations, 220 ms setup either way); examples/elasticity.py -dim 3 -side
# 40 (3 091 coarse rows, fill 1.8M) the LU 5.5 + 2.0 s (35) against 6.5 + 2.7 (39), side 32 (1 825) level
BAND_WIDTH = 112                            # one rank: RCM bandwidth up to which LAPACK's band factor serves
BAND_RCM_MAX = 32768                        # ... rows up to which a bare matrix's RCM order is tried (2.5 ms) ...
BAND_CHECK_MAX = 262144                     # ... and its own order (0.5 ms at 65 536 rows: a strip numbered across)
LINEAR_GROWTH = 1.25                        # ball growth exponent below which a graph is a chain (chain) ...
CHAIN_ROW = 3.5                             # ... whose rows hold at most this many stored entries on average


def coarse_space(dim, near, paired=False) -> str:
    """The coarse space by the problem: the piece constants alone once the operator brings ``near`` > 0 near null
    vectors of its own (block size, attached near null space: 2-D elasticity at 24k-180k rows, 3-4 more CG
    iterations and 25-45 % less setup than with the eig vector) or on leaves of ``paired`` aggregates (see
    :func:`aggregation`), else :data:`COARSE` by dimension."""
    return "const" if near or paired else COARSE[dim]


def aggregation(dim, near, per_row, coarse="auto", positive=1.0, attached=False, split=0.0) -> str:
    """The kind of the aggregation passes after the first (:mod:`.aggregation`): 'pairs' in 2-D where rows hold at
    most :data:`RICH_ROW` stored entries (5-point stencils), at most :data:`POSITIVE_MAX` of the sampled
    off-diagonal couplings are ``positive`` (a mesh Laplacian's rows) or the operator brings ``near`` > 0 near null
    vectors, and in 3-D but where a near null space is ``attached``; with the coarse space ``auto`` or ``const`` (an
    eig or learned space chosen by the user keeps the leaves it was measured on); else 'standard'. Elasticity
    (``results/elasticity-20261126a``): paired node aggregates took 33-38 against 46-49 iterations with the block
    size alone in 2-D and 0.8-0.9 times the time, 48-51 against 75-83 in 3-D (0.5-0.8 times); the rigid-body
    modes in 2-D 22-25 against 27-29 (0.8-0.9 times); in 3-D their seven columns per paired leaf passed the coarse
    LU's 8 192 rows at 150 000 rows, whose V-cycle then took 102 iterations (35 with standard leaves), and 26 once
    told the coarse near null space (:meth:`.coarsesolve.CoarseSolve._near_null`), in about the standard leaves'
    time (4.7 against 4.5 s): they stay. There leaves of paired aggregates (3-17 rows) with the const space
    cost less than standard ones (10-40 rows) with the eig space, in about the same CG iterations, as their coarse
    LU is scalar (the foreign study at 64k rows and ``examples/dmda_poisson.py`` at 512^2 and 1024^2, README); P1
    triangles at 16k-262k rows 12-20 % less time in 29-34 against 29-39 iterations, Q1 quadrilaterals (PyAMG's
    9-point FE stencil, 65 536 rows) 132 against 214 ms. Where a quarter or more of the couplings are positive
    (rotated anisotropy's 9-point stencils) the const space on paired leaves takes far more iterations (110-146
    against 40-61). In 3-D any bare matrix's aggregates are paired, rich rows too:
    with two coarse V-cycles (:func:`coarse_exact`) the foreign study's DMDA case took 25-29 against 33-41 CG
    iterations from 32^3 to 128^3 and 0.88-1.05 times the time (10.5 against 11.9 s at 128^3), and the P1 tets at
    64 000 rows 40 against 47 iterations and 461 against 468-500 ms (results/foreign-20261126c and -d, README).
    Where :data:`SPLIT_PAIRED` or more of the couplings join rows of two ranks (``split``: rows in a random order
    split by PETSc, a matrix file read as it is), each rank's block falls apart, standard leaves hold many pieces
    and the coarse operator couples each to leaves all over the other ranks: on 2 ranks at 65 536 rows the 45-degree
    anisotropy numbered at random took 310 s (standard leaves, eig space, 200 iterations) against 0.8 s paired (269
    iterations; GAMG 0.6 s, 90; ``results/rotated-20261127/split-before.txt`` and ``split.txt``). Only for leaves
    whose aggregation is chosen here: bare matrices, the coarse space auto or const (one chosen by the user keeps
    standard leaves, slow on such a split), not 3-D with a near null space attached."""
    if coarse not in ("auto", "const") or (dim == 3 and attached):
        return "standard"
    paired = dim == 3 or near or per_row <= RICH_ROW or positive <= POSITIVE_MAX or split >= SPLIT_PAIRED
    return "pairs" if paired else "standard"


def chain(growth: float, per_row: float) -> bool:
    """Whether a graph is a chain (a 1-D Laplacian's): its balls grow slower than :data:`LINEAR_GROWTH` (the largest
    ``growth`` over the ranks' diagonal blocks) and its rows hold at most :data:`CHAIN_ROW` stored entries. The
    growth alone is no proof: a rank's diagonal block of rows in a random order breaks into small pieces, whose
    balls barely grow (a shuffled 2-D grid on two ranks: 0.7-1.2)."""
    return bool(growth < LINEAR_GROWTH and per_row <= CHAIN_ROW)


def dimension(coords_dim, shape) -> int:
    """2 or 3: the attached coordinates' dimension, else what the graph showed (``shape``: a
    :class:`~petsc_htp.twolevel.graphshape.GraphShape`)."""
    if coords_dim is not None:
        return 3 if int(coords_dim) == 3 else 2
    return shape.dim


def whole_factor(dim: int, n: int, per_row: float, bare: bool):
    """The factor of the whole matrix that serves an ``n``-row matrix with ``per_row`` stored nonzeros per row in
    ``dim`` dimensions best, or None (the two-level method). A bare matrix (no coordinates) gets ICC(0) where rows
    are rich or the graph is 3-D (its fill stays that of A while the exact factor's grows with the couplings per
    row) up to :data:`WHOLE_ICC_MAX` rows, else a sparse Cholesky factor up to :data:`DIRECT_MAX`; a matrix with
    coordinates attached (the project's own frames) the Cholesky factor up to :data:`DIRECT_MAX` (see the module
    docstring). Sparse rows up to ``DIRECT_MAX[3]`` get the Cholesky factor in any dimension."""
    if n <= DIRECT_MAX[3] and per_row <= RICH_ROW:
        return "cholesky"
    if bare and (per_row > RICH_ROW or dim == 3):
        return "icc" if n <= WHOLE_ICC_MAX[dim] else None
    return "cholesky" if n <= DIRECT_MAX[dim] else None


def leaf_size(dim: int, n: int) -> int:
    """Default rows per leaf of an ``n``-row matrix in ``dim`` dimensions."""
    leaf = LEAF[dim]
    return LEAF_AMG[dim] if coarse_solver(dim, n // leaf, kind="morton") == "gamg" else leaf


def leaf_factor(dim: int, kind: str) -> dict:
    """The leaf factor's PETSc options (under ``<prefix>htp_leaf_``) in ``dim`` dimensions for leaves of ``kind``:
    aggregation leaves (10-40 rows) are factored exactly in any dimension."""
    return dict(EXACT_FACTOR if kind == "aggregation" else FACTOR[dim])


def coarse_solver(dim: int, rows: int, ranks: int = 1, kind: str = "aggregation", near: int = 0,
                  linear: bool = False, dense: bool = False) -> str:
    """'lu' or 'gamg' for a coarse operator of ``rows`` rows in ``dim`` dimensions on ``ranks`` ranks, of leaves of
    ``kind``. A 2-D LU grows faster than its rows and is redundant on several ranks (each factors the whole
    operator, and two ranks factoring at once slow each other down), so above :data:`COARSE_REDUNDANT_MAX` rows on
    several ranks and :data:`COARSE_SCALAR_DIRECT_MAX` on one (aggregation leaves), else above
    ``COARSE_DIRECT_MAX[2]`` on one, two distributed GAMG V-cycles (:data:`COARSE_AMG_2D`) replace it, in the
    deflated form (:func:`coarse_exact`). Morton leaves (the project's own frames, coordinates attached) keep the LU
    on several ranks up to :data:`COARSE_REDUNDANT_LU_MAX`: at 1M rows on 2 ranks (``examples/poisson_multiphase.py
    -n 1048576``, 65 536 coarse rows) the V-cycle took 34 against 22 iterations and 1.43-1.62 against 1.12-1.47 s
    (setup + solve, 4 runs each). ``examples/dmda_poisson.py -n N -warmup``, setup + solve ms (CG iterations),
    V-cycle against LU: two ranks, 512^2 586 (37) against 612-659 (36), 1024^2 2 418 (40) against
    4 415 (39), 2048^2 15 077 (42) against 25 235 (40); one rank, 1024^2 (107 718 coarse rows) 4 513 (40)
    against 4 376 (38), 2048^2 (430 000, the eig space) 23 505 (42) against 27 563 (40); with the paired
    aggregates' scalar coarse operator in METIS's order, 2048^2 (368 000 rows) 22 987 (44) against 20 724 (40),
    peak RSS 2.33 against 2.51 GB (GAMG tuned: 19 062 ms, 1.75 GB; results/scale-20261125g: 20 609 (44) against
    20 226 (40)), so the LU served up to 400 000. With two V-cycles in the deflated form (one rank, setup + solve,
    ``-htp_coarse_solver gamg`` against the LU, 2026-11-26): 1024^2 (91 629 coarse rows) 4 014 (37) against 3 915
    (37), 3 runs each; 1448^2 (about 184 000) 8 758 (38) against 9 817 (38), 2048^2 (368 000) 18 899 (40) against
    21 704 (40), 2 runs each, peak RSS 2.23 against 2.50 GB at 2048^2 (the LU's METIS order alone takes 2.1 s of its
    analysis there), so for aggregation leaves without near null vectors the LU serves up to
    :data:`COARSE_SCALAR_DIRECT_MAX` rows on one rank. An operator with ``near`` > 0 near null
    vectors of its own keeps the LU on several ranks too: GAMG's V-cycle does not know the coarse operator's near
    null space (2-D elasticity, 320k rows on 2 ranks, ``examples/elasticity.py -side 400``: 204-208 iterations).
    A ``linear`` graph (a chain, :func:`chain`) keeps the LU at any size: its
    coarse operator is a chain too, whose LU does not fill, and whose conditioning (1e9 at 16 000 coarse rows) the
    V-cycles did not meet: a 1-D Laplacian of 100 000 rows on 2 ranks ran to 5 000 iterations and one of
    1 000 000 on one rank to 1 000 (``DIVERGED_ITS``), against 6 each with the LU (1.7 s at 1M, GAMG 3.6). So does an
    operator with a ``dense`` row (:func:`.graphshape.hub_rows`: a constraint coupled to every row), whose coarse
    operator has one too: GAMG's setup on it did not end in 5 minutes at 1M rows (158 799 coarse rows;
    ``results/denserow-20261126``), where the LU, which takes the dense row last (:mod:`.coarseorder`, nested
    dissection), factors it in 1.5 s. A dense row is one with more than sqrt(N) entries (:func:`.graphshape.hub_rows`,
    :attr:`.structure.Structure.dense`)."""
    return "lu" if linear or dense or rows <= direct_limit(dim, ranks, kind, near) else "gamg"


def direct_limit(dim: int, ranks: int = 1, kind: str = "aggregation", near: int = 0) -> int:
    """Coarse rows up to which :func:`coarse_solver` factors the coarse operator: in 3-D
    :data:`COARSE_PAIRED_DIRECT_MAX_3D` for aggregation leaves, :data:`COARSE_NEAR_DIRECT_MAX_3D` with near null
    vectors, else ``COARSE_DIRECT_MAX[3]``; in
    2-D for aggregation leaves without near null vectors :data:`COARSE_SCALAR_DIRECT_MAX` on one rank and
    :data:`COARSE_REDUNDANT_MAX` on several, else ``COARSE_DIRECT_MAX[2]`` on one and
    :data:`COARSE_REDUNDANT_LU_MAX` on several (a redundant LU: every rank factors it whole)."""
    plain = kind == "aggregation" and not near
    if dim == 3:
        return COARSE_PAIRED_DIRECT_MAX_3D if plain else COARSE_NEAR_DIRECT_MAX_3D if near else COARSE_DIRECT_MAX[3]
    if ranks == 1:
        return COARSE_SCALAR_DIRECT_MAX if plain else COARSE_DIRECT_MAX[2]
    return COARSE_REDUNDANT_MAX if plain else COARSE_REDUNDANT_LU_MAX


def coarse_exact(dim: int, solver: str, kind: str = "aggregation", cycles=None, near: int = 0) -> bool:
    """Whether the coarse solve is exact enough for the deflated form: not a 'gamg' solve of the 3-D coarse operator of
    aggregation leaves (``kind``), one V-cycle, which only the balanced form takes well (with exact leaves it is
    applied through F = W^T C, which assumes E c1 = W^T x: with a V-cycle V it stays symmetric, and positive
    definite where V converges on its own, eigenvalues of V E in (0, 2), as GAMG's Chebyshev-smoothed cycle does):
    deflated, that V-cycle costs 1.3-3.4x the CG iterations (a bare 3-D DMDA matrix at 300 763 rows: 133 against 39
    with the coarse LU). Morton leaves' 3-D coarse operator keeps its V-cycle in the deflated form (the project's
    own frames). In 2-D the coarse solve is two V-cycles at threshold 0.02 (:data:`COARSE_AMG_2D`), exact enough for
    the deflated form, which then takes one coarse solve an application where the balanced form takes two: the DMDA
    program on 2 ranks (``mpiexec -n 2 python examples/dmda_poisson.py -n N -warmup``), setup + solve ms
    (iterations), against one V-cycle in the balanced form (both with Chebyshev(3) then): 512^2 460-475 against
    488-557 (35 either way), 1024^2 1 868 (37) against 2 331 (37), 2048^2 11 523 (39) against 13 691 (40); one
    V-cycle deflated took 41 and 44 iterations at 1024^2 and 2048^2. On one rank at 2048^2 with the standard leaves
    (430 000 coarse rows) 16 761 against 18 216 ms, 42 iterations either way. The 3-D coarse operator of paired
    aggregation leaves (``near`` = 0) takes two V-cycles in the deflated form too (:data:`COARSE_AMG_3D_PAIRED`): as
    many CG iterations as under its LU (25 at 32^3 and 64 000 rows), and at 128^3 27 in 9.3 s against one V-cycle's
    balanced form, 27 in 12.4 s (``-htp_aggregation pairs``, one run each). ``cycles``: the GAMG PC's V-cycles an
    application (None: the defaults' for ``dim``, ``kind`` and ``near``); one alone stays in the balanced form."""
    if solver != "gamg":
        return True
    if dim == 3 and kind != "aggregation":
        return True
    if cycles is None:
        cycles = int(coarse_options(dim, False, "gamg", kind, near=near).get("pc_mg_multiplicative_cycles", 1))
    return cycles >= 2


def metis_ordered(solver: str, dim: int, rows: int, ranks: int = 1, kind: str = "aggregation", near: int = 0,
                  block: int = 2, linear: bool = False, dense: bool = False) -> bool:
    """Whether the coarse columns get METIS's order (:mod:`.coarseorder`): a coarse LU ('lu', or 'auto' choosing
    it for leaves of ``kind`` and ``near`` near null vectors) of at least :data:`COARSE_METIS_ROWS` rows whose
    leaves take ``block`` > 1 columns per piece, or :data:`COARSE_METIS_SCALAR_ROWS` rows of one column per piece
    (the const space), which PETSc's own nested dissection orders as well up to about that size
    (``examples/dmda_poisson.py -n N -warmup``, 3 runs each, setup + solve ms against that ordering: 512^2, 23 000
    coarse rows, METIS 769-807 against 742-825; 768^2, 52 000, 1 872-2 070 against 1 997-2 044; 1024^2, 92 000,
    3 734-3 762 against 3 804-3 837, an LU of 6.1 against 8.3 million values). Not on several ranks with a
    ``dense`` row: each rank orders its own leaves, so the dense row's would sit amid the gathered operator's columns
    (PETSc's nested dissection of the whole takes one last); on one rank at any size with one (PETSc's took three,
    each a hub coupled to a fifth of a 200^2 grid's rows, into a 6 559-row LU of 31 s)."""
    lu = solver == "lu" or (solver == "auto" and coarse_solver(dim, rows, ranks, kind, near, linear, dense) == "lu")
    return (lu and not linear and not (dense and ranks > 1)
            and (dense or rows >= (COARSE_METIS_ROWS if block > 1 else COARSE_METIS_SCALAR_ROWS)))


def coarse_options(dim: int, parallel: bool, solver: str, kind: str = "", ordered=False, near: int = 0) -> dict:
    """The coarse solver's PETSc options (under ``<prefix>htp_cs_``): ``solver`` 'lu' (a sparse factor) or
    'gamg' (V-cycles whose interpolation new values of E keep, as PETSc's GAMG does, unless the couplings moved
    under kept leaves: :attr:`.coarsesolve.CoarseSolve.renew`)
    in ``dim`` dimensions: two V-cycles an application in the deflated form in 2-D (:data:`COARSE_AMG_2D`) and on
    paired 3-D aggregation leaves (:data:`COARSE_AMG_3D_PAIRED`); one in the balanced form on the 3-D coarse operator
    of aggregation leaves with near null vectors (:data:`COARSE_AMG_3D`) and in the deflated form on Morton leaves'
    (:data:`COARSE_AMG`; :func:`coarse_exact`). Threshold 0.02 on aggregation leaves' coarse operators: on the bare
    3-D DMDA program (``examples/dmda_poisson.py -dim 3 -n 100 -warmup``, one V-cycle then) it keeps the 41
    iterations of a GCR to rtol 1e-3 around GAMG in the deflated form and takes 4.9 against 8.0 s (threshold 0: 84
    iterations, 0.1: 53); on 2 ranks at 2048^2 (``mpiexec -n 2 python examples/dmda_poisson.py -n 2048 -warmup``,
    the paired aggregates' 368 000 coarse rows, one V-cycle with Chebyshev(3) then) 0.01-0.03 takes 40 outer
    iterations and 13.1-14.6 s, 0.05 46 and 15.1 s (threshold 0: 94 iterations, 0.1: 100); at 1024^2 37 against 38
    iterations. The coarse LU is ordered by nested dissection: on bare 2-D DMDA matrices (``examples/dmda_poisson.py``)
    QMD and ND tie at 42 430 and 61 100 coarse rows (640^2 and 768^2: 356/358 and 642/636 ms) and ND factors 107 000
    rows (1024^2) in 1317 against 1631 ms; below, the foreign study's 2-D matrices at 16k and 64k rows (1 300-8 400
    coarse rows) and the own frames in sequence mode tie within 1-5 % either way, but a dense row (a constraint
    coupled to every row of a 64k DMDA matrix) took QMD 472 ms against ND's 42 (natural: 331 s). A coarse operator
    whose columns came ``ordered`` (:mod:`.coarseorder`) keeps its order."""
    if solver == "gamg":
        if dim == 2:
            return dict(COARSE_AMG_2D)
        if kind != "aggregation":
            return dict(COARSE_AMG)
        return dict(COARSE_AMG_3D if near else COARSE_AMG_3D_PAIRED)
    opts = {**COARSE_FACTOR, "pc_factor_mat_ordering_type": "natural" if ordered else "nd"}
    return {"pc_type": "redundant", **{"redundant_" + k: v for k, v in opts.items()}} if parallel else opts
