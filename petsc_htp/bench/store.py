"""Result files of a benchmark folder, every one written atomically (temp file + os.replace)."""
from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from ..atomic import write_text

META = "meta.json"
REPORT = "report.md"


def clean(value):
    """``value`` with NaN/Inf floats turned into None (strict JSON) and numpy scalars into Python ones."""
    if isinstance(value, dict):
        return {str(k): clean(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [clean(v) for v in value]
    if isinstance(value, np.ndarray):
        return clean(value.tolist())
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def write_json(path, obj):
    """Write one JSON document atomically."""
    write_text(path, json.dumps(clean(obj), indent=2, sort_keys=True) + "\n")


def read_json(path):
    """Read one JSON document."""
    return json.loads(Path(path).read_text())


def write_jsonl(path, rows):
    """Write rows as JSON lines atomically."""
    write_text(path, "".join(json.dumps(clean(row), sort_keys=True) + "\n" for row in rows))


def read_jsonl(path):
    """Rows of a JSON-lines file (an empty list if it does not exist)."""
    path = Path(path)
    if not path.is_file():
        return []
    return [json.loads(line) for line in path.read_text().splitlines() if line.strip()]


def study_path(out, study):
    """The raw-rows file of ``study`` in results folder ``out``."""
    return Path(out) / f"{study}.jsonl"
