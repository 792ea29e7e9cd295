"""The methods this project compares: PETSc options files, loaded by PETSc itself under a prefix.

One loader for the example, the benchmark and the tests. A method is an
options file (``petsc_htp/options/NAME.opts``, shipped with the package, also
reachable as ``options/`` in a checkout) or a path to one. :class:`Loaded`
inserts it with PETSc's own ``-prefix_push P -options_file F -prefix_pop``
(includes such as ``-options_file options/common.opts`` resolve against the
folder that holds ``options/`` when the file sits in one, else against the
current directory, as PETSc does), applies the project's two rules and removes
the prefixed options again on exit:

- ``-htp_bjacobi_leaf L`` (a file cannot know N) sets ``-pc_bjacobi_blocks ceil(N/L)``;
- when HTP preconditions block-Jacobi blocks (``-sub_pc_python_type`` set),
  every ``-htp_*`` option is copied to ``-sub_htp_*`` unless that is set.
"""
from __future__ import annotations

import contextlib
import os
from importlib.resources import files
from pathlib import Path

OPTIONS_DIR = Path(str(files("petsc_htp") / "options"))
COMMON = "common"


def init_petsc(argv) -> list:
    """Start petsc4py for a script: ``-options_file F`` pairs leave ``argv`` (in place) for :class:`Loaded`.

    Returns the options files, in command-line order. Call it before importing ``petsc4py.PETSc``.
    """
    import petsc4py

    rest, files, i = [], [], 0
    while i < len(argv):
        if argv[i] == "-options_file" and i + 1 < len(argv):
            files.append(argv[i + 1])
            i += 2
        else:
            rest.append(argv[i])
            i += 1
    argv[:] = rest
    petsc4py.init(argv)
    return files


def method_names() -> list:
    """The shipped methods (options-file stems, ``common`` excluded)."""
    return sorted(p.stem for p in OPTIONS_DIR.glob("*.opts") if p.stem != COMMON)


def find(name) -> Path:
    """An options file from a method name (``cg_gamg``) or a path (``my.opts``).

    Names are looked up in ``./options`` first, then among the shipped files.
    """
    given = Path(str(name)).expanduser()
    if given.suffix == ".opts" or given.parent != Path("."):
        if not given.is_file():
            raise ValueError(f"options file {name} not found")
        return given.resolve()
    for folder in (Path.cwd() / "options", OPTIONS_DIR):
        if (folder / f"{name}.opts").is_file():
            return (folder / f"{name}.opts").resolve()
    raise ValueError(f"unknown method {name!r}: no {name}.opts in ./options or {OPTIONS_DIR}; "
                     f"known: {', '.join(method_names())}, or a path to an .opts file")


def common_setting(name: str, default: float) -> float:
    """A value set in the shipped ``common.opts`` (the shared tolerances), as a float."""
    from petsc4py import PETSc

    with Loaded(OPTIONS_DIR / f"{COMMON}.opts", prefix="htp_common_"):
        value = PETSc.Options("htp_common_").getString(name, "")
    return float(value) if value else default


def reason_name(code: int) -> str:
    """KSP converged-reason code -> the name ``-ksp_converged_reason`` prints (CONVERGED_RTOL, DIVERGED_ITS)."""
    from petsc4py import PETSc

    if code == PETSc.KSP.ConvergedReason.DIVERGED_MAX_IT:
        return "DIVERGED_ITS"
    for name, value in vars(PETSc.KSP.ConvergedReason).items():
        if name.isupper() and value == code and name not in ("ITERATING", "CONVERGED_ITERATING"):
            return name
    return str(code)


@contextlib.contextmanager
def _cwd(path: Path):
    before = os.getcwd()
    os.chdir(path)
    try:
        yield
    finally:
        os.chdir(before)


class Loaded:
    """An options file in PETSc's database under ``prefix`` while the object is open.

    Parameters
    ----------
    method : str or Path
        Method name or options-file path (see :func:`find`).
    prefix : str
        Options prefix of the KSP that will read it ('' for the global database).
    extra : iterable of (name, value)
        Options set after the file (winning over it), without the prefix.
    """

    def __init__(self, method, prefix: str = "", extra=()):
        self.path = find(method)
        self.name = self.path.stem
        self.prefix = prefix
        self.extra = list(extra)
        self._before = set()

    def __enter__(self) -> "Loaded":
        from petsc4py import PETSc

        db = PETSc.Options()
        self._before = set(db.getAll())
        push = (f"-prefix_push {self.prefix} ", " -prefix_pop") if self.prefix else ("", "")
        home = self.path.parent.parent if self.path.parent.name == "options" else Path.cwd()
        with _cwd(home):                             # includes name options/common.opts
            db.insertString(f"{push[0]}-options_file {self.path}{push[1]}")
        for name, value in self.extra:
            db.setValue(self.prefix + name, "" if value is None else value)
        self._propagate_sub(db)
        return self

    def __exit__(self, *exc):
        from petsc4py import PETSc

        db = PETSc.Options()
        for name in set(db.getAll()) - self._before:      # the file's and the extras
            db.delValue(name)

    def _propagate_sub(self, db):
        p = self.prefix
        if not db.hasName(p + "sub_pc_python_type"):
            return
        for name, value in list(db.getAll().items()):
            if name.startswith(p + "htp_") and name != p + "htp_bjacobi_leaf":
                sub = p + "sub_" + name[len(p):]
                if not db.hasName(sub):
                    db.setValue(sub, "" if value is None else value)


@contextlib.contextmanager
def bjacobi_blocks(prefix: str, n: int, ranks: int = 1):
    """While open, ``-<prefix>htp_bjacobi_leaf L`` stands as ``-<prefix>pc_bjacobi_blocks max(ceil(N/L), ranks)``.

    Yields the block count, or None without ``htp_bjacobi_leaf``. A block count already in the
    options database (the user's or the file's) wins and stays; the one set here is removed on
    exit, so nothing is left in the global database. Open it around ``KSPSetFromOptions``.
    """
    from petsc4py import PETSc

    db = PETSc.Options(prefix)
    if not db.hasName("htp_bjacobi_leaf"):
        yield None
        return
    leaf = db.getInt("htp_bjacobi_leaf")
    if leaf < 1:
        raise ValueError(f"-{prefix}htp_bjacobi_leaf must be positive, got {leaf}")
    if db.hasName("pc_bjacobi_blocks"):
        yield db.getInt("pc_bjacobi_blocks")
        return
    blocks = max(-(-int(n) // leaf), ranks)
    db.setValue("pc_bjacobi_blocks", blocks)
    try:
        yield blocks
    finally:
        db.delValue("pc_bjacobi_blocks")


def solve(A, b, prefix: str = "", x=None, monitor=None, rtol=None) -> dict:
    """Solve ``A x = b`` with a fresh KSP configured from ``prefix``'s options; time setup and solve apart.

    :func:`bjacobi_blocks` is applied for ``A``'s size; ``rtol`` (if given) overrides the options'.

    Setup is ``KSPSetUp`` + ``KSPSetUpOnBlocks`` (factorisation, AMG hierarchy or HTP's setup),
    solve is ``KSPSolve``; both are timed between barriers of ``A``'s communicator.

    Returns
    -------
    dict
        ``ksp``, ``pc`` (with the sub-PC of block Jacobi), ``its``, ``reason`` (PETSc's name),
        ``converged``, ``setup_ms``, ``solve_ms`` and ``x`` (the solution Vec; the caller owns it).
    """
    import time

    from petsc4py import PETSc

    comm = A.getComm()
    ksp = PETSc.KSP().create(comm=comm)
    try:
        ksp.setOptionsPrefix(prefix)
        ksp.setOperators(A, A)
        with bjacobi_blocks(prefix, A.getSize()[0], comm.getSize()):
            ksp.setFromOptions()
        if rtol:
            ksp.setTolerances(rtol=rtol)
        if monitor is not None:
            ksp.setMonitor(monitor)
        if x is None:
            x = b.duplicate()
            x.set(0.0)
        comm.barrier()
        t0 = time.perf_counter()
        ksp.setUp()
        ksp.setUpOnBlocks()
        comm.barrier()
        t1 = time.perf_counter()
        ksp.solve(b, x)
        comm.barrier()
        t2 = time.perf_counter()
        pc = ksp.getPC()
        sub = ""
        if pc.getType() == "bjacobi" and pc.getBJacobiSubKSP():
            sub = "/" + pc.getBJacobiSubKSP()[0].getPC().getType()
        reason = ksp.getConvergedReason()
        ctxs = [p.getPythonContext() for p in ([k.getPC() for k in pc.getBJacobiSubKSP()]
                                               if pc.getType() == "bjacobi" else [pc]) if p.getType() == "python"]
        held = [c.setup.nbytes for c in ctxs if getattr(c, "setup", None) is not None]
        return {"ksp": ksp.getType(), "pc": pc.getType() + sub, "its": ksp.getIterationNumber(),
                "reason": reason_name(reason), "converged": reason > 0, "rtol": ksp.getTolerances()[0],
                "setup_ms": 1e3 * (t1 - t0), "solve_ms": 1e3 * (t2 - t1), "x": x,
                "htp_setup_ms": sum(getattr(c, "setup_ms", 0.0) for c in ctxs) if ctxs else None,
                "htp_bytes": sum(held) if held else None}
    finally:
        ksp.destroy()
