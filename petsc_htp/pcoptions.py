"""HTPPC's options: one small dataclass read from a PETSc options prefix (``<prefix>htp_*``)."""
from __future__ import annotations

import math
from dataclasses import dataclass, fields

from .training import checkpoint
from .variants import VARIANTS

ORDERINGS = ("auto", "aggregation", "morton", "graph", "rcm", "natural", "metis")
COARSE = ("auto", "const", "eig", "learned")
COARSE_SOLVERS = ("auto", "lu", "gamg")
AGGREGATIONS = ("auto", "standard", "pairs")
FALLBACKS = ("none", "jacobi")
FORMS = ("auto", "deflated", "balanced")

# Fields whose change needs a new analysis (ordering, partition), or may switch between the two-level method and a
# small matrix's whole-matrix factor (form, coarse_space_every); the others only a numeric step.
PATTERN_FIELDS = ("variant", "checkpoint", "device", "ordering", "aggregation", "leaf", "coarse", "coarse_checkpoint",
                  "coarse_rank", "coarse_tol", "overlap", "coarse_solver", "direct_max", "form", "coarse_space_every",
                  "block_size")

HELP = {
    "variant": "paper (the paper's H-matrix M), twolevel (exact leaf solves + coarse space, SPD, float64) or "
               "multilevel (V-cycles on an aggregation hierarchy of leaves; options -htp_ml_*)",
    "checkpoint": "HTP checkpoint file (empty: the shipped petsc_htp/checkpoints/htp_default.pt)",
    "device": "torch device for the network and the apply: cpu, cuda[:k] or auto",
    "ordering": "auto (Morton with coordinates, else RCM for paper and aggregation for twolevel), aggregation "
                "(twolevel: aggregates of aggregates of A's strong couplings; their size follows the graph), morton, "
                "rcm, natural, graph (twolevel: Morton leaves of coordinates found by breadth-first search in A's "
                "graph, METIS when that graph is not 2-D-like) or metis (twolevel)",
    "aggregation": "twolevel aggregation leaves only: the passes after the first, auto (pairs, with the const "
                   "space, where -htp_coarse is auto or const: in 3-D unless a near null space is attached, and in "
                   "2-D where rows hold at most 5.5 entries on average, at most 5% of the couplings are positive, or "
                   "there is a block size (the Mat's, -htp_block_size or one found in the pattern) or near null space; "
                   "else standard), standard (aggregates of "
                   "aggregates: 10-40 rows) or pairs (aggregates matched in pairs: 3-17 rows)",
    "block_size": "twolevel: unknowns per node (leaves hold whole nodes, each component's constant is a coarse "
                  "vector); 0: the Mat's block size, else 6, 4, 3 or 2 where the nonzero pattern comes in such "
                  "nodes on every rank (-ksp_view says so), else 1",
    "leaf": "twolevel: rows per leaf; 0: by the problem (32 in 2-D; 64 in 3-D, 32 above N = 524288, where the "
            "coarse solve is GAMG); the paper's leaf size is the network's",
    "coarse": "twolevel coarse space: auto (eig in 2-D, const on paired aggregates; const, with ICC(0) leaf solves, "
              "in 3-D; const where there is a block size or a near null space, whose vectors every leaf takes "
              "too), const (r=1), eig (local Neumann eigenvectors) or learned (network)",
    "coarse_checkpoint": "twolevel learned coarse space: network file (empty: the shipped coarse_default.pt)",
    "coarse_rank": "twolevel: coarse vectors per leaf r: each piece's constant and r - 1 more (eig; learned takes "
                   "the network's r)",
    "coarse_tol": "twolevel eig/learned: r more candidates per leaf go through the same step; a leaf keeps those "
                  "whose Ritz value is at most tol x its mean diagonal (0: exactly r per leaf)",
    "coarse_solver": "twolevel: auto (LU; in 3-D two GAMG V-cycles once the coarse operator of paired "
                     "aggregation leaves has more than 1536 rows, one once one with near null vectors has more "
                     "than 4096 or another more than 8192, in 2-D two "
                     "once it has more than 400000, for a bare matrix's aggregation leaves 131072, "
                     "16384 on several ranks, or where their coarse graph grows as no mesh's), lu (redundant on "
                     "more than one rank) or gamg; -htp_cs_* options "
                     "configure it",
    "coarse_space_every": "twolevel: compute the coarse space at every k-th numeric setup; the ones between keep it "
                          "and refresh A W, W^T A W and the leaf factor (like -pc_gamg_reuse_interpolation); 0: "
                          "keep it while it serves, at most 4 setups and while the last solve took at most 1.25 x "
                          "+ 2 the iterations of the first with it",
    "form": "twolevel: auto (deflated; balanced under a KSP that needs a symmetric M, with one GAMG V-cycle "
            "on aggregation leaves, V-cycles whose forward error on a probe is above 0.4 or any under -htp_overlap), "
            "deflated (one coarse solve per apply, started so that W^T r0 = 0) or balanced (symmetric, two coarse "
            "solves)",
    "overlap": "twolevel: 0 for exact leaf solves, k > 0 for additive Schwarz on leaves grown by k layers of "
               "neighbours within each rank (the forms then go through A W)",
    "direct_max": "twolevel: with no other twolevel option set, one factor of the whole matrix replaces the two-level "
                  "method where it is cheaper, on several ranks gathered on every rank (-1: by measurement, "
                  "petsc_htp.twolevel.sizing.whole_factor: sparse Cholesky up to 8000 rows in 2-D and 1000 in 3-D, "
                  "for a bare matrix with richer rows or a 3-D graph ICC(0) up to 8000, and at any size ICC(0) "
                  "(of each rank's block on several ranks) for diagonally dominant rows or, bare, a graph that is no "
                  "mesh, and where a trial confirms it for anisotropic (rotated or along the grid), wide or shifted "
                  "rows; on one rank one banded Cholesky factor (LAPACK) where the bandwidth is at most 112, up to "
                  "8000 rows or, bare, in RCM order up to 32768 and in its own up to 262144 (a chain's at any size, "
                  "on several ranks gathered); "
                  "n >= 0: sparse Cholesky up to n rows; 0: "
                  "never); whatever the options where a rank owns no rows, up to 8000 rows (above: HTPPC on the ranks "
                  "that own rows, PCTELESCOPE, options -htp_telescope_htp_*)",
    "shift": "paper: add shift * D^-1 to M (SPD safety margin)",
    "spd_guard": "paper: Lanczos estimate of lambda_min(D^1/2 M D^1/2) at setup; if < 0, shift M to SPD",
    "threads": "BLAS, OpenMP and torch threads of this process (set process-wide at setup; -ksp_view says so; 1 "
               "suits one MPI rank per core)",
    "fallback": "none or jacobi: apply D^-1 when M is non-finite or found indefinite at setup",
    "probe": "random Rayleigh-quotient probes of M at setup (0: skip the check; -1: 4 for paper, 0 for twolevel, "
             "SPD by construction, whose factorisations are checked instead)",
}

MULTILEVEL_HELP = (    # read by petsc_htp.multilevel.setup.MultilevelPC (with PCMG's own under the same prefix)
    ("coarse_max", "int", 5000, "rows of the coarsest operator, factored once (1000 on a 3-D graph)"),
    ("max_levels", "int", 12, "levels at most, the coarsest included"),
    ("jacobi", "real", 1.4, "the coarse vectors' Jacobi step, over the Gershgorin bound of D^-1 A"),
    ("damping", "real", 1.5, "the largest eigenvalue of s M^-1 A the smoothers' Richardson scale s takes, in (0, 2) "
     "(M: D, or the leaf blocks; Gauss-Seidel unscaled)"),
    ("smoother", "string", "auto", "gs (a Gauss-Seidel sweep of each rank's rows, forward down, backward up), "
     "jacobi (D^-1) or leaves (the leaf blocks' exact solves); auto: gs on a 2-D graph or a "
     "3-D one with at most 5% of its couplings positive, else leaves"),
    ("reorder", "bool", "auto", "each rank's rows in their leaves' order; auto: where some rank's rows are not "
     "numbered locally"))


@dataclass(frozen=True)
class HTPOptions:
    """The ``-htp_*`` options of one HTPPC (defaults as shown by ``-help``)."""

    variant: str = "twolevel"
    checkpoint: str = ""
    device: str = "auto"
    ordering: str = "auto"
    aggregation: str = "auto"
    leaf: int = 0
    block_size: int = 0
    coarse: str = "auto"
    coarse_rank: int = 2
    coarse_checkpoint: str = ""
    coarse_tol: float = 0.0
    coarse_solver: str = "auto"
    coarse_space_every: int = 0
    form: str = "auto"
    overlap: int = 0
    direct_max: int = -1
    shift: float = 0.0
    spd_guard: bool = True
    threads: int = 1
    fallback: str = "none"
    probe: int = -1

    @classmethod
    def from_petsc(cls, prefix: str) -> "HTPOptions":
        """Read and validate ``-<prefix>htp_*`` from PETSc's options database."""
        from petsc4py import PETSc

        lead = (prefix + "htp_").lower()
        if not any(name.lower().startswith(lead) for name in PETSc.Options().getAll()):
            return _DEFAULTS        # none set: the defaults, without a PETSc call per option
        db = PETSc.Options(prefix + "htp_")
        get = {str: db.getString, float: db.getReal, int: db.getInt, bool: db.getBool}
        values = {f.name: get[type(f.default)](f.name, f.default) for f in fields(cls)}
        return cls(**values).validate("-" + prefix + "htp_")

    def validate(self, opt: str = "-htp_") -> "HTPOptions":
        """Raise ValueError naming the first bad option."""
        for name, allowed in (("variant", VARIANTS), ("ordering", ORDERINGS), ("coarse", COARSE),
                              ("coarse_solver", COARSE_SOLVERS),
                              ("aggregation", AGGREGATIONS),
                              ("fallback", FALLBACKS), ("form", FORMS)):
            if getattr(self, name) not in allowed:
                raise ValueError(f"{opt}{name} {getattr(self, name)!r} unknown; use one of {', '.join(allowed)}")
        if self.device not in ("auto", "cpu", "cuda") and not self.device.startswith("cuda:"):
            raise ValueError(f"{opt}device {self.device!r} unknown; use cpu, cuda or auto")
        for name in ("shift", "coarse_tol"):
            if not math.isfinite(getattr(self, name)) or getattr(self, name) < 0:
                raise ValueError(f"{opt}{name} must be a finite non-negative number, got {getattr(self, name)}")
        if self.leaf == 1 or self.leaf < 0:
            raise ValueError(f"{opt}leaf must be 0 (by the problem) or >= 2, got {self.leaf}")
        for name, low in (("threads", 1), ("coarse_rank", 1), ("coarse_space_every", 0), ("probe", -1),
                          ("overlap", 0), ("direct_max", -1), ("block_size", 0)):
            if getattr(self, name) < low:
                raise ValueError(f"{opt}{name} must be >= {low}, got {getattr(self, name)}")
        if self.variant == "paper" and self.ordering in ("metis", "graph", "aggregation"):
            raise ValueError(f"{opt}ordering {self.ordering} needs {opt}variant twolevel (the paper's leaves are "
                             "contiguous blocks of one ordering)")
        return self

    @property
    def plain(self) -> bool:
        """Whether no option of the two-level method is set: its choices (a factor of the whole matrix, the multilevel
        V-cycles) then follow the problem."""
        return (self.leaf, self.ordering, self.aggregation, self.coarse, self.coarse_solver, self.overlap,
                self.coarse_tol, self.coarse_rank, self.form, self.coarse_space_every, self.block_size) == (
            0, "auto", "auto", "auto", "auto", 0, 0.0, 2, "auto", 0, 0)

    @property
    def probes(self) -> int:
        """Rayleigh probes at setup: ``probe``, or the variant's default for -1."""
        return self.probe if self.probe >= 0 else {"paper": 4}.get(self.variant, 0)

    def pattern_key(self) -> tuple:
        """The options a new analysis depends on."""
        return tuple(getattr(self, name) for name in PATTERN_FIELDS)

    def help_text(self, opt: str) -> str:
        """``-help``'s text for options that start with ``opt``: a heading, then per option its type, current
        value, default and meaning."""
        out = [f"HTPPC options (prefix {opt}; default: the two-level preconditioner, no network; "
               "-htp_variant paper: the paper's Hierarchical Transformer Preconditioner) -----"]
        for f in fields(self):
            now, default = getattr(self, f.name), f.default
            if f.name == "checkpoint":
                now, default = now or checkpoint.DEFAULT, checkpoint.DEFAULT
            if f.name == "coarse_checkpoint":
                now, default = now or "shipped", "shipped"
            kind = {str: "string", float: "real", int: "int", bool: "bool"}[type(f.default)]
            out.append(f"  {opt}{f.name} <{kind}> <now {now} : formerly {default}>: {HELP[f.name]} (HTPPC)")
        out += [f"  {opt}ml_{name} <{kind}> <default {default}>: {text} (HTPPC multilevel)"
                for name, kind, default, text in MULTILEVEL_HELP]
        return "\n".join(out)


_DEFAULTS = HTPOptions().validate()      # every option at its default
