"""trep's forces: ``Damping(system, default_damping=0.0, damping=None, name=None)``,
``ConfigForce(system, config, finput, name=None)`` (an input pushing on a config) and
``LinearDamper(system, frame1, frame2, c, name=None)``."""
from ._core import _ConfigForce as ConfigForce
from ._core import _Damping as Damping
from ._core import _LinearDamper as LinearDamper

__all__ = ["ConfigForce", "Damping", "LinearDamper"]
