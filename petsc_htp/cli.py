"""The ``petsc-htp`` command: scene, train, join-logs, fit, bench."""
from __future__ import annotations

import argparse
import json
import sys
from dataclasses import fields
from pathlib import Path


def _scene(args):
    from .scenes.dataset import save_frames
    from .scenes.plot import plot_frame
    from .scenes.generator import frame_summary, make_frame

    frame = make_frame(args.n, seed=args.seed, distribution=args.distribution,
                       contrast=tuple(args.contrast) if args.contrast else None, rhs=args.rhs, dim=args.dim)
    print(frame_summary(frame))
    out = Path(args.out or f"scene{'3d' if args.dim == 3 else ''}_n{args.n}_s{args.seed}")
    save_frames([frame], out.with_suffix(".npz"))
    plot_frame(frame, out.with_suffix(".png"))
    print(f"wrote {out.with_suffix('.npz')} and {out.with_suffix('.png')}")


def _model_config(args):
    from .paper.model import HTPConfig

    return HTPConfig(d=args.d, n_layers=args.n_layers, leaf=args.leaf, p_off=args.p_off, n_gcn=args.n_gcn,
                     heads=args.heads, highways=not args.no_highways, shift=args.shift).validate()


def _train(args):
    from .paper.train import TrainSettings, train

    names = {f.name for f in fields(TrainSettings)}
    kw = {k: v for k, v in vars(args).items() if k in names and v is not None}
    kw["scales"] = tuple(args.scales)
    path = train(_model_config(args), TrainSettings(**kw))
    print(f"checkpoint: {path}")


def _join_logs(args):
    from .paper.train import join_logs

    stages = []
    for spec in args.logs:
        path, _, n = spec.rpartition(":")
        if not path or not n.isdigit():
            raise ValueError(f"stage {spec!r} must be LOG:HELDOUT_N, e.g. runs/a/train_log.jsonl:1024")
        stages.append((path, int(n)))
    print(f"wrote {join_logs(stages, args.out)}")


def _fit(args):
    from .paper.fit import fit_frame
    from .scenes.generator import make_frame

    for n in args.n:
        res = fit_frame(make_frame(n, seed=args.seed, distribution="full"), steps=args.steps, lr=args.lr,
                        leaf=args.leaf, coarse=args.leaf // args.p_off, log=print)
        print(json.dumps(res))


def build_parser() -> argparse.ArgumentParser:
    """Argument parser with one sub-parser per subcommand."""
    p = argparse.ArgumentParser(prog="petsc-htp", description="Hierarchical Transformer Preconditioner for PETSc")
    sub = p.add_subparsers(dest="cmd", required=True)

    s = sub.add_parser("scene", help="generate one multiphase Poisson frame (.npz + .png)")
    s.add_argument("-n", type=int, default=4096)
    s.add_argument("--dim", type=int, default=2, choices=[2, 3],
                   help="2 or 3 (3-D: near-cubic box, 7-point operator; the picture shows slices and a projection)")
    s.add_argument("--seed", type=int, default=0)
    s.add_argument("--distribution", default="full")
    s.add_argument("--contrast", type=float, nargs=2, metavar=("LO", "HI"))
    s.add_argument("--rhs", default="random", choices=["random", "buoyancy"])
    s.add_argument("--out", help="output path stem (default scene_n<N>_s<seed>)")
    s.set_defaults(func=_scene)

    t = sub.add_parser("train", help="train an HTP network")
    t.add_argument("--scales", type=int, nargs="+", default=[1024])
    t.add_argument("--distribution", default="full")
    t.add_argument("--frames", type=int)
    t.add_argument("--loss", choices=["cosine", "sai"])
    t.add_argument("--lr", type=float)
    t.add_argument("--warmup", type=int, help="linear learning-rate warm-up steps")
    t.add_argument("--accum", type=int)
    t.add_argument("--max-steps", dest="max_steps", type=int)
    t.add_argument("--max-minutes", dest="max_minutes", type=float)
    t.add_argument("--log-every", dest="log_every", type=int)
    t.add_argument("--eval-every", dest="eval_every", type=int)
    t.add_argument("--ckpt-every", dest="ckpt_every", type=int)
    t.add_argument("--geometry-free", dest="geometry_free", type=float)
    t.add_argument("--eval-n", dest="eval_n", type=int)
    t.add_argument("--seed", type=int)
    t.add_argument("--device")
    t.add_argument("--threads", type=int, help="torch threads (1 is best on a busy machine)")
    t.add_argument("--compile", action="store_true", default=None)
    t.add_argument("--resume", action="store_true", default=None)
    t.add_argument("--init", help="start from this checkpoint's weights (fine-tuning; fresh optimizer)")
    t.add_argument("--out")
    t.add_argument("--cache-dir", dest="cache_dir")
    for name, default in (("d", 128), ("n-layers", 3), ("leaf", 128), ("p-off", 4), ("n-gcn", 2), ("heads", 8)):
        t.add_argument(f"--{name}", dest=name.replace("-", "_"), type=int, default=default)
    t.add_argument("--no-highways", action="store_true")
    t.add_argument("--shift", action="store_true", help="learned softplus diagonal shift")
    t.set_defaults(func=_train)

    f = sub.add_parser("fit", help="structure check: fit one frame's factors directly (no network)")
    f.add_argument("-n", type=int, nargs="+", default=[1024])
    f.add_argument("--seed", type=int, default=1_000_000)
    f.add_argument("--steps", type=int, default=1000)
    f.add_argument("--lr", type=float, default=3e-2)
    f.add_argument("--leaf", type=int, default=128)
    f.add_argument("--p-off", dest="p_off", type=int, default=4)
    f.set_defaults(func=_fit)

    j = sub.add_parser("join-logs", help="one training log from the logs of successive (fine-tuning) stages")
    j.add_argument("out", help="joined log (JSONL)")
    j.add_argument("logs", nargs="+", metavar="LOG:HELDOUT_N", help="stage logs, oldest first")
    j.set_defaults(func=_join_logs)

    sub.add_parser("bench", help="benchmark every method through PETSc (see petsc-htp bench -h)", add_help=False)
    return p


def main(argv=None) -> int:
    """Entry point of the ``petsc-htp`` console script."""
    argv = sys.argv[1:] if argv is None else list(argv)
    if argv[:1] == ["bench"]:          # the bench owns its own argument parser
        from .bench import main as bench_main
        return bench_main(argv[1:])
    args = build_parser().parse_args(argv)
    try:
        args.func(args)
    except ValueError as exc:
        print(f"petsc-htp {args.cmd}: error: {exc}", file=sys.stderr)
        return 2
    except ModuleNotFoundError as exc:
        if exc.name != "torch":
            raise
        from .variants import TORCH_EXTRA

        print(f"petsc-htp {args.cmd}: error: it runs torch, which is not installed: {TORCH_EXTRA}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
