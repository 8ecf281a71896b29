"""trep's forces: ``Damping(system, default_damping=0.0, damping=None, name=None)``,
``ConfigForce(system, config, finput, name=None)`` (an input pushing on a config) and
``LinearDamper(system, frame1, frame2, c, name=None)`` — each writes its own part of the
system's model file — and the constant wrenches ``BodyWrench``, ``SpatialWrench``,
``HybridWrench`` ``(system, frame, wrench=(), name=None)``, called back by the runtime."""
from __future__ import annotations

from typing import Any, Dict, List, Optional

from ._core import Config, Force, Input, System, _BetweenFrames, _toml_string
from ._wrenches import BodyWrench, HybridWrench, SpatialWrench

__all__ = ["BodyWrench", "ConfigForce", "Damping", "HybridWrench", "LinearDamper",
           "SpatialWrench"]


class Damping(Force):
    """Viscous damping ``−c q̇`` on every dynamic config: ``damping`` maps config names to
    ``c``, ``default_damping`` for the rest."""

    def __init__(self, system: System, default_damping: float = 0.0,
                 damping: Optional[Dict[Any, float]] = None, name: Optional[str] = None):
        self.default_damping = float(default_damping)
        self._damping = {}
        known = system._config_names()
        for k, v in (damping or {}).items():
            key = k.name if isinstance(k, Config) else k
            if key not in known:
                raise KeyError(f"Damping: no config {key!r} in the system")
            self._damping[key] = float(v)
        super().__init__(system, name)

    def _damping_on(self, config: Config) -> float:
        return self.get_damping_coefficient(config)

    def get_damping_coefficient(self, config: Config) -> float:
        """The damping coefficient on ``config`` (the default where none was set)."""
        return self._damping.get(config.name, self.default_damping)

    def set_damping_coefficient(self, config: Config, coefficient: float) -> None:
        """Sets the damping coefficient on ``config``."""
        self._damping[config.name] = float(coefficient)
        self._system._structure_changed()


class ConfigForce(Force):
    """The input ``finput`` as a generalized force on ``config``."""

    def __init__(self, system: System, config: Any, finput: Optional[str],
                 name: Optional[str] = None):
        self.config = system.get_config(config) if not isinstance(config, Config) else config
        if self.config.kinematic:
            raise ValueError(f"a ConfigForce acts on a dynamic config; `{self.config.name}` "
                             "is kinematic")
        system._hold()
        try:
            self.finput = Input(system, finput)
            self.finput._force = self
            super().__init__(system, name)
        finally:
            system._release()

    def _toml(self) -> List[str]:
        return ["[[input]]", f"name = {_toml_string(self.finput.name)}",
                f"variable = {_toml_string(self.config.name)}", ""]


class LinearDamper(_BetweenFrames, Force):
    """A damper between two frames' origins: ``−c ℓ̇`` along the line, ``ℓ = |p₁ − p₂|``."""

    def __init__(self, system: System, frame1: Any, frame2: Any, c: float,
                 name: Optional[str] = None):
        self.frame1, self.frame2 = system.get_frame(frame1), system.get_frame(frame2)
        self.c = float(c)
        super().__init__(system, name)

    def _toml(self) -> List[str]:
        return ["[[damper]]", self._frames_line(self._system), f"damping = {self.c!r}", ""]
