"""trep's constraints: ``Distance(system, frame1, frame2, distance, name=None)`` (a number,
or the name of a new kinematic config), ``PointOnPlane(system, plane_frame, plane_normal,
point_frame, name=None)`` and ``PointToPoint1D(system, axis, frame1, frame2, name=None)``,
``PointToPoint2D(system, plane, …)``, ``PointToPoint3D(system, frame1, frame2, name=None)``
(one row per axis, ``(p₁ − p₂)[axis]``)."""
from ._core import _Distance as Distance
from ._core import _PointOnPlane as PointOnPlane
from ._core import _PointToPoint1D as PointToPoint1D
from ._core import _PointToPoint2D as PointToPoint2D
from ._core import _PointToPoint3D as PointToPoint3D

__all__ = ["Distance", "PointOnPlane", "PointToPoint1D", "PointToPoint2D", "PointToPoint3D"]
