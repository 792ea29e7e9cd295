#!/usr/bin/env python
"""Solve one multiphase pressure-Poisson frame with PETSc, preconditioned by HTP.

    python examples/poisson_multiphase.py                       # CG + HTPPC's default (options/cg_htp.opts)
    python examples/poisson_multiphase.py -options_file options/cg_gamg.opts
    python examples/poisson_multiphase.py -n 4096 -compare -plot results/demo.png
    mpiexec -n 2 python examples/poisson_multiphase.py -options_file options/bjacobi_paper.opts

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

``-options_file`` arguments are loaded by :class:`petsc_htp.bench.harness.Loaded`
(PETSc's own ``-options_file``, with the ``options/common.opts`` include
resolved from any working directory, a method name such as ``cg_gamg`` works
too); options given on the command line win over the files. The project's
two rules apply: ``-htp_bjacobi_leaf L`` gives ``-pc_bjacobi_blocks ceil(N/L)``
and, for HTP inside block Jacobi, ``-htp_*`` is copied to ``-sub_htp_*``.

With ``-compare`` each shipped method is loaded under its own options prefix
(its name plus ``_``) into a fresh KSP, so the methods cannot leak into each
other; ``-htp_*`` and ``-ksp_rtol/-ksp_atol/-ksp_max_it`` from the command
line apply to every method. The exit status is non-zero when the main method
did not converge (after printing PETSc's reason).
"""
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
try:
    import petsc_htp  # noqa: F401  (installed)
except ImportError:                # run from a checkout without installing
    sys.path.insert(0, str(ROOT))
from petsc_htp.bench.harness import Loaded, method_names, solve, init_petsc  # noqa: E402

OPTION_FILES = init_petsc(sys.argv)
from petsc4py import PETSc  # noqa: E402


import petsc_htp  # noqa: E402
from petsc_htp.petscmat import frame_mat, frame_vec  # noqa: E402
from petsc_htp.scenes.plot import plot_frame  # noqa: E402
from petsc_htp.scenes.generator import make_frame  # noqa: E402

DEFAULT_FILES = ("cg_htp",)
PROPAGATE = ("ksp_rtol", "ksp_atol", "ksp_max_it")


def true_residual(A, b, x):
    """||b - A x|| / ||b||."""
    r = b.duplicate()
    A.mult(x, r)
    r.aypx(-1.0, b)
    out = r.norm() / b.norm()
    r.destroy()
    return out


def run(A, b, prefix=""):
    """Solve with the options under ``prefix``; the result dict (with ``relres``)."""
    res = solve(A, b, prefix)
    res["relres"] = true_residual(A, b, res["x"])
    return res


def print_result(method, res):
    PETSc.Sys.Print(f"method: {method} (ksp {res['ksp']}, pc {res['pc']})")
    PETSc.Sys.Print(f"iterations: {res['its']}")
    PETSc.Sys.Print(f"converged reason: {res['reason']}")
    PETSc.Sys.Print(f"setup ms (KSPSetUp): {res['setup_ms']:.1f}")
    PETSc.Sys.Print(f"solve ms: {res['solve_ms']:.1f}")
    PETSc.Sys.Print(f"true relative residual ||b - A x|| / ||b||: {res['relres']:.3e}")


def compare(A, b, n, cli):
    """Run every shipped method on the same frame, each under its own prefix; print a table."""
    shared = [(k, v) for k, v in cli if (k.startswith("htp_") and k != "htp_bjacobi_leaf") or k in PROPAGATE]
    rows = []
    for name in method_names():
        try:
            with Loaded(name, prefix=name + "_", extra=shared) as loaded:
                res = run(A, b, loaded.prefix)
                res.pop("x").destroy()
        except PETSc.Error as exc:
            res = {"ksp": "-", "pc": "-", "its": -1, "reason": f"ERROR {exc}", "converged": False,
                   "setup_ms": float("nan"), "solve_ms": float("nan"), "relres": float("nan")}
        rows.append((name, res))
    w = max(len(stem) for stem, _ in rows)
    head = f"{'method':<{w}} {'ksp':<6} {'pc':<16} {'its':>6} {'reason':<24} {'setup ms':>10} {'solve ms':>10} {'rel. res.':>10}"
    PETSc.Sys.Print("")
    PETSc.Sys.Print(f"comparison on N={n} (rtol and norm from options/common.opts):")
    PETSc.Sys.Print(head)
    PETSc.Sys.Print("-" * len(head))
    for stem, r in rows:
        PETSc.Sys.Print(f"{stem:<{w}} {r['ksp']:<6} {r['pc']:<16} {r['its']:>6} {r['reason']:<24} "
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

    files = OPTION_FILES or ([] if db.hasName("pc_type") else list(DEFAULT_FILES))
    for f in files:
        Loaded(f, extra=cli).__enter__()      # kept for the whole run; the command line wins over the files
    method = ", ".join(Path(f).stem for f in files) or "command line"

    frame = make_frame(n, seed=seed, contrast=contrast, rhs=rhs)
    A = frame_mat(frame)
    petsc_htp.attach(A, coords=frame.coords, density=frame.rho)
    b = frame_vec(frame, A)
    size = A.getComm().getSize()
    PETSc.Sys.Print(f"frame: N={frame.n}, seed={seed}, rho_heavy={frame.params['rho_heavy']:.3g}, "
                    f"barriers={len(frame.params['barriers'])}, rhs={rhs}, ranks={size}")

    res = run(A, b)
    x = res["x"]
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
