"""The threads of this process's BLAS, OpenMP and torch, which ``-htp_threads`` sets (1 by default).

An MPI rank that leaves OpenBLAS at its default uses a thread per core, and two ranks on two cores
then contend for them: PETSc's vector and triangular-solve kernels (BLAS) ran three to four times slower on
2 ranks of a bare 512^2 DMDA matrix until the threads were set to 1 (one thread per rank is what PETSc assumes).
The setters are looked up in the loaded libraries, listed by glibc's ``dl_iterate_phdr`` (threadpoolctl does
the same), again only after an import that loaded a library; elsewhere only torch's threads are set.
"""
from __future__ import annotations

import ctypes
import os
import sys

SETTERS = (("openblas_set_num_threads", "openblas_get_num_threads"),
           ("scipy_openblas_set_num_threads64_", "scipy_openblas_get_num_threads64_"),     # NumPy's wheel's
           ("scipy_openblas_set_num_threads", "scipy_openblas_get_num_threads"),   # SciPy's (scipy.linalg's LAPACK)
           ("omp_set_num_threads", "omp_get_max_threads"))
LIKELY = ("blas", "lapack", "omp")   # loaded names worth resolving (a link named so may lead to a pool)
_FOUND = {}          # library path -> its (setter, getter) pairs
_REAL = {}           # loaded object's name -> its real path
_SCANNED = [-1, -1, []]  # len(sys.modules) when last looked, shared objects loaded at the last scan, the pairs


class _Object(ctypes.Structure):
    _fields_ = [("addr", ctypes.c_void_p), ("name", ctypes.c_char_p)]     # the head of glibc's dl_phdr_info


_EACH = ctypes.CFUNCTYPE(ctypes.c_int, ctypes.POINTER(_Object), ctypes.c_size_t, ctypes.c_void_p)


def loaded_objects() -> list:
    """Paths of the shared objects loaded in this process, from glibc's ``dl_iterate_phdr`` (about 0.05 ms; reading
    ``/proc/self/maps`` costs about 1 ms, and more after a large solve); empty where there is no such call."""
    try:
        walk = ctypes.CDLL(None).dl_iterate_phdr
    except (OSError, AttributeError, TypeError):     # no glibc (CDLL(None) fails on Windows)
        return []
    names = []

    def each(info, size, data):
        names.append((info.contents.name or b"").decode(errors="replace"))
        return 0

    walk(_EACH(each), None)
    return names


def thread_pools() -> list:
    """(setter, getter) pairs of the thread pools of the shared libraries loaded in this process. They are looked
    for again only after an import that loaded a shared object (a library such as torch's OpenMP comes with one;
    one loaded by ``ctypes`` alone is found after the next import)."""
    if _SCANNED[0] == len(sys.modules):
        return _SCANNED[2]
    _SCANNED[0] = len(sys.modules)
    names = loaded_objects()
    if _SCANNED[1] == len(names):
        return _SCANNED[2]
    for name in names:                     # resolving all ~120 links took 8 ms: only names a pool could be behind
        if name not in _REAL:
            _REAL[name] = os.path.realpath(name) if any(k in name for k in LIKELY) else ""
    paths = sorted({real for real in map(_REAL.get, names) if "blas" in real or "gomp" in real})
    for path in paths:
        if path not in _FOUND:
            try:
                lib = ctypes.CDLL(path)
            except OSError:
                lib = None
            _FOUND[path] = [(getattr(lib, s), getattr(lib, g)) for s, g in SETTERS
                            if lib is not None and hasattr(lib, s) and hasattr(lib, g)]
    _SCANNED[1:] = [len(names), [pair for path in paths for pair in _FOUND[path]]]
    return _SCANNED[2]


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
