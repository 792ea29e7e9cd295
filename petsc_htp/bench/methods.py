"""Which methods a benchmark runs: PETSc options files, plus pyamg's classical AMG."""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from ..options import OPTIONS_DIR
PYAMG = "pyamg"
DEFAULT_METHODS = ("cg_none", "cg_jacobi", "cg_icc", "cg_bjacobi", "cg_gamg", "cg_htp", PYAMG)


@dataclass(frozen=True)
class Method:
    """One benchmarked method: an options file, or pyamg when ``path`` is None."""

    name: str
    path: Path | None = None

    @property
    def is_petsc(self) -> bool:
        """True for an options-file method solved by PETSc's KSP."""
        return self.path is not None

    @property
    def prefix(self) -> str:
        """Options prefix the method's file is loaded under."""
        return f"bench_{self.name}_"


def options_dirs():
    """Folders searched for a method name: the repository's options/, then ./options."""
    return [OPTIONS_DIR, Path.cwd() / "options"]


def resolve_method(name) -> Method:
    """A method from ``pyamg``, an options-file stem in options/, or a path to an ``.opts`` file."""
    if name == PYAMG:
        return Method(PYAMG)
    given = Path(name).expanduser()
    if given.suffix == ".opts" or given.parent != Path("."):
        if not given.is_file():
            raise ValueError(f"options file {name} not found")
        return Method(given.stem, given.resolve())
    for folder in options_dirs():
        path = folder / f"{name}.opts"
        if path.is_file():
            return Method(name, path)
    known = sorted({p.stem for d in options_dirs() if d.is_dir() for p in d.glob("*.opts")} - {"common"})
    raise ValueError(f"unknown method {name!r}: no {name}.opts in {OPTIONS_DIR}; known: "
                     f"{', '.join(known + [PYAMG])}, or a path to an .opts file")


def resolve_methods(names) -> list:
    """Resolve every name; two methods with the same name are an error."""
    methods = [resolve_method(str(n)) for n in names]
    seen = set()
    for m in methods:
        if m.name in seen:
            raise ValueError(f"method name {m.name!r} given twice")
        seen.add(m.name)
    return methods
