"""Plots shared by the run report and the paper's figures (matplotlib Figure objects, never pyplot).

Every plot has labelled axes with units, a legend where there is more than
one thing to tell apart, and a title.

Examples
--------
>>> from cmosnoise import plots
>>> fig, ax = plots.figure(figsize=(3, 2))     # a matplotlib Figure, no pyplot
>>> len(plots.to_png_bytes(fig)) > 100      # the figure as PNG bytes
True
"""

from __future__ import annotations

import base64
import io

import numpy as np

from ..io.output import png_bytes

_FIGURE_KEYS = ("figsize", "dpi", "facecolor", "edgecolor", "layout")


def figure(*args, **kwargs):
    """``(fig, axes)`` as ``pyplot.subplots`` gives them, on a :class:`matplotlib.figure.Figure` of its own: no
    pyplot, no global backend switch (a notebook's backend is left alone), nothing to close.

    Parameters
    ----------
    *args, **kwargs
        As ``pyplot.subplots`` takes them (``figsize``, ``dpi``, ``layout`` go to the figure, the rest to
        ``Figure.subplots``).

    Returns
    -------
    (matplotlib.figure.Figure, Axes or array of Axes)
    """
    from matplotlib.figure import Figure

    fig = Figure(**{k: kwargs.pop(k) for k in _FIGURE_KEYS if k in kwargs})
    return fig, fig.subplots(*args, **kwargs)


def to_png_bytes(fig, dpi: int = 100) -> bytes:
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi, bbox_inches="tight")
    return buf.getvalue()


def image_png_bytes(img: np.ndarray) -> bytes:
    return png_bytes(img)


def data_uri(png: bytes) -> str:
    return "data:image/png;base64," + base64.b64encode(png).decode("ascii")


# ------------------------------------------------------------------ histograms
def log_histogram_axes(ax, xlabel: str, title: str, ylabel: str = "pixels per bin (log)") -> None:
    """Log count axis, labels, title and a legend: the dress of every histogram here.

    Parameters
    ----------
    ax : matplotlib.axes.Axes
        Where to draw.
    xlabel, title, ylabel : str
        The labels.
    """
    ax.set_yscale("log")
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.set_title(title)
    ax.legend(fontsize=8)


def dark_current_histogram(ax, rate: np.ndarray, state, title: str = "") -> None:
    """Dark-current map on log rate and log count axes, body and tail told apart, threshold marked (paper Figs. 5, 6).

    The rate axis is logarithmic so that the body (a few e-/s) and the tail
    (up to tens of thousands) both show; pixels at exactly 0 (a body clipped
    at 0) are counted in the legend.

    Parameters
    ----------
    ax : matplotlib.axes.Axes
        Where to draw.
    rate : array, e-/s
        The dark-current map.
    state : DarkState or None
        Its parameters (:attr:`Sensor.dark_state`): body and tail told apart, the threshold marked.
    title : str
    """
    r = rate.ravel().astype(np.float64)
    pos = r[r > 0]
    top = max(float(r.max()), 1.0)
    low = max(float(pos.min()) if pos.size else 1e-3, top * 1e-6)
    bins = np.geomspace(low, top * 1.02, 200)
    zeros = int(r.size - pos.size)
    ax.hist(pos, bins=bins, color="C0", alpha=0.8,
            label=f"map ({r.size} pixels" + (f"; {zeros} at 0 e-/s not shown" if zeros else "") + ")")
    if state is not None and state.tail_fraction > 0:
        if state.between:  # a per-pixel interpolation: the body's top from the map itself
            body_top = float(np.quantile(r, 1 - state.tail_fraction))
        else:
            body_top = float(state.model.body.ppf(1 - 1e-7))
        ax.axvspan(body_top, top * 1.02, color="C3", alpha=0.08,
                   label=f"white-pixel tail: {100 * state.tail_fraction:.3g} % of pixels up to {state.tail_max:.0f} e-/s")
    if state is not None and state.threshold is not None:
        above = 1e6 * float((r > state.threshold).mean())
        ax.axvline(state.threshold, color="C3", ls="--",
                   label=f"threshold {state.threshold:.0f} e-/s: {above:.0f} ppm above")
    log_histogram_axes(ax, "dark current [e-/s per pixel, log]", title or "Dark-current non-uniformity")
    ax.set_xscale("log")


def temporal_noise_histogram(ax, sigma: np.ndarray, model=None, threshold: float | None = None, title: str = "",
                             xlabel: str = "per-pixel temporal noise [e- rms]") -> None:
    """Per-pixel temporal noise on a log count axis, with the model's density (paper Fig. 7).

    Parameters
    ----------
    ax : matplotlib.axes.Axes
        Where to draw.
    sigma : array, e- rms
        Each pixel's temporal noise.
    model : distribution, optional
        Its law (with a ``cdf``), drawn as the expected counts per bin.
    threshold : float, optional
        A tail threshold to mark, e- rms.
    title, xlabel : str
    """
    s = sigma.ravel().astype(np.float64)
    bins = np.linspace(0, max(float(s.max()), 1e-6) * 1.02, 150)
    counts, edges, _ = ax.hist(s, bins=bins, color="C0", alpha=0.8, label=f"pixels ({s.size})")
    if model is not None:
        x = (edges[1:] + edges[:-1]) / 2
        expected = s.size * np.diff(model.cdf(edges))
        ax.plot(x, np.maximum(expected, 1e-3), "C1-", lw=1.5, label="model: Gumbel body + uniform tail")
    if threshold is not None:
        ax.axvline(threshold, color="C3", ls="--", label=f"tail threshold {threshold:g}")
    log_histogram_axes(ax, xlabel, title or "Temporal noise across the array")
    ax.set_ylim(bottom=0.5)


def noise_budget_bars(ax, dark: dict, scene: dict) -> None:
    """Each temporal source's rms at dark and at the scene's mean level.

    Parameters
    ----------
    ax : matplotlib.axes.Axes
        Where to draw.
    dark, scene : dict
        :func:`cmosnoise.analysis.noise_budget.budget` in the dark and at the scene's mean.
    """
    from ..analysis.noise_budget import by_size

    names = by_size(dark, scene)
    y = np.arange(len(names))
    ax.barh(y - 0.2, [dark["temporal_rms_e"].get(n, 0) for n in names], 0.4, label="dark")
    ax.barh(y + 0.2, [scene["temporal_rms_e"].get(n, 0) for n in names], 0.4,
            label=f"scene mean ({scene['signal_e']:.0f} e-)")
    from ..analysis.noise_budget import SOURCE_NAMES

    ax.set_yticks(y, [SOURCE_NAMES.get(n, n) for n in names])
    ax.invert_yaxis()
    ax.set_xlabel("temporal noise [e- rms]")
    ax.set_title("Noise budget")
    ax.legend()


def circle_couplets(ax, pairs: np.ndarray, offset=(0, 0), scale: float = 1.0, radius: float = 6.0, color="white") -> None:
    """Circle each couplet (pairs of (row, col)) on an image axis.

    Parameters
    ----------
    ax : matplotlib.axes.Axes
        Where to draw.
    pairs : (n, 2, 2) int array
        Couplets (:func:`cmosnoise.analysis.white_pixels.couplet_pairs`).
    offset : (row, col)
        The image's top-left pixel on the sensor.
    scale : float
        Image pixels per sensor pixel.
    radius : float
        The circles' radius, image pixels.
    color : matplotlib colour
    """
    from matplotlib.patches import Circle

    for (r1, c1), (r2, c2) in pairs:
        cy = ((r1 + r2) / 2 - offset[0]) * scale
        cx = ((c1 + c2) / 2 - offset[1]) * scale
        ax.add_patch(Circle((cx, cy), radius, fill=False, color=color, lw=2))


def densest_window(mask: np.ndarray, size: tuple[int, int]) -> tuple[int, int]:
    """Top-left corner of the ``size`` window holding the most True pixels.

    Parameters
    ----------
    mask : (rows, cols) bool array
    size : (rows, cols)
        The window's size.

    Returns
    -------
    (int, int)
        The window's top-left pixel.
    """
    from scipy import ndimage

    h, w = min(size[0], mask.shape[0]), min(size[1], mask.shape[1])
    counts = ndimage.uniform_filter(mask.astype(np.float32), size=(h, w), mode="constant")
    r, c = np.unravel_index(np.argmax(counts), counts.shape)
    r0 = int(np.clip(r - h // 2, 0, mask.shape[0] - h))
    c0 = int(np.clip(c - w // 2, 0, mask.shape[1] - w))
    return r0, c0
