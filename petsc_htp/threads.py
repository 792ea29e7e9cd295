"""The threads of this process's BLAS, OpenMP and torch, which ``-htp_threads`` sets (1 by default).

An MPI rank that leaves OpenBLAS at its default uses a thread per core, and two ranks on two cores
then contend for them: PETSc's vector and triangular-solve kernels (BLAS) ran three to four times slower on
2 ranks of a bare 512^2 DMDA matrix until the threads were set to 1 (one thread per rank is what PETSc assumes).
The setters of the loaded libraries are found in ``/proc/self/maps`` (as threadpoolctl does), again only after
an extension module was imported (reading the maps of a process that has run a large solve costs about 2 ms, a
small matrix's whole solve); elsewhere only torch's threads are set.
"""
from __future__ import annotations

import ctypes
import sys

SETTERS = (("openblas_set_num_threads", "openblas_get_num_threads"),
           ("scipy_openblas_set_num_threads64_", "scipy_openblas_get_num_threads64_"),
           ("omp_set_num_threads", "omp_get_max_threads"))
_FOUND = {}          # library path -> its (setter, getter) pairs
_SCANNED = [-1, []]  # len(sys.modules) when last looked at, and the pairs found at the last scan


def _new_extension(since) -> bool:
    """Whether a compiled extension module is among the modules imported after the first ``since`` (all of them
    when modules went away since)."""
    modules = list(sys.modules.values())
    new = modules[since:] if 0 <= since <= len(modules) else modules
    return since < 0 or any(str(getattr(m, "__file__", None) or "").endswith((".so", ".pyd")) for m in new)


def thread_pools() -> list:
    """(setter, getter) pairs of the thread pools of the shared libraries loaded in this process. The libraries
    are read again only after an extension module was imported since (a library such as torch's OpenMP comes
    with one; one loaded by ``ctypes`` alone is found at the next such import)."""
    since, count = _SCANNED[0], len(sys.modules)
    if since == count:
        return _SCANNED[1]
    if not _new_extension(since):
        _SCANNED[0] = count
        return _SCANNED[1]
    try:
        with open("/proc/self/maps") as fh:
            paths = sorted({line.split()[-1] for line in fh if "blas" in line or "gomp" in line})
    except OSError:
        paths = []
    for path in paths:
        if path not in _FOUND:
            try:
                lib = ctypes.CDLL(path)
            except OSError:
                lib = None
            _FOUND[path] = [(getattr(lib, s), getattr(lib, g)) for s, g in SETTERS
                            if lib is not None and hasattr(lib, s) and hasattr(lib, g)]
    _SCANNED[:] = [len(sys.modules), [pair for path in paths for pair in _FOUND[path]]]
    return _SCANNED[1]


def set_threads(n: int) -> int | None:
    """Set the BLAS, OpenMP and (where loaded) torch threads of this process to ``n``; returns the previous count
    where one changed, else None. torch is never imported here."""
    before = None
    for setter, getter in thread_pools():
        now = getter()
        if now != n:
            setter(n)
            before = before or now
    torch = sys.modules.get("torch")
    if torch is not None and torch.get_num_threads() != n:
        before = before or torch.get_num_threads()
        torch.set_num_threads(n)
    return before
