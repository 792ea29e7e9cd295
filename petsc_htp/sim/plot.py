"""Charts for ``examples/multiphase_flow.py``: ms per frame of one or more runs, and a GIF of a run."""
import json
from pathlib import Path

import numpy as np

from ..atomic import atomic_open

FPS_LINES = ((60, "60 fps"), (24, "24 fps"))


def read_jsonl(path):
    """The records of a JSONL file, one dict per line."""
    with open(path) as handle:
        return [json.loads(line) for line in handle if line.strip()]


def plot_runs(jsonl_paths, out_png):
    """Draw setup + solve ms against frame for each run, with the 60 and 24 fps budgets.

    Parameters
    ----------
    jsonl_paths : sequence of path-like
        Per-frame records with ``frame``, ``setup_ms``, ``solve_ms`` and ``method``.
    out_png : path-like
        Output PNG, written atomically.
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    from matplotlib.ticker import FormatStrFormatter, MaxNLocator

    fig = Figure(figsize=(9, 4.5))
    FigureCanvasAgg(fig)
    ax = fig.subplots()
    for path in jsonl_paths:
        records = read_jsonl(path)
        ms = [r["setup_ms"] + r["solve_ms"] for r in records]
        label = records[0]["method"] if records else Path(path).stem
        ax.plot([r["frame"] for r in records], ms, marker=".", label=label)
    for fps, text in FPS_LINES:
        ax.axhline(1e3 / fps, color="grey", linestyle="--", linewidth=1)
        ax.annotate(text, (1.0, 1e3 / fps), xycoords=("axes fraction", "data"), ha="right",
                    xytext=(-4, 2), textcoords="offset points", color="grey")
    ax.set_yscale("log")
    ax.yaxis.set_major_formatter(FormatStrFormatter("%g"))
    ax.yaxis.set_minor_formatter(FormatStrFormatter("%g"))
    ax.xaxis.set_major_locator(MaxNLocator(integer=True))
    ax.set_xlabel("frame")
    ax.set_ylabel("pressure solve ms (setup + solve)")
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0))
    fig.tight_layout()
    with atomic_open(out_png, "wb") as handle:
        fig.savefig(handle, format="png", dpi=100)


def write_gif(densities, pressures, path, fps=20):
    """Animate density (log scale) and pressure images side by side.

    Parameters
    ----------
    densities, pressures : sequence of numpy.ndarray, shape (ny, nx)
        One image per frame, row 0 at the bottom, NaN in solid cells.
    path : path-like
        Output GIF, written atomically.
    fps : int
        Playback frames per second.
    """
    from matplotlib import colormaps
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.colors import LogNorm
    from matplotlib.figure import Figure
    from PIL import Image

    fig = Figure(figsize=(8, 4))
    canvas = FigureCanvasAgg(fig)
    ax_rho, ax_p = fig.subplots(1, 2)
    top = max(float(np.nanmax(d)) for d in densities)
    style = {"origin": "lower", "interpolation": "nearest"}
    rho_im = ax_rho.imshow(np.ma.masked_invalid(densities[0]), norm=LogNorm(1.0, max(top, 1.0 + 1e-9)),
                           cmap=colormaps["viridis"].with_extremes(bad="0.5"), **style)
    p_im = ax_p.imshow(np.ma.masked_invalid(pressures[0]),
                       cmap=colormaps["coolwarm"].with_extremes(bad="0.5"), **style)
    ax_rho.set_title("density")
    fig.colorbar(rho_im, ax=ax_rho, shrink=0.8)
    fig.colorbar(p_im, ax=ax_p, shrink=0.8)
    images = []
    for k, (rho, p) in enumerate(zip(densities, pressures)):
        rho_im.set_data(np.ma.masked_invalid(rho))
        p_im.set_data(np.ma.masked_invalid(p))
        p_im.set_clim(np.nanmin(p), np.nanmax(p))
        ax_p.set_title(f"pressure, frame {k}")
        canvas.draw()
        images.append(Image.fromarray(np.asarray(canvas.buffer_rgba())[..., :3].copy()))
    with atomic_open(path, "wb") as handle:
        images[0].save(handle, format="GIF", save_all=True, append_images=images[1:],
                       duration=int(1000 / fps), loop=0)
