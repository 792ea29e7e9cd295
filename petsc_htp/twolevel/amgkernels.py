"""PyAMG's compiled kernels (``pyamg.amg_core``) without PyAMG's Python package.

``from pyamg import amg_core`` runs ``pyamg/__init__``, which loads its gallery, SciPy's io and all its solvers:
about 40 ms of a fresh process's first setup, where the leaves need four C++ routines of two extension modules.
:func:`kernels` loads such a module from PyAMG's installed ``amg_core`` folder by itself, once, under its own name
in ``sys.modules`` (so a later ``import pyamg`` finds it there rather than initialising it twice), and falls back
to the package import where the folder holds no such file. PETSc-free.
"""
from __future__ import annotations

import functools
import importlib.machinery
import importlib.util
import sys
from pathlib import Path


@functools.lru_cache(maxsize=None)
def kernels(name: str):
    """The compiled module ``pyamg.amg_core.<name>`` ('smoothed_aggregation', 'graph', ...)."""
    full = f"pyamg.amg_core.{name}"
    if full in sys.modules:
        return sys.modules[full]
    spec = importlib.util.find_spec("pyamg")                # finds the package without running its __init__
    for folder in (spec.submodule_search_locations or []) if spec else []:
        for suffix in importlib.machinery.EXTENSION_SUFFIXES:
            path = Path(folder) / "amg_core" / f"{name}{suffix}"
            if path.is_file():
                loader = importlib.machinery.ExtensionFileLoader(full, str(path))
                module = importlib.util.module_from_spec(importlib.util.spec_from_loader(full, loader))
                sys.modules[full] = module
                loader.exec_module(module)
                return module
    from pyamg import amg_core

    return getattr(amg_core, name)
