"""trep's potentials: ``Gravity(system, gravity=[0, 0, -9.8], name=None)``,
``ConfigSpring(system, config, k, q0=0.0, name=None)`` and
``LinearSpring(system, frame1, frame2, k, x0=0.0, name=None)``."""
from ._core import _ConfigSpring as ConfigSpring
from ._core import _Gravity as Gravity
from ._core import _LinearSpring as LinearSpring

__all__ = ["ConfigSpring", "Gravity", "LinearSpring"]
