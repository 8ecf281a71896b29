"""trep's potentials: ``Gravity(system, gravity=[0, 0, -9.8], name=None)``,
``ConfigSpring(system, config, k, q0=0.0, name=None)`` and
``LinearSpring(system, frame1, frame2, k, x0=0.0, name=None)`` — each writes its own part
of the system's model file — and ``NonlinearConfigSpring(system, config, spline, m=1.0,
b=0.0, name=None)``, called back by the runtime."""
from __future__ import annotations

from typing import Any, List, Optional, Sequence

import numpy as np

from ._core import Config, Potential, System, _BetweenFrames, _toml_string, _vector3
from ._spline import Spline

__all__ = ["ConfigSpring", "Gravity", "LinearSpring", "NonlinearConfigSpring"]


class Gravity(Potential):
    """Uniform gravity ``gravity`` (default ``[0, 0, -9.8]``) on every mass."""

    def __init__(self, system: System, gravity: Sequence[float] = (0.0, 0.0, -9.8),
                 name: Optional[str] = None):
        self.gravity = _vector3(gravity, "Gravity: gravity")
        super().__init__(system, name)

    def _gravity(self) -> Sequence[float]:
        return self.gravity

    def V(self) -> float:
        """``−Σ m g·p`` over the frames' masses (trep's frames carry their mass at their
        origin)."""
        g = np.asarray(self.gravity, dtype=float)
        return -float(sum(f.mass * (g @ f.p()[:3]) for f in self._system.frames if f.mass))


class ConfigSpring(Potential):
    """``½k(q − q0)²`` on one config."""

    def __init__(self, system: System, config: Any, k: float, q0: float = 0.0,
                 name: Optional[str] = None):
        self.config = system.get_config(config) if not isinstance(config, Config) else config
        self.k, self.q0 = float(k), float(q0)
        super().__init__(system, name)

    def V(self) -> float:
        """``½k(q − q0)²``."""
        return 0.5 * self.k * (self.config.q - self.q0) ** 2

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

    def V(self) -> float:
        """``½k(|p₁ − p₂| − x0)²``."""
        d = float(np.linalg.norm((self.frame1.p() - self.frame2.p())[:3]))
        return 0.5 * self.k * (d - self.x0) ** 2

    def _toml(self) -> List[str]:
        return ["[[spring]]", self._frames_line(self._system), f"stiffness = {self.k!r}",
                f"rest = {self.x0!r}", ""]


class NonlinearConfigSpring(Potential):
    """A spring on one config whose force is a curve: ``∂V/∂q = −f(m·q + b)`` with ``f`` a
    :class:`Spline` (trep's sign: the force on the config is ``+f(m·q + b)``), so
    ``∂²V/∂q² = −m f′`` and ``∂³V/∂q³ = −m² f″``. ``V`` itself is the exact integral,
    ``V(q) = −∫₀^q f(m·s + b) ds`` (zero at ``q = 0``), where trep's ``V`` is 0: the energy
    this layer reports includes the spring's (docs/python.md)."""

    #: Called back by the runtime (its curve is no model text).
    _called_back = True

    def __init__(self, system: System, config: Any, spline: Spline, m: float = 1.0,
                 b: float = 0.0, name: Optional[str] = None):
        self.config = system.get_config(config) if not isinstance(config, Config) else config
        if not isinstance(spline, Spline):
            raise TypeError("NonlinearConfigSpring: spline must be a trep.Spline")
        self.spline, self.m, self.b = spline, float(m), float(b)
        super().__init__(system, name)

    def _at(self) -> float:
        return self.m * self.config.q + self.b

    def V(self) -> float:
        """``−∫₀^q f(m·s + b) ds``."""
        q = self.config.q
        if self.m == 0.0:
            return -self.spline.y(self.b) * q
        return -self.spline.integral(self.b, self._at()) / self.m

    def V_dq(self, q1: Config) -> float:
        """``−f(m·q + b)`` on the spring's config."""
        return -self.spline.y(self._at()) if q1 is self.config else 0.0

    def V_dqdq(self, q1: Config, q2: Config) -> float:
        """``−m f′(m·q + b)``."""
        if q1 is not self.config or q2 is not self.config:
            return 0.0
        return -self.m * self.spline.dy(self._at())

    def V_dqdqdq(self, q1: Config, q2: Config, q3: Config) -> float:
        """``−m² f″(m·q + b)``."""
        if not q1 is q2 is q3 is self.config:
            return 0.0
        return -self.m ** 2 * self.spline.ddy(self._at())
