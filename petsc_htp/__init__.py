"""petsc_htp: Hierarchical Transformer Preconditioner for PETSc."""
__version__ = "0.1.0"


def __getattr__(name):  # HTPPC and attach load petsc4py lazily: `import petsc_htp` works without it
    if name in ("HTPPC", "attach"):
        from . import pc
        return getattr(pc, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
