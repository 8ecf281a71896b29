"""trep's forces: ``Damping(system, default_damping=0.0, damping=None, name=None)`` and
``ConfigForce(system, config, finput, name=None)`` (an input pushing on a config)."""
from ._core import _ConfigForce as ConfigForce
from ._core import _Damping as Damping

__all__ = ["ConfigForce", "Damping"]
