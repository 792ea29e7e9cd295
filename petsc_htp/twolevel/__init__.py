"""The two-level variant: exact leaf solves, a coarse space per leaf and its exact Galerkin operator.

One definition, two back-ends. The parts: :mod:`.leaves` (and :mod:`.embedding` for bare matrices) cut the
rows into leaves; :mod:`.leaflayout` maps a pattern's entries onto them; :mod:`.nullspace` finds the leaves'
pieces and the null components; :mod:`.coarsespace` builds every leaf's coarse vectors (with
:mod:`.coarsenet`, the learned seeds, trained by :mod:`.coarsetrain`); :mod:`.leafsolvers` solves the leaves.
:mod:`.composed` puts them together from PETSc parts (HTPPC, any number of ranks); :mod:`.batched` in
batched torch (PETSc-free, the GPU fast path).

``analyse``, ``factor`` and ``coarse_space`` (the torch back-end) and ``choose_leaves`` are importable from here.
"""

_EXPORTS = {"analyse": "batched", "factor": "batched", "coarse_space": "batched", "BatchedTwoLevel": "batched",
            "choose_leaves": "leaves"}


def __getattr__(name):  # the torch back-end loads on first use
    if name in _EXPORTS:
        from importlib import import_module

        return getattr(import_module(f"{__name__}.{_EXPORTS[name]}"), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
