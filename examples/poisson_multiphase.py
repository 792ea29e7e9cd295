#!/usr/bin/env python
"""Solve one multiphase pressure-Poisson frame with PETSc, preconditioned by HTP.

    python examples/poisson_multiphase.py                       # CG + HTP (options/cg_htp.opts)
    python examples/poisson_multiphase.py -options_file options/cg_gamg.opts
    python examples/poisson_multiphase.py -n 4096 -compare -plot results/demo.png
    mpiexec -n 2 python examples/poisson_multiphase.py -options_file options/bjacobi_htp.opts

Example options
    -n N                 unknowns (default 4096)
    -seed S              scene seed (default 0); every rank builds the same frame
    -contrast LO,HI      heavy-density range (default: the 'full' distribution's)
    -rhs random|buoyancy right-hand side (default random)
    -compare             also run every method file in options/ on the same frame
    -plot FILE.png       draw density, rhs and the computed pressure

Without ``-options_file`` and without ``-pc_type`` the method is
``options/common.opts`` + ``options/cg_htp.opts``. Everything else is ordinary
PETSc (``-ksp_view``, ``-log_view``, ``-htp_checkpoint ...``).

``-options_file`` arguments are read by this script rather than by PETSc so
that the ``-options_file options/common.opts`` line inside every method file
resolves from any working directory (first against the current directory,
then against the repository root). Options given on the command line win over
the files. When the method runs HTP inside block Jacobi (``-sub_pc_python_type``
set), ``-htp_*`` options are copied to ``-sub_htp_*`` (unless set), so
``-htp_checkpoint`` reaches the per-block HTP too. A file that sets
``-htp_bjacobi_leaf L`` gets ``-pc_bjacobi_blocks ceil(N/L)``.

With ``-compare`` each file is loaded under its own options prefix (its file
name plus ``_``) into a fresh KSP, so the methods cannot leak into each other;
``-htp_*`` and ``-ksp_rtol/-ksp_atol/-ksp_max_it`` from the command line apply
to every method. The exit status is non-zero when the main method did not
converge (after printing PETSc's reason).
"""
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
OPTIONS_DIR = ROOT / "options"


def _split_options_files(argv):
    """Remove ``-options_file F`` pairs from argv; return (argv, files)."""
    out, files, i = [], [], 0
    while i < len(argv):
        if argv[i] == "-options_file" and i + 1 < len(argv):
            files.append(argv[i + 1])
            i += 2
        else:
            out.append(argv[i])
            i += 1
    return out, files


sys.argv, OPTION_FILES = _split_options_files(sys.argv)
if str(ROOT) not in sys.path:      # run from a checkout without installing
    sys.path.insert(0, str(ROOT))

import petsc4py  # noqa: E402

petsc4py.init(sys.argv)
from petsc4py import PETSc  # noqa: E402


import petsc_htp  # noqa: E402
from petsc_htp.options import read_options_file  # noqa: E402
from petsc_htp.scenes import make_frame, plot_frame  # noqa: E402

DEFAULT_FILES = ("common.opts", "cg_htp.opts")
PROPAGATE = ("ksp_rtol", "ksp_atol", "ksp_max_it")


# --------------------------------------------------------------- options files

def insert_options(pairs, prefix="", override=True):
    """Put (name, value) pairs into PETSc's database under ``prefix`` (later pairs win)."""
    db = PETSc.Options()
    for name, value in dict(pairs).items():
        full = prefix + name
        if override or not db.hasName(full):
            db.setValue(full, "" if value is None else value)


def method_options(prefix=""):
    """Copy -htp_* to -sub_htp_* (unless set) when HTP preconditions sub-blocks."""
    db = PETSc.Options()
    if not db.hasName(prefix + "sub_pc_python_type"):
        return
    for name, value in list(db.getAll().items()):
        if name.startswith(prefix + "htp_") and name != prefix + "htp_bjacobi_leaf":
            sub = prefix + "sub_" + name[len(prefix):]
            if not db.hasName(sub):
                db.setValue(sub, "" if value is None else value)


def set_bjacobi_blocks(n, prefix=""):
    """-<prefix>htp_bjacobi_leaf L -> -<prefix>pc_bjacobi_blocks ceil(N/L); returns the block count."""
    db = PETSc.Options(prefix)
    if not db.hasName("htp_bjacobi_leaf"):
        return None
    leaf = db.getInt("htp_bjacobi_leaf")
    if leaf < 1:
        raise ValueError(f"-{prefix}htp_bjacobi_leaf must be positive, got {leaf}")
    blocks = max(-(-n // leaf), PETSc.COMM_WORLD.getSize())
    if not db.hasName("pc_bjacobi_blocks"):
        db.setValue("pc_bjacobi_blocks", blocks)
    return blocks


# ------------------------------------------------------------------- solving

def solve(A, b, n, prefix=""):
    """Create a KSP with ``prefix``, set it up and solve; return a result dict and the solution."""
    set_bjacobi_blocks(n, prefix)
    ksp = PETSc.KSP().create(comm=A.getComm())
    ksp.setOptionsPrefix(prefix)
    ksp.setOperators(A, A)
    ksp.setFromOptions()
    x = b.duplicate()
    x.set(0.0)
    A.getComm().barrier()
    t0 = time.perf_counter()
    ksp.setUp()
    ksp.setUpOnBlocks()
    A.getComm().barrier()
    t1 = time.perf_counter()
    ksp.solve(b, x)
    A.getComm().barrier()
    t2 = time.perf_counter()
    r = b.duplicate()
    A.mult(x, r)
    r.aypx(-1.0, b)
    pc = ksp.getPC()
    sub = ""
    if pc.getType() == "bjacobi":
        sub_ksps = pc.getBJacobiSubKSP()
        if sub_ksps:
            sub = "/" + sub_ksps[0].getPC().getType()
    reason = ksp.getConvergedReason()
    res = {
        "ksp": ksp.getType(), "pc": pc.getType() + sub, "its": ksp.getIterationNumber(),
        "reason": reason_name(reason), "converged": reason > 0,
        "setup_ms": 1e3 * (t1 - t0), "solve_ms": 1e3 * (t2 - t1),
        "relres": r.norm() / b.norm(),
    }
    ksp.destroy()
    r.destroy()
    return res, x


def reason_name(code):
    """KSP converged reason code -> the name PETSc prints (e.g. CONVERGED_RTOL, DIVERGED_ITS)."""
    if code == -3:          # petsc4py calls it DIVERGED_MAX_IT; -ksp_converged_reason says DIVERGED_ITS
        return "DIVERGED_ITS"
    for name, value in vars(PETSc.KSP.ConvergedReason).items():
        if not name.startswith("_") and name.isupper() and value == code and name != "ITERATING":
            return name
    return str(code)


def print_result(method, res):
    PETSc.Sys.Print(f"method: {method} (ksp {res['ksp']}, pc {res['pc']})")
    PETSc.Sys.Print(f"iterations: {res['its']}")
    PETSc.Sys.Print(f"converged reason: {res['reason']}")
    PETSc.Sys.Print(f"setup ms (KSPSetUp): {res['setup_ms']:.1f}")
    PETSc.Sys.Print(f"solve ms: {res['solve_ms']:.1f}")
    PETSc.Sys.Print(f"true relative residual ||b - A x|| / ||b||: {res['relres']:.3e}")


def compare(A, b, n, cli):
    """Run every method file on the same frame, each under its own prefix; print a table."""
    files = sorted(p for p in OPTIONS_DIR.glob("*.opts") if p.name != "common.opts")
    rows = []
    for path in files:
        prefix = path.stem + "_"
        insert_options(read_options_file(path), prefix)
        for name, value in cli:
            if (name.startswith("htp_") and name != "htp_bjacobi_leaf") or name in PROPAGATE:
                insert_options([(name, value)], prefix)
        method_options(prefix)
        try:
            res, x = solve(A, b, n, prefix)
            x.destroy()
        except PETSc.Error as exc:
            res = {"ksp": "-", "pc": "-", "its": -1, "reason": f"ERROR {exc}", "converged": False,
                   "setup_ms": float("nan"), "solve_ms": float("nan"), "relres": float("nan")}
        rows.append((path.stem, res))
        db = PETSc.Options()
        for name in list(db.getAll()):
            if name.startswith(prefix):
                db.delValue(name)
    head = f"{'method':<12} {'ksp':<6} {'pc':<16} {'its':>6} {'reason':<24} {'setup ms':>10} {'solve ms':>10} {'rel. res.':>10}"
    PETSc.Sys.Print("")
    PETSc.Sys.Print(f"comparison on N={n} (rtol and norm from options/common.opts):")
    PETSc.Sys.Print(head)
    PETSc.Sys.Print("-" * len(head))
    for stem, r in rows:
        PETSc.Sys.Print(f"{stem:<12} {r['ksp']:<6} {r['pc']:<16} {r['its']:>6} {r['reason']:<24} "
                        f"{r['setup_ms']:>10.1f} {r['solve_ms']:>10.1f} {r['relres']:>10.2e}")
    return rows


def gather(x):
    """The whole solution vector on every rank."""
    scatter, full = PETSc.Scatter.toAll(x)
    scatter.scatter(x, full, PETSc.InsertMode.INSERT, PETSc.ScatterMode.FORWARD)
    out = full.getArray().copy()
    scatter.destroy()
    full.destroy()
    return out


def main():
    db = PETSc.Options()
    cli = [(k, v) for k, v in db.getAll().items()]      # command-line options (before any file)
    n = db.getInt("n", 4096)
    seed = db.getInt("seed", 0)
    rhs = db.getString("rhs", "random")
    contrast = db.getString("contrast", "")
    contrast = tuple(float(c) for c in contrast.split(",")) if contrast else None
    do_compare = db.getBool("compare", False)
    plot = db.getString("plot", "")

    files = OPTION_FILES
    if not files and not db.hasName("pc_type"):
        files = [str(OPTIONS_DIR / f) for f in DEFAULT_FILES]
    for f in reversed(files):                 # the command line, then later files, win
        insert_options(read_options_file(f), override=False)
    method_options()
    method = ", ".join(Path(f).stem for f in files if Path(f).name != "common.opts") or "command line"

    frame = make_frame(n, seed=seed, contrast=contrast, rhs=rhs)
    A = frame.petsc_mat()
    petsc_htp.attach(A, coords=frame.coords, density=frame.rho)
    b = frame.petsc_vec(A)
    size = A.getComm().getSize()
    PETSc.Sys.Print(f"frame: N={frame.n}, seed={seed}, rho_heavy={frame.params['rho_heavy']:.3g}, "
                    f"barriers={len(frame.params['barriers'])}, rhs={rhs}, ranks={size}")

    res, x = solve(A, b, frame.n)
    print_result(method, res)
    if do_compare:
        compare(A, b, frame.n, cli)
    if plot:
        pressure = gather(x)
        if PETSc.COMM_WORLD.getRank() == 0:
            Path(plot).parent.mkdir(parents=True, exist_ok=True)
            plot_frame(frame, plot, pressure=pressure)
            PETSc.Sys.Print(f"plot: {plot}", comm=PETSc.COMM_SELF)
    return 0 if res["converged"] else 1


if __name__ == "__main__":
    sys.exit(main())
