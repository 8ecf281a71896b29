"""trep's potentials: ``Gravity(system, gravity=[0, 0, -9.8], name=None)`` and
``ConfigSpring(system, config, k, q0=0.0, name=None)``."""
from ._core import _ConfigSpring as ConfigSpring
from ._core import _Gravity as Gravity

__all__ = ["ConfigSpring", "Gravity"]
