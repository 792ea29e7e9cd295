"""Pictures of benchmark frames: density, right-hand side and pressure with velocity arrows."""
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


def plot_frame(frame, path, pressure=None):
    """Save a PNG with density, right-hand side and optionally pressure panels.

    Parameters
    ----------
    frame : Frame
    path : str or Path
        Output PNG, written atomically.
    pressure : array_like, shape (N,), optional
        Solution in Morton order; adds a pressure panel with velocity arrows.
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.colors import LogNorm
    from matplotlib.figure import Figure

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
