"""Cached train/test datasets of benchmark frames (seeds, .npz cache files, atomic writes)."""
import json
import os
import zipfile
from pathlib import Path

import numpy as np
import scipy.sparse as sp

from ..atomic import atomic_open
from .generator import GENERATOR_VERSION, Frame, check_dim, check_distribution, check_positive_int, make_frame

TEST_SEED_OFFSET = 1_000_000
SPLIT_SEED_OFFSETS = {"train": 0, "test": TEST_SEED_OFFSET}
DEFAULT_COUNTS = {"train": 100, "test": 20}


def _check_split(split):
    """Raise ValueError unless ``split`` is 'train' or 'test'."""
    if split not in SPLIT_SEED_OFFSETS:
        raise ValueError(f"unknown split {split!r}; expected 'train' or 'test'")


def dataset_seeds(split, count):
    """Seeds of a dataset split.

    Train uses ``0 .. count-1`` and test ``1_000_000 + i``, so the splits are
    disjoint for every allowed ``count`` (1 to 1_000_000).

    Returns
    -------
    numpy.ndarray of int64
    """
    _check_split(split)
    count = check_positive_int(count, "count")
    if count > TEST_SEED_OFFSET:
        raise ValueError(f"count must be at most {TEST_SEED_OFFSET}, got {count}")
    return SPLIT_SEED_OFFSETS[split] + np.arange(count, dtype=np.int64)


def default_cache_dir():
    """``$PETSC_HTP_CACHE`` if set, else ``~/.cache/petsc_htp``."""
    return Path(os.environ.get("PETSC_HTP_CACHE") or Path.home() / ".cache" / "petsc_htp")


def _frames_to_arrays(frames, key):
    """Flatten a non-empty list of same-size frames into cache-file arrays."""
    return {
        "version": np.array(GENERATOR_VERSION),
        "key": np.array(key),
        "params": np.array(json.dumps([f.params for f in frames])),
        "indptr": np.stack([f.A.indptr for f in frames]),
        "indices": np.concatenate([f.A.indices for f in frames]),
        "data": np.concatenate([f.A.data for f in frames]),
        "b": np.stack([f.b for f in frames]),
        "rho": np.stack([f.rho for f in frames]),
        "coords": np.stack([f.coords for f in frames]),
        "perm": np.stack([f.perm for f in frames]),
        "grid_shape": np.array([f.grid_shape for f in frames]),
    }


def _frames_from_arrays(arrays):
    """Rebuild frames from the arrays of a cache file."""
    indptr = arrays["indptr"]
    n = indptr.shape[1] - 1
    offsets = np.concatenate([[0], np.cumsum(indptr[:, -1])])
    indices, data = arrays["indices"], arrays["data"]
    params = json.loads(arrays["params"].item())
    frames = []
    for k, frame_params in enumerate(params):
        entries = slice(offsets[k], offsets[k + 1])
        frames.append(Frame(
            A=sp.csr_matrix((data[entries], indices[entries], indptr[k]), shape=(n, n)),
            b=arrays["b"][k],
            rho=arrays["rho"][k],
            coords=arrays["coords"][k],
            grid_shape=tuple(int(v) for v in arrays["grid_shape"][k]),
            perm=arrays["perm"][k],
            params=frame_params,
        ))
    return frames


def _read_cache(path, key):
    """Frames stored at ``path``, or None if missing, unreadable or stale."""
    try:
        with np.load(path, allow_pickle=False) as stored:
            if stored["version"].item() != GENERATOR_VERSION or stored["key"].item() != key:
                return None
            return _frames_from_arrays(stored)
    except (OSError, ValueError, KeyError, IndexError, EOFError, zipfile.BadZipFile):
        return None


def load_dataset(n, split="train", distribution="full", count=None, cache_dir=None, dim=2):
    """Load (generating and caching on first use) a dataset of frames.

    Parameters
    ----------
    n : int
        Problem size.
    split : {'train', 'test'}
        Seed split (see :func:`dataset_seeds`).
    distribution : str
        Name in :data:`DISTRIBUTIONS`.
    count : int, optional
        Number of frames; 100 for train and 20 for test by default.
    cache_dir : str or Path, optional
        Cache directory; defaults to :func:`default_cache_dir`.
    dim : int
        2 or 3 (3-D scenes, :func:`~petsc_htp.scenes.generator.make_frame` with ``dim=3``).

    Returns
    -------
    list of Frame
    """
    n = check_positive_int(n, "n")
    _check_split(split)
    check_distribution(distribution)
    count = DEFAULT_COUNTS[split] if count is None else count
    seeds = dataset_seeds(split, count)
    fields = {"n": n, "split": split, "distribution": distribution, "count": int(count)}
    key = json.dumps(fields if check_dim(dim) == 2 else {**fields, "dim": 3}, sort_keys=True)
    directory = Path(cache_dir) if cache_dir is not None else default_cache_dir()
    path = directory / f"multiphase{'' if dim == 2 else '3d'}_n{n}_{split}_{distribution}_c{count}.npz"
    frames = _read_cache(path, key)
    if frames is None:
        frames = [make_frame(n, seed=int(s), distribution=distribution, dim=dim) for s in seeds]
        save_frames(frames, path, key)
    return frames


def save_frames(frames, path, key="frames"):
    """Write same-size frames to one .npz file atomically (readable by :func:`load_frames`)."""
    with atomic_open(path, "wb") as handle:
        np.savez(handle, **_frames_to_arrays(frames, key))


def load_frames(path):
    """Frames saved by :func:`save_frames` (or a dataset cache file)."""
    with np.load(path, allow_pickle=False) as stored:
        if stored["version"].item() != GENERATOR_VERSION:
            raise ValueError(f"{path} was written by scene generator {stored['version'].item()}, "
                             f"this is {GENERATOR_VERSION}")
        return _frames_from_arrays(stored)
