"""The preconditioner variants behind HTPPC, each a two-step setup: analysis (pattern) and numeric (values).

A variant is a class constructed from :class:`~petsc_htp.pcoptions.HTPOptions` and the PC's
options prefix, with

- ``analyse(mat, A, coords)``: the per-pattern step (ordering, leaves, structure) on the PETSc Mat
  and ``A``, this rank's rows as scipy CSR, returning an object with ``analysis_ms``;
- ``numeric(analysis, mat, A, density, previous)``: the per-values step, returning the setup object
  (``check(probes)``, ``describe()``, ``nbytes``); ``previous`` is the last setup of the same
  analysis, whose buffers it may reuse;
- ``apply(setup, x, y)``: y = M x on PETSc Vecs;
- ``presolve(setup, ksp, b, x, stale)``: called before each KSPSolve (``stale``: the setup is reused on
  an operator whose values changed since); returns the KSP's initial-guess flag when it changed it
  (restored after the solve), else None;
- ``moved(analysis, A)``: whether new values of the same pattern call for a new analysis (leaves that follow
  the couplings, once the couplings moved);
- ``destroy(analysis)``: free what the analysis and its setups hold;
- ``model``: a line naming the model, or None.

A new variant is one class here and its name in :data:`VARIANTS`.
"""
from __future__ import annotations

from .twolevel import coarsenet, composed as twolevelpc, sizing
from .twolevel.direct import DirectPC
from .twolevel.graphshape import graph_shape
from .checkpoint import DEFAULT
from .paper.inference import HTP


class Paper:
    """The paper's HTP: the network emits the H-matrix factors of M (float32 apply); one rank."""

    def __init__(self, opts, prefix=""):
        self.opts = opts
        self.htp = HTP.cached(opts.checkpoint or None, opts.device)
        cfg = self.htp.net.cfg
        self.model = (f"d={cfg.d}, n_l={cfg.n_layers}, L={cfg.leaf}, L_s={cfg.coarse}, heads={cfg.heads}, "
                      f"highways={'yes' if cfg.highways else 'no'}; {self.htp.net.n_params()} parameters; "
                      f"device {self.htp.device}; checkpoint {opts.checkpoint or 'shipped ' + str(DEFAULT)}")

    def analyse(self, mat, A, coords):
        """Ordering, partition and structural features."""
        if mat.getComm().getSize() > 1:
            raise ValueError(
                f"-htp_variant paper needs a sequential matrix but got a parallel '{mat.getType()}' matrix on "
                f"{mat.getComm().getSize()} ranks; use -htp_variant twolevel (a global coarse space), or "
                "precondition each rank's block with -pc_type bjacobi -sub_pc_type python "
                "-sub_pc_python_type petsc_htp.HTPPC")
        if coords is not None and coords.shape[1] != 2:
            raise ValueError(
                f"-htp_variant paper is 2-D only: its network was trained on 2-D scenes and reads 2-D cell "
                f"coordinates (its features and quadtree partition), but {coords.shape[1]}-D coordinates are "
                "attached; use -htp_variant twolevel (the default), which takes 3-D problems")
        return self.htp.analyse(A, coords, self.opts.ordering)

    def numeric(self, analysis, mat, A, density, previous):
        """Network, factors and SPD guard."""
        return self.htp.numeric(analysis, A, density, self.opts.shift, self.opts.spd_guard, into=previous)

    @staticmethod
    def apply(setup, x, y):
        """y = M x through the float32 torch apply."""
        y.array_w[...] = setup.apply(x.array_r)

    @staticmethod
    def presolve(setup, ksp, b, x, stale):
        """Nothing to do before a solve."""
        return None

    @staticmethod
    def moved(analysis, A) -> bool:
        """The analysis depends on the pattern only."""
        return False

    @staticmethod
    def destroy(analysis):
        """Nothing to free: torch tensors go with their Python objects."""


class TwoLevel:
    """Exact leaf solves, a coarse space per leaf and its exact Galerkin operator (float64), from PETSc parts
    (:mod:`petsc_htp.twolevel.composed`), on any number of ranks. The analysis object is the setup: its numeric
    step refreshes it in place."""

    model = None

    def __init__(self, opts, prefix=""):
        self.opts, self.prefix = opts, prefix
        self.net = None
        if opts.coarse == "learned":
            self.net, prov = coarsenet.cached(opts.coarse_checkpoint or None)
            self.model = (f"coarse network {self.net.n_parameters()} parameters, r={self.net.cfg.rank}; "
                          f"checkpoint {opts.coarse_checkpoint or 'shipped ' + str(coarsenet.DEFAULT)}")

    def config(self) -> twolevelpc.Config:
        """The two-level configuration from the options."""
        o = self.opts
        return twolevelpc.Config(o.leaf, o.ordering, o.coarse, o.coarse_rank, o.coarse_tol, o.form, o.overlap,
                                 o.coarse_solver)

    def analyse(self, mat, A, coords):
        """Leaves, index maps, components and every matrix with its pattern (see :class:`twolevelpc.TwoLevelPC`)."""
        if self.net is not None and coords is not None and coords.shape[1] != 2:
            raise ValueError(
                f"-htp_coarse learned is 2-D only: the coarse network's features are 2-D cell coordinates and "
                f"it was trained on 2-D scenes, but {coords.shape[1]}-D coordinates are attached; use "
                "-htp_coarse eig (the default) or const")
        if self.direct(mat, A, coords):
            return DirectPC(mat, A, self.config(), self.prefix + "htp_")
        return twolevelpc.TwoLevelPC(mat, A, coords, self.config(), self.prefix + "htp_", self.net)

    def direct(self, mat, A, coords) -> bool:
        """Whether one sparse factor serves ``mat`` (this rank's rows ``A``): one rank, no two-level option set, and
        at most ``-htp_direct_max`` rows, or with -1 :data:`sizing.DIRECT_MAX` rows of its dimension."""
        o = self.opts
        plain = (o.leaf, o.ordering, o.coarse, o.coarse_solver, o.overlap, o.coarse_tol, o.coarse_rank, o.form,
                 o.coarse_space_every) == (0, "auto", "auto", "auto", 0, 0.0, 2, "auto", 1)
        n = mat.getSize()[0]
        if mat.getComm().getSize() > 1 or not plain or n > max(o.direct_max, *sizing.DIRECT_MAX.values()):
            return False
        if o.direct_max >= 0:
            return n <= o.direct_max
        if n <= min(sizing.DIRECT_MAX.values()):
            return True
        shape = graph_shape(A) if coords is None else None
        return n <= sizing.DIRECT_MAX[sizing.dimension(None if coords is None else coords.shape[1], shape)]

    def numeric(self, analysis, mat, A, density, previous):
        """New values; the coarse space is kept between refreshes (``-htp_coarse_space_every``)."""
        keep = previous is not None and previous.age + 1 < self.opts.coarse_space_every
        analysis.cfg = analysis.resolved(self.config())
        analysis.numeric(A, density, keep_space=keep)
        return analysis

    @staticmethod
    def moved(analysis, A) -> bool:
        """Whether the new values ``A`` moved away from the leaves (a new analysis follows them)."""
        return analysis.moved(A)

    @staticmethod
    def apply(setup, x, y):
        """y = M x in PETSc."""
        setup.mult(x, y)

    @staticmethod
    def presolve(setup, ksp, b, x, stale):
        """The deflated form's start (x0 += Q r0); returns the KSP's guess flag to restore, or None."""
        return setup.presolve(ksp, b, x, stale)

    @staticmethod
    def destroy(analysis):
        """Free the PETSc objects."""
        analysis.destroy()


VARIANTS = {"paper": Paper, "twolevel": TwoLevel}
