"""trep's viewer, ``trep.visual``, drawn with matplotlib: a script that ends by showing its
trajectory (``visualize_3d([VisualItem3D(system, t, q)])``, ``PuppetVisual``) runs to its
end and shows it.

trep's viewer is a Qt/OpenGL window; this one is a matplotlib animation of the same items —
each frame a line from its parent's origin to its own, each mass a dot sized by its mass, the
trajectory played at 25 pictures a second of its time — shown in a window, or written to a
file with ``save=`` (``.gif`` by Pillow, which matplotlib brings; other kinds by matplotlib's
writers). Drawings a script attaches (``attachDrawing``) are OpenGL or Qt calls: they are
kept but not drawn (the frames are). matplotlib is needed only here:
``pip install matplotlib``.
"""
from __future__ import annotations

import os
import warnings
from typing import Any, Callable, List, Optional, Sequence, Tuple

import numpy as np

__all__ = ["VisualItem", "VisualItem2D", "VisualItem3D", "stlmodel", "visualize_2d",
           "visualize_3d"]

#: Pictures a second of the trajectory's time.
FPS = 25.0


class VisualItem:
    """A system and its trajectory: times ``time``, configurations ``q`` (one row per time,
    trep's config order) and inputs ``u`` (one row per step, as trep's trajectories hold
    them)."""

    def __init__(self, system: Any, time: Any = None, q: Any = None, u: Any = None):
        self._system = system
        self._time = np.asarray([] if time is None else time, dtype=float)
        self._q = np.asarray([] if q is None else q, dtype=float)
        self._u = np.asarray([] if u is None else u, dtype=float)
        if len(self._q) and len(self._q) != len(self._time):
            raise ValueError(f"{len(self._q)} configurations for {len(self._time)} times; a "
                             "trajectory has one configuration per time")
        #: ``(frame, function)`` a script attached (not drawn: the module's docs).
        self.drawings: List[Tuple[Any, Callable]] = []

    @property
    def system(self) -> Any:
        """The system drawn."""
        return self._system

    def attachDrawing(self, frame: Any, func: Callable) -> None:  # noqa: N802 (trep's name)
        """Keeps a drawing function for ``frame`` (trep's OpenGL/Qt drawing: not called
        here; the frames are drawn instead)."""
        self.drawings.append((self._system.get_frame(frame) if frame else None, func))

    def setTime(self, t: float) -> None:  # noqa: N802 (trep's name)
        """Puts the system at time ``t`` of the trajectory (clamped to its span), its
        configuration and inputs interpolated linearly between the samples."""
        if len(self._time) == 0:
            return
        t = min(max(t, float(self._time.min())), float(self._time.max()))
        self._system.t = t
        if len(self._q):
            self._system.q = _interpolate(self._time, self._q, t)
        if len(self._u) and len(self._time) > 1:
            self._system.u = _interpolate(self._time[: len(self._u)], self._u, t)

    def getTimeRange(self) -> Optional[Tuple[float, float, np.ndarray]]:  # noqa: N802
        """``(first, last, times)`` of the trajectory, or None without one."""
        if len(self._time) == 0:
            return None
        return float(self._time.min()), float(self._time.max()), self._time

    def _place(self, p: np.ndarray) -> np.ndarray:
        """A world point where the picture shows it."""
        return p

    def skeleton(self) -> Tuple[List[Tuple[np.ndarray, np.ndarray]],
                                List[Tuple[np.ndarray, float]]]:
        """At the system's current state: a segment from each frame's parent's origin to its
        own, and each massive frame's origin with its mass."""
        lines, masses = [], []
        for frame in self._system.frames:
            p = self._place(np.asarray(frame.p()[:3], dtype=float))
            parent = frame.parent
            if parent is not None:
                lines.append((self._place(np.asarray(parent.p()[:3], dtype=float)), p))
            if frame.mass:
                masses.append((p, float(frame.mass)))
        return lines, masses


class stlmodel:  # noqa: N801 (trep's name)
    """An STL mesh a script draws on a frame (``attachDrawing(frame, stlmodel(path).draw)``):
    the file must exist, as trep loads it, but the mesh is not drawn (the frames are)."""

    def __init__(self, filename: str, wireframe: bool = False, normals: bool = False,
                 color: Any = None, scale: Sequence[float] = (1.0, 1.0, 1.0)):
        if not os.path.isfile(filename):
            raise FileNotFoundError(f"stlmodel: no STL file {filename!r}")
        self.filename, self.wireframe, self.normals = filename, wireframe, normals
        self.color, self.scale = color, tuple(scale)

    def draw(self) -> None:
        """Nothing: the viewer draws frames, not meshes."""


def _interpolate(times: np.ndarray, rows: np.ndarray, t: float) -> np.ndarray:
    """``rows`` at ``t`` by linear interpolation between the samples at ``times``."""
    k = int(np.clip(np.searchsorted(times, t, side="right") - 1, 0, len(times) - 1))
    if k + 1 >= len(times) or times[k + 1] == times[k]:
        return rows[min(k, len(rows) - 1)].copy()
    w = (t - times[k]) / (times[k + 1] - times[k])
    return (1.0 - w) * rows[k] + w * rows[k + 1]


class VisualItem2D(VisualItem):
    """An item drawn in a plane of world axes (``plane="XY"``, trep's default, or ``"XZ"``,
    ``"YZ"`` …)."""

    def __init__(self, *args: Any, plane: str = "XY", **kwds: Any):
        super().__init__(*args, **kwds)
        if len(plane) != 2 or any(a not in "XYZ" for a in plane) or plane[0] == plane[1]:
            raise ValueError(f"plane {plane!r}: two different axes of X, Y, Z, as 'XY'")
        self.plane = plane
        self._axes = ["XYZ".index(a) for a in plane]

    def _place(self, p: np.ndarray) -> np.ndarray:
        return p[self._axes]


class VisualItem3D(VisualItem):
    """An item drawn in 3-D: ``offset`` moves it, ``setOrientation(forward, up)`` turns the
    world so that ``forward`` points along the picture's x and ``up`` up (trep's)."""

    def __init__(self, *args: Any, density: float = 50.0, offset: Any = None, **kwds: Any):
        super().__init__(*args, **kwds)
        self.density = density
        self.offset = None if offset is None else np.asarray(offset, dtype=float)
        self.setOrientation(forward=[1, 0, 0], up=[0, 0, 1])

    def setOrientation(self, forward: Sequence[float], up: Sequence[float]) -> None:  # noqa: N802
        """Turns the world so that ``forward`` (made square to ``up``) is the picture's x
        and ``up`` its z."""
        up_v = np.asarray(up, dtype=float)
        right = np.cross(up_v, np.asarray(forward, dtype=float))
        if np.linalg.norm(right) == 0.0 or np.linalg.norm(up_v) == 0.0:
            raise ValueError("setOrientation: forward and up must be nonzero and not parallel")
        fwd = np.cross(right, up_v)
        world = np.eye(4)
        world[:3, 0] = fwd / np.linalg.norm(fwd)
        world[:3, 1] = right / np.linalg.norm(right)
        world[:3, 2] = up_v / np.linalg.norm(up_v)
        self._orientation = world.T  # the inverse of a rotation

    def orientation(self) -> np.ndarray:
        """The 4 × 4 turn from world axes to the picture's."""
        return self._orientation.copy()

    def _place(self, p: np.ndarray) -> np.ndarray:
        p = self._orientation[:3, :3] @ p
        return p if self.offset is None else p + self.offset


def _times(items: Sequence[VisualItem]) -> np.ndarray:
    """The pictures' times: the items' whole span at :data:`FPS` (one picture without one)."""
    spans = [r for r in (i.getTimeRange() for i in items) if r is not None]
    if not spans:
        return np.zeros(1)
    first, last = min(r[0] for r in spans), max(r[1] for r in spans)
    count = max(1, int(round((last - first) * FPS)) + 1)
    return np.linspace(first, last, count)


def _pyplot() -> Any:
    try:
        import matplotlib.pyplot as plt
    except ImportError:
        raise ImportError("trep.visual draws with matplotlib: pip install matplotlib") from None
    return plt


#: matplotlib's backends that draw no window.
_HEADLESS = ("agg", "pdf", "ps", "svg", "cairo", "template", "pgf")


def _animate(items: Sequence[VisualItem], three_d: bool, limits: Callable,
             save: Optional[str]) -> int:
    plt = _pyplot()
    if save is None:
        import matplotlib
        backend = matplotlib.get_backend()
        if backend.lower() in _HEADLESS:
            warnings.warn(f"trep.visual: matplotlib has no window here (its backend is "
                          f"{backend}); pass save='run.gif' to write the animation to a file",
                          RuntimeWarning, stacklevel=3)
            return 0
    from matplotlib.animation import FuncAnimation, PillowWriter
    times = _times(items)
    fig = plt.figure(figsize=(6, 6))
    ax = fig.add_subplot(projection="3d") if three_d else fig.add_subplot()
    pictures = []
    for t in times:
        for item in items:
            item.setTime(float(t))
        pictures.append([item.skeleton() for item in items])
    limits(ax, [p for picture in pictures for lines, masses in picture
                for p in [a for seg in lines for a in seg] + [m[0] for m in masses]])
    title = ax.set_title("")

    def draw(k: int) -> List[Any]:
        for artist in list(ax.lines) + list(ax.collections):
            artist.remove()
        for lines, masses in pictures[k]:
            for a, b in lines:
                ax.plot(*zip(a, b), color="0.25", linewidth=1.5)
            if masses:
                points = np.array([m[0] for m in masses])
                sizes = [20.0 * max(m[1], 1e-3) ** (2.0 / 3.0) for m in masses]
                ax.scatter(*points.T, s=sizes, color="tab:blue")
        title.set_text(f"t = {times[k]:.2f} s")
        return list(ax.lines) + list(ax.collections)

    animation = FuncAnimation(fig, draw, frames=len(times), interval=1000.0 / FPS,
                              blit=False, repeat=True)
    if save is not None:
        writer = PillowWriter(fps=FPS) if str(save).lower().endswith(".gif") else None
        animation.save(str(save), writer=writer)
        plt.close(fig)
    else:
        plt.show()
    return 0


def _box(ax: Any, points: List[np.ndarray], three_d: bool, center: Any = None,
         scale: Any = None) -> None:
    """Equal axes around every point drawn (or trep's ``center`` and ``scale``)."""
    pts = np.array(points) if points else np.zeros((1, 3 if three_d else 2))
    mid = (pts.max(axis=0) + pts.min(axis=0)) / 2 if center is None else np.asarray(center)
    if scale is not None:
        half = float(scale)
    else:  # the figure's widest extent, a margin around it (1 for a single point)
        half = 0.55 * float(np.max(pts.max(axis=0) - pts.min(axis=0))) or 1.0
    ax.set_xlim(mid[0] - half, mid[0] + half)
    ax.set_ylim(mid[1] - half, mid[1] + half)
    if three_d:
        ax.set_zlim(mid[2] - half, mid[2] + half)
    else:
        ax.set_aspect("equal")


def visualize_3d(items: Sequence[VisualItem], argv: Sequence[str] = (),
                 camera_pos: Any = None, camera_ang: Any = None,
                 save: Optional[str] = None) -> int:
    """Plays the items' trajectories in 3-D (trep's ``visualize_3d``; ``camera_pos`` and
    ``camera_ang`` are accepted and the view fits the figure instead); ``save`` writes the
    animation to that file instead of showing it. Returns 0, as trep's window does."""
    del argv, camera_pos, camera_ang
    return _animate(items, True, lambda ax, pts: _box(ax, pts, True), save)


def visualize_2d(items: Sequence[VisualItem], argv: Sequence[str] = (), center: Any = None,
                 scale: Any = None, save: Optional[str] = None) -> int:
    """Plays the items' trajectories in their planes (trep's ``visualize_2d``, ``center``
    and ``scale`` its view); ``save`` writes the animation to that file instead."""
    del argv
    return _animate(items, False, lambda ax, pts: _box(ax, pts, False, center, scale), save)
