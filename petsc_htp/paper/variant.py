"""The paper's variant behind ``-htp_variant paper``: the network emits the H-matrix factors of M (torch)."""
from __future__ import annotations

from ..training.checkpoint import DEFAULT
from .inference import HTP


class Paper:
    """The paper's HTP: the network emits the H-matrix factors of M (float32 apply); one rank."""

    title = "the paper's Hierarchical Transformer Preconditioner: a transformer emits the factors of an H-matrix M"

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
    def solved(setup, its, seconds):
        """Nothing to record after a solve."""

    @staticmethod
    def moved(analysis, A) -> bool:
        """The analysis depends on the pattern only."""
        return False

    @staticmethod
    def once(ksp, pc, setup) -> bool:
        """The network's M is the same under any KSP."""
        return False

    @staticmethod
    def inner_pcs(setup) -> dict:
        """No inner PETSc solver."""
        return {}

    @staticmethod
    def destroy(analysis):
        """Nothing to free: torch tensors go with their Python objects."""
