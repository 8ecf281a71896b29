"""trep's constraints: ``Distance(system, frame1, frame2, distance, name=None)`` (a number,
or the name of a new kinematic config), ``PointOnPlane(system, plane_frame, plane_normal,
point_frame, name=None)`` and ``PointToPoint1D(system, axis, frame1, frame2, name=None)``,
``PointToPoint2D(system, plane, …)``, ``PointToPoint3D(system, frame1, frame2, name=None)``
(one row per axis, ``(p₁ − p₂)[axis]``) — each writes its own table of the system's model
file."""
from __future__ import annotations

import json
from typing import Any, List, Optional, Sequence

import numpy as np

from ._core import Config, Constraint, Frame, System, _BetweenFrames, _toml_string, _vector3

__all__ = ["Distance", "PointOnPlane", "PointToPoint1D", "PointToPoint2D", "PointToPoint3D"]


class Distance(_BetweenFrames, Constraint):
    """``|p₁ − p₂|² − ℓ²`` for two frames' origins (trep's row, and tree-mech's); ``distance``
    a number or the name of a new kinematic config holding ℓ."""

    def __init__(self, system: System, frame1: Any, frame2: Any, distance: Any,
                 name: Optional[str] = None):
        self.frame1, self.frame2 = system.get_frame(frame1), system.get_frame(frame2)
        system._hold()
        try:
            super().__init__(system, name)
            if isinstance(distance, str):
                self.config: Optional[Config] = Config(system, distance, kinematic=True)
                self._distance = 0.0
            else:
                self.config = None
                self._distance = float(distance)
        finally:
            system._release()

    @property
    def distance(self) -> float:
        """The distance held: its kinematic config's ``q``, or the constant."""
        return self.config.q if self.config else self._distance

    def get_actual_distance(self) -> float:
        """``|p₁ − p₂|`` at the current configuration (what ``distance`` should be)."""
        return _actual_distance(self.frame1, self.frame2)

    def _toml(self) -> List[str]:
        length = _toml_string(self.config.name) if self.config else repr(self._distance)
        return ["[[constraint]]", f"name = {_toml_string(self.name)}", 'kind = "distance"',
                self._frames_line(self._system), f"length = {length}", ""]


class PointOnPlane(Constraint):
    """trep's ``n·(p_plane − p_point)``, the normal ``plane_normal`` in ``plane_frame``'s
    axes (tree-mech's plane row with the opposite sign)."""

    _sign = -1.0

    def __init__(self, system: System, plane_frame: Any, plane_normal: Sequence[float],
                 point_frame: Any, name: Optional[str] = None):
        self.plane_frame = system.get_frame(plane_frame)
        self.point_frame = system.get_frame(point_frame)
        where = _between("PointOnPlane", self.plane_frame, self.point_frame)
        self.normal = _vector3(plane_normal, f"{where}: plane_normal")
        if not any(self.normal):
            raise ValueError(f"{where}: plane_normal must not be zero")
        system._hold()
        try:
            super().__init__(system, name)
        finally:
            system._release()

    def _frames(self) -> tuple:
        return (self.plane_frame, self.point_frame)

    def _toml(self) -> List[str]:
        s = self._system
        return ["[[constraint]]", f"name = {_toml_string(self.name)}", 'kind = "plane"',
                f"frames = [{_toml_string(s._frame_key(self.plane_frame))}, "
                f"{_toml_string(s._frame_key(self.point_frame))}]",
                f"normal = {json.dumps(self.normal)}", ""]


class PointToPoint1D(_BetweenFrames, Constraint):
    """trep's ``(p₁ − p₂)[axis]`` for two frames' origins along one world axis (``"x"``,
    ``"y"`` or ``"z"``): tree-mech's point row on that axis."""

    def __init__(self, system: System, axis: str, frame1: Any, frame2: Any,
                 name: Optional[str] = None):
        self.frame1, self.frame2 = system.get_frame(frame1), system.get_frame(frame2)
        if axis not in ("x", "y", "z"):
            raise ValueError(f"{_between('PointToPoint1D', self.frame1, self.frame2)}: axis "
                             f"must be 'x', 'y' or 'z', got {axis!r}")
        self.axis = axis
        system._hold()
        try:
            super().__init__(system, name)
        finally:
            system._release()

    def get_actual_distance(self) -> float:
        """``|p₁ − p₂|``, the whole distance between the origins (zero when held)."""
        return _actual_distance(self.frame1, self.frame2)

    def _toml(self) -> List[str]:
        # trep lets a 3-D point constraint's three rows share one name; the model's rows
        # need their own.
        earlier = [c.name for c in self._system._constraints[: self.index]]
        key = self.name if self.name not in earlier else f"{self.name}#{self.index}"
        return ["[[constraint]]", f"name = {_toml_string(key)}", 'kind = "point"',
                self._frames_line(self._system), f"axes = {_toml_string(self.axis)}", ""]


def _between(kind: str, frame1: Frame, frame2: Frame) -> str:
    """Where an error is: the element's kind and its two frames."""
    return f"{kind} between `{frame1.name}` and `{frame2.name}`"


def _actual_distance(frame1: Frame, frame2: Frame) -> float:
    return float(np.linalg.norm(np.asarray(frame1.p())[:3] - np.asarray(frame2.p())[:3]))


class _PointToPoint:
    """trep's ``PointToPoint2D``/``3D``: one :class:`PointToPoint1D` row per axis, all
    named ``name``."""

    def __init__(self, system: System, axes: str, frame1: Any, frame2: Any,
                 name: Optional[str]):
        self.frame1, self.frame2 = system.get_frame(frame1), system.get_frame(frame2)
        system._hold()
        try:
            self.constraints = [PointToPoint1D(system, a, frame1, frame2, name) for a in axes]
        finally:
            system._release()

    def get_actual_distance(self) -> float:
        """``|p₁ − p₂|``, the whole distance between the origins (zero when held)."""
        return _actual_distance(self.frame1, self.frame2)


class PointToPoint3D(_PointToPoint):
    """trep's ``PointToPoint3D(system, frame1, frame2, name=None)``: the origins held
    together, three rows (x, y, z)."""

    def __init__(self, system: System, frame1: Any, frame2: Any, name: Optional[str] = None):
        super().__init__(system, "xyz", frame1, frame2, name)


class PointToPoint2D(_PointToPoint):
    """trep's ``PointToPoint2D(system, plane, frame1, frame2, name=None)``: the origins held
    together in ``plane`` (``"xy"``, ``"xz"`` or ``"yz"``), two rows."""

    def __init__(self, system: System, plane: str, frame1: Any, frame2: Any,
                 name: Optional[str] = None):
        if plane not in ("xy", "xz", "yz"):
            where = _between("PointToPoint2D", system.get_frame(frame1), system.get_frame(frame2))
            raise ValueError(f"{where}: plane must be 'xy', 'xz' or 'yz', got {plane!r}")
        super().__init__(system, plane, frame1, frame2, name)
