"""``meta.json``: the machine, software and settings of a run, as the report states them."""
from __future__ import annotations

import datetime
import hashlib
import os
import platform
from pathlib import Path

SOURCE = Path(__file__).resolve().parents[2]     # the checkout holding this package
from .studies import STUDIES


def git_commit(root=SOURCE):
    """HEAD's commit read from the .git folder (no git process), or None."""
    git = Path(root) / ".git"
    try:
        head = (git / "HEAD").read_text().strip()
        if not head.startswith("ref: "):
            return head
        ref = head[5:]
        if (git / ref).is_file():
            return (git / ref).read_text().strip()
        for line in (git / "packed-refs").read_text().splitlines():
            if line.endswith(" " + ref):
                return line.split()[0]
    except OSError:
        return None
    return None


def cpu_model() -> str:
    """CPU model name from /proc/cpuinfo (platform.processor() elsewhere)."""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown"


def versions() -> dict:
    """Versions of Python and of the numerical packages (pyamg and pyamgcl ``missing`` when absent)."""
    import numpy
    import petsc4py
    import scipy
    import torch
    from petsc4py import PETSc

    out = {"python": platform.python_version(), "numpy": numpy.__version__, "scipy": scipy.__version__,
           "torch": torch.__version__, "petsc4py": petsc4py.__version__,
           "PETSc": ".".join(map(str, PETSc.Sys.getVersion()))}
    for name in ("pyamg", "pyamgcl"):
        try:
            out[name] = getattr(__import__(name), "__version__", "installed")
        except ImportError:
            out[name] = "missing"
    return out


def checkpoint_meta(path) -> dict:
    """Path and short sha256 of checkpoint ``path`` (default the shipped model)."""
    from ..training import checkpoint

    path = Path(path).resolve() if path else checkpoint.DEFAULT
    if not path.is_file():
        return {"path": str(path), "sha256": "missing"}
    return {"path": str(path), "sha256": hashlib.sha256(path.read_bytes()).hexdigest()[:12]}


def collect(ctx, argv, quick, selected) -> dict:
    """Everything about the machine and a run of ``selected`` studies in context ``ctx``."""
    import torch
    from petsc4py import PETSc

    from ..paper.inference import resolve_device
    from .harness import common_setting

    meta = {
        "date": datetime.datetime.now().astimezone().isoformat(timespec="seconds"),
        "machine": {"platform": platform.platform(), "cpu": cpu_model(), "cores": os.cpu_count()},
        "commit": git_commit(), "versions": versions(),
        "threads": {"torch": torch.get_num_threads(), "MPI ranks": PETSc.COMM_WORLD.getSize(),
                    **{name: os.environ.get(name, "unset") for name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS")}},
        "checkpoint": checkpoint_meta(ctx.checkpoint), "device": str(resolve_device(ctx.device or "auto")),
        "argv": list(argv), "quick": quick, "methods": [m.name for m in ctx.methods], "studies": list(selected),
        "rtol": common_setting("ksp_rtol", 1e-8), "max_it": int(common_setting("ksp_max_it", 10000)),
        "budget": {"text": ctx.budget.describe(), "minutes": ctx.budget.minutes, "steps": ctx.budget.steps},
        "study_s": {},
    }
    for study in STUDIES.values():
        meta.update(study.meta(ctx.settings))
    return meta
