"""trep's ``plot_spline``: a spline, its slope and its curvature over its points' span, drawn
with matplotlib (trep's opens a Qt dialog)."""
from __future__ import annotations

from typing import Any

import numpy as np

from . import _pyplot

__all__ = ["plot_spline"]


def plot_spline(spline: Any, points: int = 1000) -> Any:
    """Draws ``y``, ``dy`` and ``ddy`` of ``spline`` at ``points`` places from its first
    point to its last, its points marked; shows the figure (a window, where matplotlib has
    one) and returns it."""
    plt = _pyplot()
    xs = np.asarray(spline.x_points, dtype=float)
    x = np.linspace(xs.min(), xs.max(), int(points))
    fig, axes = plt.subplots(3, 1, sharex=True, figsize=(6, 7))
    for ax, name, f in zip(axes, ("y", "dy", "ddy"), (spline.y, spline.dy, spline.ddy)):
        ax.plot(x, [f(v) for v in x])
        ax.set_ylabel(name)
    axes[0].plot(xs, spline.y_points, "o")
    axes[-1].set_xlabel("x")
    plt.show()
    return fig
