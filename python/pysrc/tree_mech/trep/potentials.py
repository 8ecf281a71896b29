"""trep's potentials: ``Gravity(system, gravity=[0, 0, -9.8], name=None)``,
``ConfigSpring(system, config, k, q0=0.0, name=None)`` and
``LinearSpring(system, frame1, frame2, k, x0=0.0, name=None)`` — each writes its own part
of the system's model file."""
from __future__ import annotations

from typing import Any, List, Optional, Sequence

from ._core import Config, Potential, System, _BetweenFrames, _toml_string, _vector3

__all__ = ["ConfigSpring", "Gravity", "LinearSpring"]


class Gravity(Potential):
    """Uniform gravity ``gravity`` (default ``[0, 0, -9.8]``) on every mass."""

    def __init__(self, system: System, gravity: Sequence[float] = (0.0, 0.0, -9.8),
                 name: Optional[str] = None):
        self.gravity = _vector3(gravity, "Gravity: gravity")
        super().__init__(system, name)

    def _gravity(self) -> Sequence[float]:
        return self.gravity


class ConfigSpring(Potential):
    """``½k(q − q0)²`` on one config."""

    def __init__(self, system: System, config: Any, k: float, q0: float = 0.0,
                 name: Optional[str] = None):
        self.config = system.get_config(config) if not isinstance(config, Config) else config
        self.k, self.q0 = float(k), float(q0)
        super().__init__(system, name)

    def _toml(self) -> List[str]:
        return ["[[spring]]", f"variable = {_toml_string(self.config.name)}",
                f"stiffness = {self.k!r}", f"rest = {self.q0!r}", ""]


class LinearSpring(_BetweenFrames, Potential):
    """A spring between two frames' origins, ``½k(|p₁ − p₂| − x0)²``."""

    def __init__(self, system: System, frame1: Any, frame2: Any, k: float, x0: float = 0.0,
                 name: Optional[str] = None):
        self.frame1, self.frame2 = system.get_frame(frame1), system.get_frame(frame2)
        self.k, self.x0 = float(k), float(x0)
        super().__init__(system, name)

    def _toml(self) -> List[str]:
        return ["[[spring]]", self._frames_line(self._system), f"stiffness = {self.k!r}",
                f"rest = {self.x0!r}", ""]
