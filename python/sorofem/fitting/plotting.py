"""The figure of a fit: data against the fitted curve, one panel per test mode."""

from __future__ import annotations

from typing import Any

import numpy as np

from .curves import MODES

__all__ = ["plot_fit"]

_UNITS = ((1e6, "MPa"), (1e3, "kPa"), (1.0, "Pa"))


def _new_figure(n_panels: int) -> Any:
    # An Agg canvas of its own, not pyplot: no window, the user's backend untouched.
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(4.2 * n_panels, 3.6), dpi=120, layout="constrained")
    FigureCanvasAgg(fig)
    return fig


def plot_fit(fit: Any, ax: Any = None) -> Any:
    """Data (markers) and fit (line) of a :class:`~sorofem.fitting.MaterialFit` per mode;
    returns the Figure (see :meth:`~sorofem.fitting.MaterialFit.plot`)."""
    modes = [m for m in MODES if any(c.mode == m for c in fit.curves)]
    if ax is None:
        fig = _new_figure(len(modes))
        axes = list(np.atleast_1d(fig.subplots(1, len(modes), squeeze=False)[0]))
    elif isinstance(ax, (list, tuple, np.ndarray)):
        axes = list(np.ravel(ax))
        if len(axes) != len(modes):
            raise ValueError(f"ax holds {len(axes)} Axes but the data have {len(modes)} test modes ({', '.join(modes)})")
        fig = axes[0].figure
    else:
        axes = [ax] * len(modes)
        fig = ax.figure
    peak = max(float(np.abs(c.nominal_stress).max()) for c in fit.curves)
    scale, unit = next(((s, u) for s, u in _UNITS if peak >= s), _UNITS[-1])
    for mode, axis in zip(modes, axes):
        curves = [c for c in fit.curves if c.mode == mode]
        lo = min(float(c.stretch.min()) for c in curves)
        hi = max(float(c.stretch.max()) for c in curves)
        for curve in curves:
            axis.plot(curve.stretch, curve.nominal_stress / scale, "o", ms=3.5, mfc="none",
                      label=f"{mode} data ({_short(curve.source)})")
        grid = np.linspace(min(lo, 1.0), max(hi, 1.0), 300)
        axis.plot(grid, fit.predict(mode, grid) / scale, "-", lw=1.6, label=f"{mode} fit ({fit.model})")
        stable = fit.stable[mode]
        if stable is not None:
            for bound, reached in ((stable.lower, stable.lower_reached), (stable.upper, stable.upper_reached)):
                if reached and grid[0] <= bound <= grid[-1]:
                    axis.axvline(bound, ls="--", lw=1.0, color="0.4", label="Drucker limit")
        axis.axhline(0.0, lw=0.5, color="0.7")
        axis.set_xlabel("stretch")
        axis.set_ylabel(f"nominal stress ({unit})")
        axis.set_title(mode if len(set(map(id, axes))) > 1 else "data and fit")
        axis.legend(fontsize="small")
    return fig


def _short(source: str) -> str:
    return source.replace("\\", "/").rsplit("/", 1)[-1]
