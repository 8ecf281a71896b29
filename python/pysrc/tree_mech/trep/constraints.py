"""trep's constraints: ``Distance(system, frame1, frame2, distance, name=None)`` (a number,
or the name of a new kinematic config) and ``PointOnPlane(system, plane_frame, plane_normal,
point_frame, name=None)``."""
from ._core import _Distance as Distance
from ._core import _PointOnPlane as PointOnPlane

__all__ = ["Distance", "PointOnPlane"]
