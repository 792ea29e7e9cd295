"""petsc_htp: Hierarchical Transformer Preconditioner for PETSc."""
__version__ = "0.1.0"
