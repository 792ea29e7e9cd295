"""Checkpoints of either network: weights + configuration + provenance + a format version, written atomically.

The paper network's own loading is :mod:`petsc_htp.paper.weights`, the coarse network's
:mod:`petsc_htp.twolevel.coarsenet`.
"""
from __future__ import annotations

import os
from pathlib import Path

from ..atomic import atomic_open

FORMAT = "petsc_htp-checkpoint"
VERSION = 1
DEFAULT = Path(__file__).parent.parent / "checkpoints" / "htp_default.pt"


class CheckpointError(ValueError):
    """A checkpoint is missing, unreadable, corrupt, of an unknown version or mismatched."""


_LOADED = {}        # (path, mtime, size, *extra) -> loaded object


def cached(path, default: Path, load, *extra):
    """``load(path)`` once per process until the file changes (``extra``: more of the key); shared by callers."""
    path = Path(path).expanduser().resolve() if path else default
    try:
        st = os.stat(path)
    except OSError:
        raise CheckpointError(f"checkpoint {path} does not exist or cannot be read") from None
    key = (str(path), st.st_mtime_ns, st.st_size, *extra)
    if key not in _LOADED:
        if len(_LOADED) >= 8:
            _LOADED.pop(next(iter(_LOADED)))
        _LOADED[key] = load(path)
    return _LOADED[key]


def atomic_save(obj, path) -> Path:
    """torch.save to a temporary file in the target folder, then rename."""
    import torch

    with atomic_open(path, "wb") as fh:
        torch.save(obj, fh)
    return Path(path)


def save(path, net, provenance: dict, extra: dict | None = None, fmt: str = FORMAT, version: int = VERSION) -> Path:
    """Write a network's checkpoint; ``extra`` (optimizer state, ...) is kept for resuming.

    ``net`` has a ``cfg`` with ``to_dict()``; ``fmt`` and ``version`` tag the kind of network.
    """
    obj = {"format": fmt, "version": version, "config": net.cfg.to_dict(),
           "state_dict": net.state_dict(), "provenance": dict(provenance)}
    if extra:
        obj["extra"] = extra
    return atomic_save(obj, path)


def read(path=None, fmt: str = FORMAT, version: int = VERSION, default: Path = DEFAULT,
         what: str = "petsc_htp checkpoint") -> dict:
    """Read and validate a checkpoint file of kind ``fmt``, called ``what`` in errors (``default`` when
    ``path`` is None)."""
    path = Path(path) if path else default
    if not path.is_file():
        raise CheckpointError(f"{what} {path} does not exist")
    import torch

    try:
        obj = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as exc:  # torch raises many types for a damaged file
        raise CheckpointError(f"{what} {path} is corrupt or unreadable: torch.load failed with "
                              f"{type(exc).__name__} (the cause holds torch's message)") from exc
    if not isinstance(obj, dict) or obj.get("format") != fmt:
        raise CheckpointError(f"{path} is not a {what}")
    if obj.get("version") != version:
        raise CheckpointError(f"{what} {path} has format version {obj.get('version')!r}; "
                              f"this petsc_htp reads version {version}")
    return obj
