"""Pictures of benchmark frames: density, right-hand side and pressure with velocity arrows (2-D); in 3-D,
slices through the box's centre and a projection."""
import numpy as np

from ..atomic import atomic_open


def _image_gradient(image, spacing, axis):
    """``numpy.gradient`` along ``axis``, zero when the axis has one cell."""
    if image.shape[axis] < 2:
        return np.zeros_like(image)
    return np.gradient(image, spacing, axis=axis)


def _show(fig, ax, image, title, **style):
    """Draw one image panel with a colour bar."""
    shown = ax.imshow(np.ma.masked_invalid(image), origin="lower",
                      extent=(0, 1, 0, 1), interpolation="nearest", **style)
    fig.colorbar(shown, ax=ax, shrink=0.8)
    ax.set_title(title)


def _draw_velocity(ax, pressure, rho):
    """Quiver of ``-grad(p) / rho`` on a subsampled grid (none if it is zero)."""
    h, w = pressure.shape
    u = -_image_gradient(pressure, 1.0 / w, axis=1) / rho
    v = -_image_gradient(pressure, 1.0 / h, axis=0) / rho
    if not np.any(np.nan_to_num(np.hypot(u, v))):
        return
    step = max(1, max(w, h) // 20)
    x, y = np.meshgrid((np.arange(w) + 0.5) / w, (np.arange(h) + 0.5) / h)
    sub = (slice(None, None, step), slice(None, None, step))
    ax.quiver(x[sub], y[sub], np.ma.masked_invalid(u[sub]),
              np.ma.masked_invalid(v[sub]), color="black")


def _slices(volume):
    """The (D, H, W) volume's central x-y, x-z and y-z slices and its mean along y (x-z), with titles."""
    d, h, w = volume.shape
    with np.errstate(all="ignore"):
        side = np.nanmean(volume, axis=1)
    return [(volume[d // 2], "x-y slice, z = 1/2"), (volume[:, h // 2, :], "x-z slice, y = 1/2"),
            (volume[:, :, w // 2], "y-z slice, x = 1/2"), (side, "x-z, mean along y")]


def plot_frame(frame, path, pressure=None):
    """Save a PNG with density, right-hand side and optionally pressure panels.

    A 3-D frame shows its density in three central slices and a projection (the mean along y), then the
    right-hand side and the pressure in the central x-z slice.

    Parameters
    ----------
    frame : Frame
    path : str or Path
        Output PNG, written atomically.
    pressure : array_like, shape (N,), optional
        Solution in Morton order; adds a pressure panel (2-D: with velocity arrows).
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.colors import LogNorm
    from matplotlib.figure import Figure

    if frame.dim == 3:
        return _plot_volume(frame, path, pressure)
    rho = frame.to_image(frame.rho)
    rhs = frame.to_image(frame.b)
    panels = 2 if pressure is None else 3
    fig = Figure(figsize=(4.5 * panels, 4))
    FigureCanvasAgg(fig)
    axes = fig.subplots(1, panels, squeeze=False)[0]
    _show(fig, axes[0], rho, "density", cmap="viridis", norm=LogNorm())
    limit = float(np.nanmax(np.abs(rhs))) or 1.0
    _show(fig, axes[1], rhs, "right-hand side", cmap="RdBu_r", vmin=-limit, vmax=limit)
    if pressure is not None:
        p = frame.to_image(pressure)
        _show(fig, axes[2], p, "pressure, velocity -grad(p)/rho", cmap="coolwarm")
        _draw_velocity(axes[2], p, rho)
    fig.tight_layout()
    with atomic_open(path, "wb") as handle:
        fig.savefig(handle, format="png", dpi=100)


def _plot_volume(frame, path, pressure):
    """:func:`plot_frame` of a 3-D frame."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.colors import LogNorm
    from matplotlib.figure import Figure

    rho = frame.to_image(frame.rho)
    scale = {"cmap": "viridis", "norm": LogNorm(vmin=float(np.nanmin(rho)), vmax=float(np.nanmax(rho)))}
    panels = [(image, "density, " + title, scale) for image, title in _slices(rho)]
    rhs = _slices(frame.to_image(frame.b))[1][0]
    limit = float(np.nanmax(np.abs(rhs))) or 1.0
    panels.append((rhs, "right-hand side, x-z slice", {"cmap": "RdBu_r", "vmin": -limit, "vmax": limit}))
    if pressure is not None:
        panels.append((_slices(frame.to_image(pressure))[1][0], "pressure, x-z slice", {"cmap": "coolwarm"}))
    fig = Figure(figsize=(4.5 * 3, 4 * ((len(panels) + 2) // 3)))
    FigureCanvasAgg(fig)
    axes = fig.subplots((len(panels) + 2) // 3, 3, squeeze=False).ravel()
    for ax, (image, title, style) in zip(axes, panels):
        _show(fig, ax, image, title, **style)
    for ax in axes[len(panels):]:
        ax.set_axis_off()
    fig.tight_layout()
    with atomic_open(path, "wb") as handle:
        fig.savefig(handle, format="png", dpi=100)
