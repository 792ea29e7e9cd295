#!/usr/bin/env python
"""Two-phase flow: a heavy blob splashes into a pool; one PETSc pressure solve per frame, in 2-D or 3-D.

    python examples/multiphase_flow.py -options_file options/cg_gamg.opts
    python examples/multiphase_flow.py -options_file options/cg_icc.opts -reuse_every 5 -animate
    python examples/multiphase_flow.py -compare options/cg_gamg.opts,options/cg_icc.opts
    python examples/multiphase_flow.py -dim 3 -options_file cg_htp -animate      # a drop in a 48^3 box

Method files are loaded by :class:`petsc_htp.bench.harness.Loaded` (a shipped
name such as ``cg_gamg`` works too); the simulation itself is
:func:`petsc_htp.sim.simulation.simulate`.

Options
    -dim D              2 (default) or 3: a heavy drop falls past a plate into a pool in a closed box
    -nx N               cells across (default 64 in 2-D, 48 in 3-D; 32 / 16 with -quick)
    -ny, -nz N          cells up (2-D) or deep (3-D), and up (3-D) (default as -nx)
    -frames F           frames (default 50; 6 with -quick)
    -density_ratio R    heavy / light density (default 1000)
    -seed S             blob jitter (default 0)
    -reuse_every K      rebuild the preconditioner every K frames (default 0: every frame)
    -reuse_growth G     a reused preconditioner gets G times the iterations of the
                        last rebuilt frame; a frame that needs more rebuilds on the
                        spot and goes on from its iterate (default 1.5)
    -out DIR            output folder (default results/flow)
    -quick              a few frames at 32 x 32 (16^3 in 3-D)
    -animate            also write DIR/METHOD.gif (density and pressure; in 3-D the heavy phase shaded
                        as seen along y, and the pressure's central slice)
    -method_name NAME   label of a single run (default: the options file's name)
    -compare F1,F2,...  run each method file on the same scene, each in a fresh
                        KSP under the prefix NAME_; one chart DIR/compare.png

One matrix with a fixed nonzero pattern (Morton-ordered fluid cells) is
created once; each frame its values are replaced, the cell coordinates and the
coefficient 1/rho are attached for HTP, and the same KSP solves with the
previous pressure as the initial guess. Each run writes DIR/METHOD.jsonl (one record per frame) and
DIR/METHOD.png (ms per frame). A solve that fails (negative converged reason)
ends that run; the exit status is then 1 (2 for bad options).
"""
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
try:
    import petsc_htp  # noqa: F401  (installed)
except ImportError:                # run from a checkout without installing
    sys.path.insert(0, str(ROOT))
from petsc_htp.bench.harness import Loaded, init_petsc  # noqa: E402

OPTION_FILES = init_petsc(sys.argv)
from petsc4py import PETSc  # noqa: E402

from petsc_htp.sim.flow import Flow  # noqa: E402
from petsc_htp.sim.plot import plot_runs  # noqa: E402
from petsc_htp.sim.simulation import simulate, summary  # noqa: E402

PROPAGATE = ("ksp_rtol", "ksp_atol", "ksp_max_it")


# ------------------------------------------------------------------- main

def method_label(files):
    """Stem of the last options file other than common.opts, else ``command_line``."""
    stems = [Path(f).stem for f in files if Path(f).stem != "common"]
    return stems[-1] if stems else "command_line"


def parse_options():
    """The example's options from the PETSc database, validated (ValueError otherwise)."""
    db = PETSc.Options()
    quick = db.getBool("quick", False)
    dim = db.getInt("dim", 2)
    if dim not in (2, 3):
        raise ValueError(f"-dim must be 2 or 3, got {dim}")
    side = (32 if quick else 64) if dim == 2 else (16 if quick else 48)
    nx = db.getInt("nx", side)
    cfg = {
        "nx": nx, "ny": db.getInt("ny", nx), "nz": db.getInt("nz", nx) if dim == 3 else None,
        "frames": db.getInt("frames", 6 if quick else 50),
        "density_ratio": db.getReal("density_ratio", 1000.0), "seed": db.getInt("seed", 0),
        "reuse_every": db.getInt("reuse_every", 0), "reuse_growth": db.getReal("reuse_growth", 1.5),
        "out": db.getString("out", "results/flow"), "animate": db.getBool("animate", False),
        "method_name": db.getString("method_name", method_label(OPTION_FILES)),
        "compare": db.getString("compare", ""),
    }
    if cfg["frames"] < 1:
        raise ValueError(f"-frames must be at least 1, got {cfg['frames']}")
    if cfg["reuse_every"] < 0:
        raise ValueError(f"-reuse_every must be >= 0, got {cfg['reuse_every']}")
    if not cfg["reuse_growth"] >= 1.0:
        raise ValueError(f"-reuse_growth must be >= 1, got {cfg['reuse_growth']}")
    Flow(cfg["nx"], cfg["ny"], density_ratio=cfg["density_ratio"], seed=cfg["seed"], nz=cfg["nz"])  # validates
    return cfg


def main():
    if PETSc.COMM_WORLD.getSize() > 1:
        print("error: multiphase_flow.py runs on one MPI rank", file=sys.stderr)
        return 2
    cli = list(PETSc.Options().getAll().items())
    shared = [(k, v) for k, v in cli if k in PROPAGATE or k.startswith("htp_")]
    try:
        cfg = parse_options()
        for f in OPTION_FILES:
            Loaded(f, extra=cli).__enter__()      # kept for the whole run; the command line wins
        runs = ([(Path(f).stem, Loaded(f, prefix=Path(f).stem + "_", extra=shared).__enter__().prefix)
                 for f in cfg["compare"].split(",")] if cfg["compare"] else [(cfg["method_name"], "")])
    except (ValueError, OSError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    PETSc.Log.begin()
    failed, lines = False, []
    for label, prefix in runs:
        records, bad = simulate(cfg, label, prefix)
        failed |= bad
        lines.append(summary(records))
    if cfg["compare"]:
        plot_runs([Path(cfg["out"]) / f"{label}.jsonl" for label, _ in runs],
                  Path(cfg["out"]) / "compare.png")
    print("\nsummary (ms/frame = KSPSetUp + PCSetUpOnBlocks + KSPSolve):")
    print("\n".join(lines))
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
