"""PETSc options files: the repository's ``options/`` folder and a parser that follows includes.

Used by the example and the benchmark alike (PETSc itself reads the same files
with ``-options_file``); no PETSc import is needed to parse them.
"""
from __future__ import annotations

import shlex
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
OPTIONS_DIR = ROOT / "options"


def _resolve(path, base=None) -> Path:
    """An options file: as given, against the cwd, the repository root, then ``base``."""
    p = Path(path).expanduser()
    candidates = [p] if p.is_absolute() else [Path.cwd() / p, ROOT / p] + ([base / p] if base else [])
    for cand in candidates:
        if cand.is_file():
            return cand.resolve()
    raise FileNotFoundError(f"options file {path} not found (looked in {Path.cwd()} and {ROOT})")


def _is_number(text) -> bool:
    try:
        float(text)
        return True
    except ValueError:
        return False


def read_options_file(path, _base=None, _seen=None) -> list:
    """Parse a PETSc options file into ``[(name without '-', value or None)]``, following includes."""
    path = _resolve(path, _base)
    seen = set() if _seen is None else _seen
    if path in seen:
        raise ValueError(f"options file {path} includes itself")
    seen.add(path)
    tokens = []
    for line in path.read_text().splitlines():
        tokens += shlex.split(line, comments=True)
    pairs, i = [], 0
    while i < len(tokens):
        key = tokens[i]
        if not key.startswith("-") or _is_number(key):
            raise ValueError(f"{path}: expected an option, got {key!r}")
        value = None
        if i + 1 < len(tokens) and (not tokens[i + 1].startswith("-") or _is_number(tokens[i + 1])):
            value = tokens[i + 1]
            i += 1
        i += 1
        if key == "-options_file":
            pairs += read_options_file(value, path.parent, seen)
        else:
            pairs.append((key.lstrip("-"), value))
    return pairs
