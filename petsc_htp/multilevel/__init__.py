"""The multilevel variant (``-htp_variant multilevel``): HTP's leaves at every level of a hierarchy.

Each level (:mod:`.level`) splits its operator's rows into aggregation leaves (strong couplings, compiled kernels,
each rank its own rows), takes the leaf constants as coarse vectors, smooths them by one Jacobi step and forms the
Galerkin operator W^T A W, which the next level splits again (:mod:`.hierarchy`), down to a coarse operator small
enough for one factor. PETSc's PCMG runs the V-cycle (:mod:`.cycle`): on each level one Gauss-Seidel sweep of each
rank's rows down and one up (2-D graphs, 3-D ones without positive couplings), or one Richardson step preconditioned
by the exact solves of the level's leaf blocks (one Cholesky factor of the block-diagonal leaf matrix per rank),
damped by Lanczos' largest eigenvalue; on the coarsest LAPACK's banded Cholesky factor where its band is narrow,
else the sparse LU.
"""
