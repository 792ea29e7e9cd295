"""Charts for ``examples/multiphase_flow.py``: ms per frame of one or more runs, and a GIF of a run."""
import json
from pathlib import Path

import numpy as np

from ..atomic import atomic_open
from .flow import image

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


def heavy_view(theta, solid, light=(-0.4, -0.7, 0.6)):
    """The heavy phase of a 3-D flow seen along y (front to back), shaded: an RGB image (nz, nx, 3).

    Each pixel shows the first heavy cell (``theta >= 1/2``) or obstacle cell along its line of sight,
    darker with depth and lit from the direction ``light`` (x, y, z; the viewer is at -y) through the normal
    of the depth map; empty lines of sight show the back wall.

    Parameters
    ----------
    theta : numpy.ndarray, shape (nz, ny, nx)
        Heavy fraction of every cell.
    solid : numpy.ndarray of bool, same shape
        Obstacle cells.
    """
    nz, ny, nx = theta.shape
    hit = (theta >= 0.5) | solid
    seen = hit.any(axis=1)
    first = np.where(seen, hit.argmax(axis=1), ny)                  # (nz, nx) depth of the first hit
    depth = first / ny
    dzd, dxd = np.gradient(depth * ny / max(nx, nz))
    normal = np.stack([-dxd, -np.ones_like(depth), -dzd], axis=-1)
    normal /= np.linalg.norm(normal, axis=-1, keepdims=True)
    lit = np.clip(normal @ (np.asarray(light) / np.linalg.norm(light)), 0.0, 1.0)
    z, x = np.nonzero(seen)
    obstacle = np.zeros(seen.shape, dtype=bool)
    obstacle[z, x] = solid[z, first[z, x], x]
    base = np.where(obstacle[..., None], [0.55, 0.5, 0.45], [0.15, 0.4, 0.85])
    shade = (0.25 + 0.75 * lit)[..., None] * (1.0 - 0.4 * depth)[..., None]
    return np.where(seen[..., None], base * shade, [0.93, 0.93, 0.95])


def frame_images(flow, p):
    """The two panels of a GIF frame: density and pressure (2-D), or :func:`heavy_view` and the pressure's
    central x-z slice (3-D)."""
    if flow.dim == 2:
        return image(flow, flow.density()), image(flow, p)
    return heavy_view(flow.theta(), ~flow.fluid), image(flow, p)[:, flow.fluid.shape[1] // 2, :]


def write_gif(densities, pressures, path, fps=20):
    """Animate density (log scale) and pressure images side by side.

    Parameters
    ----------
    densities : sequence of numpy.ndarray, shape (ny, nx), or of RGB images (rows, cols, 3)
        One image per frame, row 0 at the bottom, NaN in solid cells; an RGB image (a 3-D flow's
        :func:`heavy_view`) is shown as it is.
    pressures : sequence of numpy.ndarray, shape (ny, nx)
        One image per frame (a 3-D flow's central slice).
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
    style = {"origin": "lower", "interpolation": "nearest"}
    if densities[0].ndim == 3:
        rho_im = ax_rho.imshow(densities[0], **style)
        ax_rho.set_title("heavy phase, seen along y")
        ax_rho.set_axis_off()
    else:
        top = max(float(np.nanmax(d)) for d in densities)
        rho_im = ax_rho.imshow(np.ma.masked_invalid(densities[0]), norm=LogNorm(1.0, max(top, 1.0 + 1e-9)),
                               cmap=colormaps["viridis"].with_extremes(bad="0.5"), **style)
        ax_rho.set_title("density")
        fig.colorbar(rho_im, ax=ax_rho, shrink=0.8)
    p_im = ax_p.imshow(np.ma.masked_invalid(pressures[0]),
                       cmap=colormaps["coolwarm"].with_extremes(bad="0.5"), **style)
    fig.colorbar(p_im, ax=ax_p, shrink=0.8)
    images = []
    for k, (rho, p) in enumerate(zip(densities, pressures)):
        rho_im.set_data(rho if rho.ndim == 3 else np.ma.masked_invalid(rho))
        p_im.set_data(np.ma.masked_invalid(p))
        p_im.set_clim(np.nanmin(p), np.nanmax(p))
        ax_p.set_title(f"pressure{', central x-z slice' if rho.ndim == 3 else ''}, frame {k}")
        canvas.draw()
        images.append(Image.fromarray(np.asarray(canvas.buffer_rgba())[..., :3].copy()))
    with atomic_open(path, "wb") as handle:
        images[0].save(handle, format="GIF", save_all=True, append_images=images[1:],
                       duration=int(1000 / fps), loop=0)
