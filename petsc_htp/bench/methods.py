"""Which methods a benchmark runs: PETSc options files (see :mod:`petsc_htp.bench.harness`), plus pyamg and AMGCL."""
from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

from . import harness
from .external import is_external

PYAMG = "pyamg"
DEFAULT_METHODS = ("cg_none", "cg_jacobi", "cg_icc", "cg_bjacobi", "cg_gamg", "cg_htp", "cg_paper",
                   "cg_twolevel_const", "cg_twolevel_eig", "cg_twolevel_learned", "pyamg", "pyamg_sa", "amgcl")
GAMG_SWEEP = re.compile(r"gamg_t(-?\d+(?:\.\d+)?)_a(\d+)")   # gamg_t<threshold>_a<aggressive levels>
FAMILIES = (("GAMG", "cg_gamg_default", re.compile(r"cg_gamg.*|gamg_t.*")),
            ("AMGCL", "amgcl", re.compile(r"amgcl.*")), ("pyamg", "pyamg", re.compile(r"pyamg.*")))


@dataclass(frozen=True)
class Method:
    """One benchmarked method: an options file (plus ``extra`` option pairs), or an external solver
    (:mod:`petsc_htp.bench.external`) when ``path`` is None."""

    name: str
    path: Path | None = None
    extra: tuple = ()

    @property
    def is_petsc(self) -> bool:
        """True for an options-file method solved by PETSc's KSP."""
        return self.path is not None

    @property
    def spec(self) -> str:
        """What names the method to another process (:func:`resolve_method`): an options file by its path (one
        outside ``options/`` has no name there), a sweep point or an external solver by its name."""
        return str(self.path) if self.is_petsc and not self.extra else self.name

    @property
    def prefix(self) -> str:
        """Options prefix the method's file is loaded under (the name with every character but letters, digits
        and underscores made an underscore)."""
        return "bench_" + re.sub(r"\W", "_", self.name) + "_"


def resolve_method(name) -> Method:
    """A method from an external solver's name (pyamg, pyamg_sa, amgcl, amgcl_ce<K>), a GAMG sweep point
    ``gamg_t<threshold>_a<levels>`` (``cg_gamg_default`` with ``-pc_gamg_threshold`` and
    ``-pc_gamg_aggressive_coarsening`` set), a shipped or ``./options`` method name, or a path to an ``.opts`` file."""
    if is_external(name):
        return Method(name)
    sweep = GAMG_SWEEP.fullmatch(name)
    if sweep:
        return Method(name, harness.find("cg_gamg_default"),
                      (("pc_gamg_threshold", sweep[1]), ("pc_gamg_aggressive_coarsening", sweep[2])))
    path = harness.find(name)
    return Method(path.stem, path)


def resolve_methods(names) -> list:
    """Resolve every name; two methods with the same name are an error."""
    found = [resolve_method(str(n)) for n in names]
    seen = set()
    for m in found:
        if m.name in seen:
            raise ValueError(f"method name {m.name!r} given twice")
        seen.add(m.name)
    return found


def family(name) -> tuple | None:
    """(family, its default method) of a baseline method name (GAMG, AMGCL or pyamg), or None."""
    for fam, default, pattern in FAMILIES:
        if pattern.fullmatch(name):
            return fam, default
    return None
