"""The trep layer's core: a trep-style system of frames, configs, potentials, forces,
constraints and inputs, written as a tree-mech model and evaluated by the Rust runtime.

trep's conventions kept here: configuration vectors list the dynamic configs, then the
kinematic ones, each in creation order (``Config.index``; ``Config.k_index`` among the
kinematic); matrices are indexed (output, input); a distance constraint is ``|d| − ℓ`` and
its multiplier is scaled to match (tree-mech writes ``d·d − ℓ²``, whose gradient is ``2|d|``
times trep's). The model is rebuilt whenever the structure changes (a frame, config,
potential, force, input or constraint added, a mass or a constant changed).
"""
from __future__ import annotations

import json
import math
import re
import warnings
from typing import Any, Dict, List, Optional, Sequence, Tuple, Union

import numpy as np

from .. import _native
from . import _force_inputs as force_inputs
from . import _products as products
from ._python_terms import PythonTerms, defined_in_python

#: No values (a step without inputs or kinematic configs), shared: never written.
_NO_VALUES = np.zeros(0)

WORLD = "world"
TX, TY, TZ, RX, RY, RZ = "tx", "ty", "tz", "rx", "ry", "rz"
CONST_SE3 = "const_se3"
_PRIMITIVES = (TX, TY, TZ, RX, RY, RZ)


class ConvergenceError(Exception):
    """The midpoint VI's Newton iteration did not converge (or met a singular Jacobian)."""


def _se3_inverse(g: np.ndarray) -> np.ndarray:
    """``g⁻¹ = [Rᵀ −Rᵀp; 0 1]`` of a rigid motion (exact, no general inverse)."""
    out = np.eye(4)
    rt = g[:3, :3].T
    out[:3, :3] = rt
    out[:3, 3] = -rt @ g[:3, 3]
    return out


def _vector3(v: Any, what: str) -> List[float]:
    """Three finite numbers, or a ValueError naming `what`."""
    out = [float(x) for x in v]
    if len(out) != 3 or not all(np.isfinite(out)):
        raise ValueError(f"{what} must be three finite numbers, got {list(v)!r}")
    return out


def _hidden_input(config: "Config") -> str:
    """The model's name of the hidden force on a dynamic config (``_force_inputs``): never a
    trep input's, which the model would refuse twice."""
    return f"{config.name} (tree_mech.trep: force through inputs)"


def _toml_string(s: str) -> str:
    return json.dumps(s)


class Config:
    """A configuration variable: a frame's parameter or, for a distance constraint given a
    name, the constraint's kinematic length. ``index`` is its place in ``System.configs``
    (dynamic configs first), ``k_index`` its place among the kinematic ones (or -1)."""

    def __init__(self, system: "System", name: str, kinematic: bool = False,
                 frame: Optional["Frame"] = None):
        if name in system._config_names():
            raise ValueError(f"a config named `{name}` already exists")
        self._system = system
        self._name = name
        self._kinematic = bool(kinematic)
        self._frame = frame
        self.index = -1
        self.k_index = -1
        system._configs_created.append(self)
        system._structure_changed()

    def __repr__(self) -> str:
        kind = "kinematic" if self.kinematic else "dynamic"
        return f"<Config {self.name!r} {kind} index={self.index}>"

    @property
    def name(self) -> str:
        """The config's name."""
        return self._name

    @property
    def system(self) -> "System":
        """The system the config belongs to."""
        return self._system

    @property
    def kinematic(self) -> bool:
        """Whether the config is kinematic (prescribed) rather than dynamic."""
        return self._kinematic

    @property
    def frame(self) -> Optional["Frame"]:
        """The frame whose transform the config drives (None until one does)."""
        return self._frame

    # Read directly (a script's own elements read them many times an evaluation).
    # (Inside a call back from the runtime the state is a plain list: see PythonTerms._at.)
    q = property(lambda self: (self._system._q[self.index] if self._system._in_callback
                               else self._system._q.item(self.index)),
                 lambda self, v: self._put("_q", v), doc="The config's value.")
    dq = property(lambda self: (self._system._dq[self.index] if self._system._in_callback
                                else self._system._dq.item(self.index)),
                  lambda self, v: self._put("_dq", v), doc="Its velocity.")
    ddq = property(lambda self: self._system._ddq.item(self.index),
                   lambda self, v: self._put("_ddq", v),
                   doc="Its acceleration (given for a kinematic config; see System.f).")

    def _put(self, array: str, value: float) -> None:
        getattr(self._system, array)[self.index] = value
        self._system._state_changed()


def _check_body(frame: str, mass: Any, Ixx: Any = 0.0, Iyy: Any = 0.0, Izz: Any = 0.0) -> None:
    """A ``ValueError`` naming the frame when a body's mass or moment is negative or not
    finite (before anything is changed)."""
    for what, value in (("mass", mass), ("Ixx", Ixx), ("Iyy", Iyy), ("Izz", Izz)):
        x = float(value)
        if not math.isfinite(x) or x < 0.0:
            raise ValueError(f"frame `{frame}`: {what} {value!r} must be finite and not negative")


class _FrameDef:
    """One frame of an ``import_frames`` tree (made by ``trep.tx`` … ``trep.rz``)."""

    def __init__(self, transform: str, param: Any, name: Optional[str], kinematic: bool,
                 mass: Any):
        self.transform, self.param, self.name = transform, param, name
        self.kinematic, self.mass = kinematic, mass

    def make(self, parent: "Frame") -> "Frame":
        return Frame(parent, self.transform, self.param, name=self.name,
                     kinematic=self.kinematic, mass=self.mass)

    def __repr__(self) -> str:
        return f"{self.transform.lower()}({self.param!r}, name={self.name!r})"


def _definition(transform: str):
    def define(param: Any, name: Optional[str] = None, kinematic: bool = False,
               mass: Any = 0.0) -> _FrameDef:
        return _FrameDef(transform, param, name, kinematic, mass)

    define.__name__ = transform.lower()
    define.__doc__ = (f"A {transform.upper()} frame for ``import_frames``: as ``Frame(parent, "
                      f"trep.{transform.upper()}, param, name=, kinematic=, mass=)`` with the "
                      f"parent given by where the definition sits in the list.")
    return define


tx, ty, tz, rx, ry, rz = (_definition(kind) for kind in _PRIMITIVES)


def const_se3(se3: Any, name: Optional[str] = None, kinematic: bool = False,
              mass: Any = 0.0) -> _FrameDef:
    """trep's constant SE(3) frame for ``import_frames``: ``se3`` is the four columns of its
    local transform (the rotation's three, then the translation), or a 4×4 matrix."""
    return _FrameDef(CONST_SE3, se3, name, kinematic, mass)


def const_txyz(xyz: Any, name: Optional[str] = None, kinematic: bool = False,
               mass: Any = 0.0) -> _FrameDef:
    """trep's constant translation by ``(x, y, z)`` for ``import_frames``."""
    xyz = _vector3(xyz, f"const_txyz {name or '(unnamed)'}")
    return _FrameDef(CONST_SE3, [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0], xyz],
                     name, kinematic, mass)


def _se3(param: Any, name: str) -> np.ndarray:
    """A CONST_SE3 frame's local transform (4×4) from trep's four columns or a 4×4 matrix;
    a ValueError unless its rotation is one."""
    m = np.asarray(param, dtype=float)
    if m.shape == (4, 3):
        g = np.eye(4)
        g[:3, :] = m.T
    elif m.shape == (4, 4):
        g = m.copy()
    else:
        raise ValueError(f"frame {name}: a CONST_SE3 transform is four columns of three "
                         f"(rotation, then translation) or a 4×4 matrix, got shape {m.shape}")
    r = g[:3, :3]
    if not (np.all(np.isfinite(g)) and np.allclose(r.T @ r, np.eye(3), atol=1e-9)
            and np.linalg.det(r) > 0 and np.allclose(g[3], [0, 0, 0, 1])):
        raise ValueError(f"frame {name}: the CONST_SE3 transform is not a rigid motion "
                         f"(its rotation must be orthonormal with determinant 1)")
    return g


def _zyx(r: np.ndarray) -> Tuple[float, float, float]:
    """Angles ``(a, b, c)`` with ``r = Rz(a) Ry(b) Rx(c)``."""
    b = math.asin(max(-1.0, min(1.0, -r[2, 0])))
    if abs(math.cos(b)) > 1e-12:
        return math.atan2(r[1, 0], r[0, 0]), b, math.atan2(r[2, 1], r[2, 2])
    return math.atan2(-r[0, 1], r[1, 1]), b, 0.0  # gimbal lock: all turn about one axis


class Frame:
    """A coordinate frame: ``Frame(parent, trep.TX…trep.RZ, value or config name, name=,
    kinematic=, mass=)``. A number is a constant transform; a name makes a config (kinematic
    when ``kinematic=True``). ``mass`` is a number or ``(m, Ixx, Iyy, Izz)``."""

    def __init__(self, parent: Union["Frame", str, None], transform: str, param: Any,
                 name: Optional[str] = None, kinematic: bool = False, mass: Any = 0.0):
        if transform == WORLD:
            raise ValueError("the world frame is made by System; give frames a parent")
        if transform not in _PRIMITIVES + (CONST_SE3,):
            raise ValueError(f"transform must be one of trep.TX … trep.RZ or trep.CONST_SE3, "
                             f"got {transform!r}")
        if isinstance(parent, str):
            raise TypeError("a Frame's parent is a Frame (use system.get_frame(name))")
        if not isinstance(parent, Frame):
            raise TypeError("a Frame needs a parent Frame (system.world_frame at the root)")
        system = parent.system
        self._system = system
        self._parent = parent
        self._children: List[Frame] = []
        self._transform = transform
        self._mass = 0.0
        self._inertia = (0.0, 0.0, 0.0)
        self._config: Optional[Config] = None
        self._value = 0.0
        self._name = name
        if name is not None and system._frame_named(name) is not None:
            raise ValueError(f"a frame named `{name}` already exists")
        number = isinstance(param, (int, float)) and not isinstance(param, bool)
        if transform == CONST_SE3:
            if isinstance(param, str):
                raise ValueError(f"frame {name or '(unnamed)'}: a CONST_SE3 frame is constant; "
                                 f"it cannot be driven by a config")
            se3 = _se3(param, name or "(unnamed)")
        elif not (isinstance(param, str) or number and np.isfinite(param)):
            raise ValueError(f"frame {name or '(unnamed)'}: the {transform} parameter must be a "
                             f"finite number or a config name, got {param!r}")
        masses = tuple(mass) if isinstance(mass, (tuple, list)) else (mass,)
        _check_body(name or "(unnamed)", *masses)
        parent._children.append(self)
        system._hold()
        try:
            system._frames_created.append(self)
            if transform == CONST_SE3:
                self._value = se3
            elif isinstance(param, str):
                self._config = Config(system, param, kinematic, frame=self)
            else:
                self._value = float(param)
            if isinstance(mass, (tuple, list)):
                self.set_mass(*mass)
            elif mass:
                self.set_mass(mass)
        finally:
            system._release()

    def __repr__(self) -> str:
        what = self._config.name if self._config else self._value
        return f"<Frame {self.name!r} {self._transform}({what})>"

    def import_frames(self, children: Sequence[Any]) -> None:
        """Adds a tree of frames below this one from trep's definition list: each
        ``trep.tx(…)`` … ``trep.rz(…)`` makes a child, and a list right after a definition
        holds that child's own children."""
        if not isinstance(children, (list, tuple)):
            raise TypeError("import_frames takes a list of frame definitions (trep.tx(...), …)")
        system = self._system
        system._hold()
        try:
            last: Optional[Frame] = None
            for item in children:
                if isinstance(item, _FrameDef):
                    last = item.make(self)
                elif isinstance(item, (list, tuple)):
                    if last is None:
                        raise ValueError(
                            "import_frames: a list of children must follow a frame definition")
                    last.import_frames(item)
                    last = None
                else:
                    raise TypeError(f"import_frames: expected a frame definition (trep.tx(...), "
                                    f"…) or a list of them, got {item!r}")
        finally:
            system._release()

    def flatten_tree(self) -> List["Frame"]:
        """This frame and every frame below it."""
        out = [self]
        for child in self._children:
            out.extend(child.flatten_tree())
        return out

    def tree_view(self, indent: int = 0) -> str:
        """The frame and its descendants, one line each, indented by depth (trep's form)."""
        if self._transform == WORLD:
            line = f"<Frame '{self.name}'>"
        elif self._config is not None:
            line = f"<Frame '{self.name}' {self._transform.upper()}({self._config.name})>"
        else:
            line = f"<Frame '{self.name}' {self._transform.upper()}({self._value}) {self._mass:f}>"
        lines = [" " * indent + line]
        lines += [child.tree_view(indent + 3) for child in self._children]
        return "\n".join(lines)

    @property
    def system(self) -> "System":
        """The system the frame belongs to."""
        return self._system

    @property
    def name(self) -> Optional[str]:
        """The frame's name (None for an unnamed frame)."""
        return self._name

    @property
    def parent(self) -> Optional["Frame"]:
        """The parent frame (None for the world frame)."""
        return self._parent

    @property
    def children(self) -> tuple:
        """The frames whose parent this is, in the order they were made."""
        return tuple(self._children)

    @property
    def config(self) -> Optional[Config]:
        """The config driving the frame's transform (None for a constant one)."""
        return self._config

    @property
    def transform_type(self) -> str:
        """The primitive transform: ``trep.TX`` … ``trep.RZ``, or ``trep.CONST_SE3``."""
        return self._transform

    @property
    def transform_value(self) -> float:
        """The transform's value: its config's ``q``, or the constant (settable)."""
        return self._config.q if self._config else self._value

    @transform_value.setter
    def transform_value(self, value: float) -> None:
        if self._config:
            self._config.q = value
        else:
            self._value = (_se3(value, self.name or "(unnamed)") if self._transform == CONST_SE3
                           else float(value))
            self._system._structure_changed()

    @property
    def mass(self) -> float:
        """The frame's mass (settable; ``set_mass`` sets the inertia too)."""
        return self._mass

    @mass.setter
    def mass(self, value: float) -> None:
        self.set_mass(value, *self._inertia)

    @property
    def Ixx(self) -> float:
        """The moment of inertia about the frame's x axis."""
        return self._inertia[0]

    @property
    def Iyy(self) -> float:
        """The moment of inertia about the frame's y axis."""
        return self._inertia[1]

    @property
    def Izz(self) -> float:
        """The moment of inertia about the frame's z axis."""
        return self._inertia[2]

    def set_mass(self, mass: float, Ixx: float = 0.0, Iyy: float = 0.0,
                 Izz: float = 0.0) -> None:
        """A rigid body at this frame's origin: mass and principal moments in its axes.
        A negative or non-finite value is a ``ValueError`` here, where it is set (the model
        would refuse it only at its next evaluation)."""
        _check_body(self.name or "(unnamed)", mass, Ixx, Iyy, Izz)
        self._mass = float(mass)
        self._inertia = (float(Ixx), float(Iyy), float(Izz))
        self._system._structure_changed()

    def uses_config(self, q: Config) -> bool:
        """Whether this frame moves with config ``q``."""
        f: Optional[Frame] = self
        while f is not None and f is not self._system.world_frame:
            if f._config is q:
                return True
            f = f._parent
        return False

    def g(self) -> np.ndarray:
        """The frame's pose in the world (4×4)."""
        if self is self._system.world_frame:
            return np.eye(4)
        return self._system._state()["poses"][self._system._frame_key(self)].copy()

    def p(self) -> np.ndarray:
        """The frame's origin in the world, homogeneous ``[x, y, z, 1]``."""
        return self.g()[:, 3].copy()

    def vb(self) -> np.ndarray:
        """The body velocity in se(3) (4×4: ω̂ and v)."""
        if self is self._system.world_frame:
            return np.zeros((4, 4))
        v = self._system._state()["body_velocities"][self._system._frame_key(self)]
        w = v[3:]
        out = np.zeros((4, 4))
        out[:3, :3] = [[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]]
        out[:3, 3] = v[:3]
        return out

    # Derivatives of the pose and the body velocity by the configs -------------------------
    def _generator(self) -> np.ndarray:
        """``ξ̂``: this frame's primitive as a 4×4 generator, ``d(local)/dq = local · ξ̂``
        (zero for the world, which has none)."""
        out = np.zeros((4, 4))
        if self._transform not in _PRIMITIVES:  # the world, a constant SE(3): no config
            return out
        axis = "xyz".index(self._transform[1])
        if self._transform[0] == "t":
            out[axis, 3] = 1.0
        else:
            a, b = [(1, 2), (2, 0), (0, 1)][axis]
            out[b, a], out[a, b] = 1.0, -1.0
        return out

    def _spatial(self, q: Config) -> Optional[np.ndarray]:
        """``S = g_F ξ̂ g_F⁻¹`` of the frame F that config ``q`` drives, if ``q`` moves this
        frame: then ``∂g/∂q = S g``."""
        if not isinstance(q, Config):
            raise TypeError("expected a Config")
        driven = q.frame
        if driven is None or not self.uses_config(q):
            return None
        pose = driven.g()
        return pose @ driven._generator() @ _se3_inverse(pose)

    def _depth(self) -> int:
        depth, f = 0, self
        while f._parent is not None:
            depth, f = depth + 1, f._parent
        return depth

    def g_dq(self, q1: Config) -> np.ndarray:
        """``∂g/∂q1`` (4×4)."""
        s1 = self._spatial(q1)
        return np.zeros((4, 4)) if s1 is None else s1 @ self.g()

    def g_dqdq(self, q1: Config, q2: Config) -> np.ndarray:
        """``∂²g/∂q1∂q2`` (4×4): the generator nearer the root acts first from the left."""
        s1, s2 = self._spatial(q1), self._spatial(q2)
        if s1 is None or s2 is None:
            return np.zeros((4, 4))
        if q1.frame._depth() > q2.frame._depth():
            s1, s2 = s2, s1
        return s1 @ s2 @ self.g()

    def _pose_by(self, configs: tuple) -> np.ndarray:
        """``∂^S g`` for the configs ``S``: their spatial generators in order from the root,
        then ``g`` (each ``∂/∂q_i`` multiplies by ``S_i`` from the left, the nearer the root
        the further left); zero where one does not move this frame."""
        spatial = [self._spatial(q) for q in configs]
        if any(x is None for x in spatial):
            return np.zeros((4, 4))
        out = self.g()
        depths = [q.frame._depth() for q in configs]
        for _, x in sorted(zip(depths, spatial), key=lambda d: -d[0]):
            out = x @ out
        return out

    def g_dqdqdq(self, q1: Config, q2: Config, q3: Config) -> np.ndarray:
        """``∂³g/∂q1∂q2∂q3`` (4×4)."""
        return self._pose_by((q1, q2, q3))

    def g_dqdqdqdq(self, q1: Config, q2: Config, q3: Config, q4: Config) -> np.ndarray:
        """``∂⁴g/∂q1∂q2∂q3∂q4`` (4×4)."""
        return self._pose_by((q1, q2, q3, q4))

    def p_dqdqdq(self, q1: Config, q2: Config, q3: Config) -> np.ndarray:
        """``∂³p/∂q1∂q2∂q3``, homogeneous."""
        return self.g_dqdqdq(q1, q2, q3)[:, 3].copy()

    def p_dqdqdqdq(self, q1: Config, q2: Config, q3: Config, q4: Config) -> np.ndarray:
        """``∂⁴p/∂q1∂q2∂q3∂q4``, homogeneous."""
        return self.g_dqdqdqdq(q1, q2, q3, q4)[:, 3].copy()

    def p_dq(self, q1: Config) -> np.ndarray:
        """``∂p/∂q1``, homogeneous (last entry 0)."""
        return self.g_dq(q1)[:, 3].copy()

    def p_dqdq(self, q1: Config, q2: Config) -> np.ndarray:
        """``∂²p/∂q1∂q2``, homogeneous."""
        return self.g_dqdq(q1, q2)[:, 3].copy()

    def g_inv(self) -> np.ndarray:
        """``g⁻¹``: the world seen from this frame."""
        return _se3_inverse(self.g())

    def g_inv_dq(self, q1: Config) -> np.ndarray:
        """``∂g⁻¹/∂q1 = −g⁻¹ (∂g/∂q1) g⁻¹``."""
        inv = self.g_inv()
        return -inv @ self.g_dq(q1) @ inv

    def _rate(self) -> np.ndarray:
        """``ġ = Σ_i (∂g/∂q_i) q̇_i``."""
        s = self._system
        return sum((self.g_dq(c) * c.dq for c in s.configs), np.zeros((4, 4)))

    def vb_ddq(self, dq1: Config) -> np.ndarray:
        """``∂v̂_b/∂q̇1 = g⁻¹ ∂g/∂q1`` (4×4)."""
        return self.g_inv() @ self.g_dq(dq1)

    def g_inv_dqdq(self, q1: Config, q2: Config) -> np.ndarray:
        """``∂²g⁻¹/∂q1∂q2`` (the product rule on ``∂g⁻¹ = −g⁻¹ ∂g g⁻¹``)."""
        return products.value(self, products.derivatives([(1.0, (("inv",),))], q1, q2))

    def _body_rate(self, *by: Config) -> np.ndarray:
        """``∂^by v̂_b`` of ``v̂_b = Σ_i q̇_i g⁻¹ ∂g/∂q_i``."""
        out = np.zeros((4, 4))
        for c in self._system.configs:
            if c.dq != 0.0 and self.uses_config(c):
                terms = products.derivatives([(1.0, (("inv",), ("g", (c,))))], *by)
                out += c.dq * products.value(self, terms)
        return out

    def _body_column(self, dq1: Config, *by: Config) -> np.ndarray:
        """``∂^by (g⁻¹ ∂g/∂q1)``: the body velocity's column for ``q̇1``, differentiated."""
        if not self.uses_config(dq1):
            return np.zeros((4, 4))
        return products.value(self, products.derivatives([(1.0, (("inv",), ("g", (dq1,))))],
                                                          *by))

    def vb_dq(self, q1: Config) -> np.ndarray:
        """``∂v̂_b/∂q1`` of ``v̂_b = g⁻¹ ġ`` (4×4)."""
        return self._body_rate(q1)

    def vb_dqdq(self, q1: Config, q2: Config) -> np.ndarray:
        """``∂²v̂_b/∂q1∂q2``."""
        return self._body_rate(q1, q2)

    def vb_dqdqdq(self, q1: Config, q2: Config, q3: Config) -> np.ndarray:
        """``∂³v̂_b/∂q1∂q2∂q3``."""
        return self._body_rate(q1, q2, q3)

    def vb_ddqdq(self, dq1: Config, q2: Config) -> np.ndarray:
        """``∂²v̂_b/∂q̇1∂q2 = ∂(g⁻¹ ∂g/∂q1)/∂q2``."""
        return self._body_column(dq1, q2)

    def vb_ddqdqdq(self, dq1: Config, q2: Config, q3: Config) -> np.ndarray:
        """``∂³v̂_b/∂q̇1∂q2∂q3``."""
        return self._body_column(dq1, q2, q3)

    def lg(self) -> np.ndarray:
        """The transform from the parent to this frame (4×4; the identity for the world)."""
        if self._parent is None:
            return np.eye(4)
        return _se3_inverse(self._parent.g()) @ self.g()

    def lg_dq(self) -> np.ndarray:
        """Its derivative by the primitive's parameter, ``lg · ξ̂`` — for a constant frame
        too, as trep 1.0.2 returns it (its documentation says zero)."""
        return self.lg() @ self._generator()

    def lg_dqdq(self) -> np.ndarray:
        """``lg · ξ̂²``."""
        return self.lg_dq() @ self._generator()

    def lg_dqdqdq(self) -> np.ndarray:
        """``lg · ξ̂³``."""
        return self.lg_dqdq() @ self._generator()

    def lg_inv(self) -> np.ndarray:
        """``lg⁻¹``: the parent seen from this frame."""
        return _se3_inverse(self.lg())

    def lg_inv_dq(self) -> np.ndarray:
        """``−ξ̂ · lg⁻¹``."""
        return -self._generator() @ self.lg_inv()

    def lg_inv_dqdq(self) -> np.ndarray:
        """``ξ̂² · lg⁻¹``."""
        xi = self._generator()
        return xi @ xi @ self.lg_inv()

    def twist_hat(self) -> np.ndarray:
        """The frame's own twist ``ξ̂``: its primitive's generator in its axes (4×4)."""
        return self._generator()


class _World(Frame):
    def __init__(self, system: "System"):
        self._system = system
        self._parent = None
        self._children = []
        self._transform = WORLD
        self._mass = 0.0
        self._inertia = (0.0, 0.0, 0.0)
        self._config = None
        self._value = 0.0
        self._name = "World"

    def __repr__(self) -> str:
        return "<Frame 'World'>"


class Input:
    """An input: one entry of ``System.u`` (trep's finput), ``index`` its place."""

    def __init__(self, system: "System", name: Optional[str]):
        self._system = system
        self.name = name if name is not None else f"input{len(system._inputs) + 1}"
        self.index = len(system._inputs)
        #: The force that reads it; whether the model carries it (a ConfigForce's, on one
        #: config) or a force written in Python reads it (``Force._create_input``).
        self._force: Any = None
        self._in_model = True
        system._inputs.append(self)

    @property
    def system(self) -> "System":
        """The system the input belongs to."""
        return self._system

    @property
    def force(self) -> Any:
        """The force that reads the input."""
        return self._force

    @property
    def u(self) -> float:
        """The input's current value (settable)."""
        return float(self._system._u[self.index])

    @u.setter
    def u(self, value: float) -> None:
        self._system._u[self.index] = value
        self._system._state_changed()

    def __repr__(self) -> str:
        return f"<Input {self.name!r}>"


def _loads_generated(text: str) -> _native.Model:
    """The model of a System's generated TOML. Its problems name frames, configs and
    constraints by the names the script gave; the lines of a text the user never sees are
    dropped from the message."""
    try:
        return _native.loads(text)
    except _native.ModelError as e:
        lines = [re.sub(r"^line \d+: ", "", m) for m in str(e).splitlines()]
        err = _native.ModelError("the system is not a valid model: " + "\n".join(lines))
        err.file, err.line = None, None
        raise err from None


class System:
    """A trep system over tree-mech: frames from ``world_frame`` out, configs, potentials,
    forces, inputs and constraints; state ``q``, ``dq``, ``ddq`` (kinematic accelerations are
    given, dynamic ones computed by ``f()``), ``u`` and ``t``."""

    def __init__(self) -> None:
        self._frames_created: List[Frame] = []
        self._configs_created: List[Config] = []
        self._potentials: List[Any] = []
        self._forces: List[Any] = []
        self._inputs: List[Input] = []
        self._constraints: List[Any] = []
        self._holds = 0
        self._q = np.zeros(0)
        self._dq = np.zeros(0)
        self._ddq = np.zeros(0)
        self._u = np.zeros(0)
        self.t = 0.0
        self._configs: tuple = ()
        self._dyn: tuple = ()
        self._kin: tuple = ()
        self._model: Optional[_native.Model] = None
        self._kinematic_twin: Optional[_native.Model] = None
        #: Whether the runtime is calling the script's elements back (the state is then
        #: plain lists, frames are read on the twin model: ``_state``).
        self._in_callback = False
        # The script's own elements, called back by the native model (_add_python_terms).
        self._terms: Optional[PythonTerms] = None
        self._python_plan: Any = None
        self._cache: Dict[str, Any] = {}
        self._world = _World(self)

    def __repr__(self) -> str:
        return (f"<System {self.nQ} configs, {len(self.frames)} frames, "
                f"{len(self._potentials)} potentials, {self.nc} constraints, "
                f"{len(self._forces)} forces, {self.nu} inputs>")

    # Structure ----------------------------------------------------------------------
    def _hold(self) -> None:
        self._holds += 1

    def _release(self) -> None:
        self._holds -= 1
        if self._holds == 0:
            self._structure_changed()

    def hold_structure_changes(self) -> None:
        """Defer the updates a structure change causes until ``resume_structure_changes``."""
        self._hold()

    def resume_structure_changes(self) -> None:
        """Undo one ``hold_structure_changes``; the last one applies the changes."""
        if self._holds == 0:
            raise RuntimeError("resume_structure_changes without hold_structure_changes")
        self._release()

    def _structure_changed(self) -> None:
        self._model = None
        self._kinematic_twin = None
        self._cache = {}
        if self._holds:
            return
        # Keep each config's state across the renumbering.
        old = {c.name: (self._q[c.index], self._dq[c.index], self._ddq[c.index])
               for c in self._configs if 0 <= c.index < len(self._q)}
        dyn = [c for c in self._configs_created if not c.kinematic]
        kin = [c for c in self._configs_created if c.kinematic]
        self._configs = tuple(dyn + kin)
        self._dyn, self._kin = tuple(dyn), tuple(kin)
        for i, c in enumerate(self._configs):
            c.index = i
            c.k_index = i - len(dyn) if c.kinematic else -1
        n = len(self._configs)
        self._q, self._dq, self._ddq = np.zeros(n), np.zeros(n), np.zeros(n)
        for c in self._configs:
            if c.name in old:
                self._q[c.index], self._dq[c.index], self._ddq[c.index] = old[c.name]
        u = self._u
        self._u = np.zeros(len(self._inputs))
        self._u[: min(len(u), len(self._u))] = u[: len(self._u)]

    def _state_changed(self) -> None:
        self._cache = {}

    def _config_names(self) -> List[str]:
        return [c.name for c in self._configs_created]

    def _frame_named(self, name: str) -> Optional[Frame]:
        if name == "World":
            return self._world
        for f in self._frames_created:
            if f.name == name:
                return f
        return None

    def _frame_key(self, frame: Frame) -> str:
        return frame.name if frame.name is not None else \
            f"frame_{self._frames_created.index(frame) + 1}"

    # Lookups ------------------------------------------------------------------------
    @property
    def world_frame(self) -> Frame:
        """The world frame, the root of the tree."""
        return self._world

    def import_frames(self, children: Sequence[Any]) -> None:
        """``world_frame.import_frames(children)``."""
        self.world_frame.import_frames(children)

    @property
    def frames(self) -> tuple:
        """Every frame, the world frame first."""
        return (self._world,) + tuple(self._frames_created)

    @property
    def configs(self) -> tuple:
        """Every config: the dynamic ones, then the kinematic ones."""
        return self._configs

    @property
    def dyn_configs(self) -> tuple:
        """The dynamic configs."""
        return self._dyn

    @property
    def kin_configs(self) -> tuple:
        """The kinematic (prescribed) configs."""
        return self._kin

    @property
    def potentials(self) -> tuple:
        """The potentials (gravity, springs)."""
        return tuple(self._potentials)

    @property
    def forces(self) -> tuple:
        """The forces (damping, config forces, dampers)."""
        return tuple(self._forces)

    @property
    def inputs(self) -> tuple:
        """The inputs, every force's in the order they were made."""
        return tuple(self._inputs)

    @property
    def constraints(self) -> tuple:
        """The constraints."""
        return tuple(self._constraints)

    @property
    def masses(self) -> tuple:
        """The frames that carry a mass or an inertia."""
        return tuple(f for f in self._frames_created if f.mass or any(f._inertia))

    @property
    def nQ(self) -> int:
        """The number of configs."""
        return len(self._configs)

    @property
    def nQd(self) -> int:
        """The number of dynamic configs."""
        return len(self._dyn)

    @property
    def nQk(self) -> int:
        """The number of kinematic configs."""
        return len(self._kin)

    @property
    def nu(self) -> int:
        """The number of inputs."""
        return len(self._inputs)

    @property
    def nc(self) -> int:
        """The number of constraints."""
        return len(self._constraints)

    @staticmethod
    def _find(items: Sequence[Any], what: str, identifier: Any) -> Any:
        """The item that is `identifier`, is named it, or (an int) sits at that index."""
        is_index = isinstance(identifier, int) and not isinstance(identifier, bool)
        for i, x in enumerate(items):
            if x is identifier or getattr(x, "name", None) == identifier \
                    or (is_index and i == identifier):
                return x
        raise KeyError(f"no {what} {identifier!r} in the system")

    def get_frame(self, identifier: Any) -> Frame:
        """The frame named (or given) by `identifier`; KeyError if there is none."""
        if isinstance(identifier, Frame):
            return identifier
        f = self._frame_named(identifier) if isinstance(identifier, str) else None
        if f is None:
            raise KeyError(f"no frame {identifier!r} in the system")
        return f

    def get_config(self, identifier: Any) -> Config:
        """The config named, indexed or given by `identifier` (KeyError if none)."""
        return self._find(self._configs, "config", identifier)

    def get_potential(self, identifier: Any) -> Any:
        """The potential named, indexed or given by `identifier` (KeyError if none)."""
        return self._find(self._potentials, "potential", identifier)

    def get_constraint(self, identifier: Any) -> Any:
        """The constraint named, indexed or given by `identifier` (KeyError if none)."""
        return self._find(self._constraints, "constraint", identifier)

    def get_force(self, identifier: Any) -> Any:
        """The force named, indexed or given by `identifier` (KeyError if none)."""
        return self._find(self._forces, "force", identifier)

    def get_input(self, identifier: Any) -> Input:
        """The input named, indexed or given by `identifier` (KeyError if none)."""
        return self._find(self._inputs, "input", identifier)

    # State ----------------------------------------------------------------------------
    def _set(self, target: np.ndarray, value: Any, configs: Sequence[Config]) -> None:
        if isinstance(value, dict):
            for k, v in value.items():
                target[self.get_config(k).index] = v
        elif np.ndim(value) == 0:
            # trep's third form: one number for every config of the group.
            target[[c.index for c in configs]] = float(value)
        else:
            v = np.asarray(value, dtype=float).reshape(-1)
            if len(v) != len(configs):
                raise ValueError(f"expected {len(configs)} values, got {len(v)}")
            target[[c.index for c in configs]] = v
        self._state_changed()

    q = property(lambda self: np.array(self._q),
                 lambda self, v: self._set(self._q, v, self._configs),
                 doc="Every config's value, in ``configs`` order (settable).")
    dq = property(lambda self: np.array(self._dq),
                  lambda self, v: self._set(self._dq, v, self._configs),
                  doc="Every config's velocity (settable).")
    ddq = property(lambda self: np.array(self._ddq),
                   lambda self, v: self._set(self._ddq, v, self._configs),
                   doc="Every config's acceleration (settable; ``f`` gives the dynamic ones).")
    qd = property(lambda self: np.array(self._q[: self.nQd]),
                  lambda self, v: self._set(self._q, v, self.dyn_configs),
                  doc="The dynamic configs' values (settable).")
    dqd = property(lambda self: np.array(self._dq[: self.nQd]),
                   lambda self, v: self._set(self._dq, v, self.dyn_configs),
                   doc="The dynamic configs' velocities (settable).")
    ddqd = property(lambda self: np.array(self._ddq[: self.nQd]),
                    lambda self, v: self._set(self._ddq, v, self.dyn_configs),
                    doc="The dynamic configs' accelerations (settable).")
    qk = property(lambda self: np.array(self._q[self.nQd:]),
                  lambda self, v: self._set(self._q, v, self.kin_configs),
                  doc="The kinematic configs' values (settable).")
    dqk = property(lambda self: np.array(self._dq[self.nQd:]),
                   lambda self, v: self._set(self._dq, v, self.kin_configs),
                   doc="The kinematic configs' velocities (settable).")
    ddqk = property(lambda self: np.array(self._ddq[self.nQd:]),
                    lambda self, v: self._set(self._ddq, v, self.kin_configs),
                    doc="The kinematic configs' accelerations (settable).")

    @property
    def u(self) -> np.ndarray:
        """The inputs' current values (settable)."""
        return self._u.copy()

    @u.setter
    def u(self, value: Any) -> None:
        v = np.asarray(value, dtype=float).reshape(-1)
        if len(v) != self.nu:
            raise ValueError(f"expected {self.nu} inputs, got {len(v)}")
        self._u[:] = v
        self._state_changed()

    def set_state(self, q: Any = None, dq: Any = None, u: Any = None, ddqk: Any = None,
                  t: Optional[float] = None) -> None:
        """Sets any of q, dq, u, ddqk and t at once."""
        if q is not None:
            self.q = q
        if dq is not None:
            self.dq = dq
        if u is not None:
            self.u = u
        if ddqk is not None:
            self.ddqk = ddqk
        if t is not None:
            self.t = t
            self._state_changed()

    # The model ----------------------------------------------------------------------
    def _toml(self) -> str:
        """The model file of the system: its frames and configs, then each potential, force
        and constraint's own lines (``_toml``), gravity and damping summed over the parts
        that contribute them."""
        parts = [*self._potentials, *self._forces]
        gravity = [sum(g) for g in zip([0.0, 0.0, 0.0], *(p._gravity() for p in parts))]
        out = ['name = "trep"', f"gravity = {json.dumps([float(g) for g in gravity])}", ""]
        attached = [*self._constraints, *parts]
        if any(self._world in c._frames() for c in attached):
            # An element on the world frame attaches to a fixed frame at the origin.
            out += ["[[frame]]", 'name = "World"', "tx = 0.0", ""]
        for f in self._frames_created:
            out += self._frame_toml(f)
        for c in self._configs:
            damping = sum(p._damping_on(c) for p in parts) if not c.kinematic else 0.0
            out.append(f"[variables.{_toml_string(c.name)}]")
            # The model starts where the system is when it is built: what validation judges
            # (a spring's frames may coincide only at a configuration the script never
            # takes; the runtime refuses them where they do, as trep fails where it does).
            if 0 <= c.index < len(self._q) and self._q[c.index] != 0.0:
                out.append(f"q0 = {float(self._q[c.index])!r}")
            if c.kinematic:
                out.append("kinematic = true")
            if damping:
                out.append(f"damping = {damping!r}")
            out.append("")
        for part in [*parts, *self._constraints]:
            if not defined_in_python(part):  # a script's own element is called back instead
                out += part._toml()
        if any(not i._in_model for i in self._inputs):
            # Inputs a Python force reads: a hidden force on each dynamic config without a
            # ConfigForce (whose input is one already), held at zero, whose derivatives give
            # theirs (_force_inputs).
            pushed = self._config_inputs()
            for c in self.dyn_configs:
                if c.name not in pushed:
                    out += ["[[input]]", f"name = {_toml_string(_hidden_input(c))}",
                            f"variable = {_toml_string(c.name)}", ""]
        return "\n".join(out)

    def _frame_toml(self, f: Frame) -> List[str]:
        """Frame ``f``'s ``[[frame]]`` table."""
        key = self._frame_key(f)
        parent = None if f.parent is self._world else self._frame_key(f.parent)
        out = []
        if f.transform_type == CONST_SE3:
            # Its translations then its ZYX rotation as constant primitives, each but the
            # last a frame of its own (`KEY#1` …, never a trep frame's name).
            g = f._value
            steps = [(k, x) for k, x in zip(("tx", "ty", "tz"), g[:3, 3]) if x != 0.0]
            steps += [(k, x) for k, x in zip(("rz", "ry", "rx"), _zyx(g[:3, :3])) if x != 0.0]
            steps = steps or [("tx", 0.0)]
            for k, (kind, x) in enumerate(steps[:-1]):
                out += ["[[frame]]", f"name = {_toml_string(f'{key}#{k + 1}')}"]
                if parent is not None:
                    out.append(f"parent = {_toml_string(parent)}")
                out += [f"{kind} = {float(x)!r}", ""]
                parent = f"{key}#{k + 1}"
            kind, value = steps[-1][0], repr(float(steps[-1][1]))
        else:
            kind = f.transform_type
            value = _toml_string(f.config.name) if f.config else repr(f._value)
        out += ["[[frame]]", f"name = {_toml_string(key)}"]
        if parent is not None:
            out.append(f"parent = {_toml_string(parent)}")
        out.append(f"{kind} = {value}")
        if f.mass or any(f._inertia):
            out.append(f"mass = {f.mass!r}")
            out.append(f"inertia = {json.dumps(list(f._inertia))}")
        out.append("")
        return out

    def _native_model(self) -> _native.Model:
        if self._holds:
            raise RuntimeError("the structure is on hold (resume_structure_changes first)")
        if self._model is None:
            if not self._configs:
                raise ValueError("the system has no configs")
            self._model = _loads_generated(self._toml())
            index = {name: i for i, name in enumerate(self._model.variables)}
            dynamic = {name: i for i, name in enumerate(self._model.dynamic)}
            kinematic = {name: i for i, name in enumerate(self._model.kinematic)}
            # Model order → trep order: trep_vector = model_vector[perm].
            self._perm = np.array([index[c.name] for c in self._configs], dtype=int)
            self._dperm = np.array([dynamic[c.name] for c in self.dyn_configs], dtype=int)
            self._kperm = np.array([kinematic[c.name] for c in self.kin_configs], dtype=int)
            #: Whether trep's config order is the model's (every vector handed over as is).
            self._model_order_is_trep = all(
                np.array_equal(p, np.arange(len(p))) for p in (self._perm, self._dperm,
                                                               self._kperm))
            self._place_inputs()
            self._add_python_terms()
        return self._model

    def _place_inputs(self) -> None:
        """Where trep's inputs are among the model's (after a build): ``_uin`` the model's
        column of each ConfigForce input (trep's order), ``_through`` the inputs a force
        written in Python reads, ``_hidden`` the model's column of the hidden force on each
        dynamic config (their derivatives: ``_force_inputs``), ``_ucols`` each trep input's
        column among ``(ConfigForce inputs…, through…)``."""
        col = {name: k for k, name in enumerate(self._model.inputs)}
        own = [i for i in self._inputs if i._in_model]
        self._through = [i for i in self._inputs if not i._in_model]
        self._uin = np.array([col[i.name] for i in own], dtype=int)
        pushed = self._config_inputs()
        self._hidden = np.array([col[pushed.get(c.name, _hidden_input(c))]
                                 for c in self.dyn_configs] if self._through else [], dtype=int)
        self._own_index = np.array([i.index for i in own], dtype=int)
        place = {i.index: k for k, i in enumerate(own + self._through)}
        self._ucols = np.array([place[i.index] for i in self._inputs], dtype=int)
        self._n_model_u = len(col)

    def _config_inputs(self) -> Dict[str, str]:
        """Each config a ConfigForce pushes on, with its input's name (the model's inputs are
        ConfigForces' alone)."""
        return {i.force.config.name: i.name for i in self._inputs
                if i._in_model and i.force is not None}

    def _model_u(self, u: np.ndarray) -> np.ndarray:
        """The model's inputs for trep's ``u``: the ConfigForce inputs' values, the hidden
        forces zero (an input a Python force reads acts through its call back)."""
        out = np.zeros(self._n_model_u)
        out[self._uin] = np.asarray(u)[self._own_index]
        return out

    def _input_columns(self, block: np.ndarray) -> np.ndarray:
        """``∂y/∂u`` in trep's input order from ``block`` over the model's inputs, at the
        current state (an input through a Python force: the hidden forces' columns times
        its ``∂F/∂u``, ``_force_inputs``)."""
        if not self._through:
            return block[:, self._uin]
        b = self._terms.input_map(self._q.tolist(), self._dq.tolist(), self._u, False)[0]
        return force_inputs.dynamics_columns(block, self._uin, self._hidden, b)[:, self._ucols]

    def _twin(self) -> _native.Model:
        """The native model without the Python elements (their frames' poses and velocities,
        evaluated while the runtime calls them back), built once per structure."""
        if self._kinematic_twin is None:
            self._native_model()  # the config order (_perm) the evaluation reads
            self._kinematic_twin = _loads_generated(self._toml())
        return self._kinematic_twin

    def _add_python_terms(self) -> None:
        """The script's own potentials, forces and constraints (written in Python), added to
        the native model's terms: the runtime calls them back on every evaluation."""
        self._python_plan = None  # found again for this model
        terms = PythonTerms(self)
        potentials, forces, constraints = terms.parts()
        self._terms = terms if potentials or forces or constraints else None
        if self._terms is None:
            return
        built_in = [c for c in self._constraints if not defined_in_python(c)]
        if constraints and built_in and self._constraints.index(constraints[0]) < \
                self._constraints.index(built_in[-1]):
            raise NotImplementedError(
                f"the constraint {built_in[-1].name!r} is built in but comes after "
                f"{constraints[0].name!r}, written in Python: tree_mech.trep numbers a script's "
                f"own constraints after the built-in ones; create them last")
        self._model.add_python_terms(terms, [c.name for c in constraints])

    def _raise_python_error(self) -> None:
        """Raises what a script's own element raised while the runtime called it back."""
        terms = self._terms
        if terms is not None and terms.error is not None:
            error, terms.error = terms.error, None
            raise error

    def _native_call(self, call: Any, error: type = ValueError, context: str = "") -> Any:
        """``call()`` into the native model: what a script's own element raised while called
        back is raised as itself; otherwise a simulation error is raised as ``error`` (its
        message after ``context``)."""
        try:
            result = call()
        except _native.SimulationError as e:
            self._raise_python_error()
            raise error(f"{context}{e}") from None
        except ValueError:
            self._raise_python_error()  # a script's element failed: its own error, not NaN's
            raise
        self._raise_python_error()
        return result

    def _to_model(self, v: np.ndarray) -> np.ndarray:
        out = np.zeros(len(v))
        out[self._perm] = v
        return out

    def _state(self) -> Dict[str, Any]:
        """The model evaluated at the current state (cached until the state changes). Inside
        a call back from the runtime (a Python element reading a frame), the model without
        the Python elements: the runtime is in the middle of evaluating the other."""
        if "state" not in self._cache:
            m = self._twin() if self._in_callback else self._native_model()
            self._cache["state"] = self._native_call(lambda: m.evaluate(
                self._to_model(self._q), self._to_model(self._dq), self.t,
                self._model_u(self._u) if self._n_model_u else None, ddq=self._to_model(self._ddq)))
        return self._cache["state"]

    def _linear(self) -> Dict[str, Any]:
        if "linear" not in self._cache:
            m = self._native_model()
            self._cache["linear"] = self._native_call(lambda: m.linearize(
                self._to_model(self._q), self._to_model(self._dq),
                self._model_u(self._u) if self._n_model_u else None, self.t, ddq=self._to_model(self._ddq)))
        return self._cache["linear"]

    # The Lagrangian ------------------------------------------------------------------
    def total_energy(self) -> float:
        """T + V at the current state."""
        return float(self._state()["energy"])

    def L(self) -> float:
        """The Lagrangian at the current state."""
        return float(self._state()["L"])

    def _i(self, c: Config) -> int:
        if not isinstance(c, Config):
            raise TypeError("expected a Config")
        self._native_model()
        return int(self._perm[c.index])

    def L_dq(self, q1: Config) -> float:
        """∂L/∂q for config `q1` at the current state."""
        return float(self._state()["dL_dq"][self._i(q1)])

    def L_ddq(self, dq1: Config) -> float:
        """∂L/∂q̇ for config `dq1` at the current state."""
        return float(self._state()["dL_ddq"][self._i(dq1)])

    def L_dqdq(self, q1: Config, q2: Config) -> float:
        """∂²L/∂q∂q for configs `q1`, `q2` at the current state."""
        return float(self._state()["d2L_dqdq"][self._i(q1), self._i(q2)])

    def L_ddqdq(self, dq1: Config, q2: Config) -> float:
        """∂²L/∂q̇∂q for configs `dq1`, `q2` at the current state."""
        return float(self._state()["d2L_ddqdq"][self._i(dq1), self._i(q2)])

    def L_ddqddq(self, dq1: Config, dq2: Config) -> float:
        """∂²L/∂q̇∂q̇ (the mass matrix's entry) for configs `dq1`, `dq2`."""
        return float(self._state()["M"][self._i(dq1), self._i(dq2)])

    # The dynamics ---------------------------------------------------------------------
    def _index(self, kind: str, obj: Any) -> Any:
        """trep's indexing: an object → its index, None → every entry."""
        if obj is None:
            return slice(None)
        if kind in "qd":
            if kind == "d" and obj.kinematic:
                raise TypeError(f"`{obj.name}` is kinematic; a dynamic config is needed")
            return obj.index
        if kind == "k":
            if not obj.kinematic:
                raise TypeError(f"`{obj.name}` is dynamic; a kinematic config is needed")
            return obj.k_index
        return obj.index  # an input or a constraint

    def _dynamics(self) -> Dict[str, Any]:
        """The evaluation at the current state, its dynamic accelerations left in ``ddq`` as
        trep's dynamics calls leave them (until the next such call: a state set afterwards
        does not clear them)."""
        self._native_model()
        state = self._state()
        self._ddq[: self.nQd] = np.asarray(state["qdd"])[self._dperm]
        return state

    def f(self, q: Optional[Config] = None) -> Any:
        """The dynamic configs' accelerations at the current state (one, given a config);
        like every dynamics call, leaves them in ``ddq``."""
        ddq = np.asarray(self._dynamics()["qdd"])[self._dperm]
        return ddq[self._index("d", q)].copy() if q is None else float(ddq[self._index("d", q)])

    def _block(self, key: str, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
        self._dynamics()
        return np.asarray(self._linear()[key])[np.ix_(rows, cols)]

    def _rows_d(self) -> np.ndarray:
        """The rows of trep's dynamic configs among the model's dynamic variables (the rows
        of ``qdd_*``: not their places among all variables, where a kinematic config built
        before a dynamic one shifts them)."""
        self._native_model()
        return self._dperm

    def f_dq(self, q: Optional[Config] = None, q1: Optional[Config] = None) -> Any:
        """``∂q̈_d/∂q`` (one entry, given both configs; a row or column, given one)."""
        m = self._block("qdd_dq", self._rows_d(), self._perm)
        return m[self._index("d", q), self._index("q", q1)]

    def f_ddq(self, q: Optional[Config] = None, dq1: Optional[Config] = None) -> Any:
        """``∂q̈_d/∂q̇`` (one entry, given both configs; a row or column, given one)."""
        m = self._block("qdd_ddq", self._rows_d(), self._perm)
        return m[self._index("d", q), self._index("q", dq1)]

    def f_du(self, q: Optional[Config] = None, u1: Optional[Input] = None) -> Any:
        """``∂q̈_d/∂u`` (an entry, given a config and an input; a row or column, given one)."""
        self._dynamics()
        block = np.asarray(self._linear()["qdd_du"])[self._rows_d()]
        m = self._input_columns(block)
        return m[self._index("d", q), self._index("u", u1)]

    def _kinematic_acceleration_derivatives(self) -> np.ndarray:
        """``∂(q̈_d, λ)/∂q̈_k`` (trep's rows and columns, λ in trep's signs): with
        ``M q̈ = … + Dhᵀλ`` and ``Dh q̈ = …`` the kinematic accelerations enter only through
        ``M_dk q̈_k`` and ``Dh_k q̈_k``, so ``[[M_dd, −Dh_dᵀ], [Dh_d, 0]] X = −[M_dk; Dh_k]``."""
        if "dddk" not in self._cache:
            state = self._dynamics()
            d, k = self._perm[: self.nQd], self._perm[self.nQd:]
            mass = np.asarray(state["M"], dtype=float)
            dh = np.asarray(state["dh_dq"], dtype=float).reshape(self.nc, self.nQ)
            nd, nc = len(d), self.nc
            kkt = np.zeros((nd + nc, nd + nc))
            kkt[:nd, :nd] = mass[np.ix_(d, d)]
            kkt[:nd, nd:] = -dh[:, d].T
            kkt[nd:, :nd] = dh[:, d]
            rhs = -np.vstack([mass[np.ix_(d, k)], dh[:, k]])
            x = np.linalg.solve(kkt, rhs)
            x[nd:] *= self._signs()[:, None]
            self._cache["dddk"] = x
        return self._cache["dddk"]

    def f_dddk(self, q: Optional[Config] = None, k1: Optional[Config] = None) -> Any:
        """``∂q̈_d/∂q̈_k``: how the dynamic accelerations follow the kinematic ones."""
        m = self._kinematic_acceleration_derivatives()[: self.nQd]
        return m[self._index("d", q), self._index("k", k1)]

    def lambda_dddk(self, constraint: Any = None, k1: Optional[Config] = None) -> Any:
        """``∂λ/∂q̈_k`` (trep's rows)."""
        m = self._kinematic_acceleration_derivatives()[self.nQd:]
        return m[self._index("c", constraint), self._index("k", k1)]

    def _signs(self) -> np.ndarray:
        """Per constraint, trep's row over tree-mech's: +1 (a distance: both ``d·d − ℓ²``) or
        −1 (a plane: trep's ``n·(p_plane − p_point)``); multipliers scale the same way."""
        return np.array([c._sign for c in self._constraints], dtype=float)

    def lambda_(self, constraint: Any = None) -> Any:
        """The constraint forces at the current state, for trep's rows."""
        lam = np.asarray(self._dynamics()["lambda"]) * self._signs()
        return lam.copy() if constraint is None else float(lam[self._index("c", constraint)])

    def _lambda_derivative(self, key: str, cols: np.ndarray) -> np.ndarray:
        self._dynamics()
        return np.asarray(self._linear()[key])[:, cols] * self._signs()[:, None]

    def lambda_dq(self, constraint: Any = None, q1: Optional[Config] = None) -> Any:
        """``∂λ/∂q`` (trep's rows and signs)."""
        self._native_model()
        m = self._lambda_derivative("lambda_dq", self._perm)
        return m[self._index("c", constraint), self._index("q", q1)]

    def lambda_ddq(self, constraint: Any = None, dq1: Optional[Config] = None) -> Any:
        """``∂λ/∂q̇`` (trep's rows and signs)."""
        self._native_model()
        m = self._lambda_derivative("lambda_ddq", self._perm)
        return m[self._index("c", constraint), self._index("q", dq1)]

    def lambda_du(self, constraint: Any = None, u1: Optional[Input] = None) -> Any:
        """``∂λ/∂u`` (trep's rows and signs)."""
        self._native_model()
        self._dynamics()
        block = np.asarray(self._linear()["lambda_du"]) * self._signs()[:, None]
        m = self._input_columns(block)
        return m[self._index("c", constraint), self._index("u", u1)]

    # Constraints ----------------------------------------------------------------------
    def _held(self, keep_kinematic: bool, constant_q_list: Any) -> np.ndarray:
        """Per config (trep's order), whether it stays where it is."""
        held = np.zeros(self.nQ, dtype=bool)
        if keep_kinematic:
            held[self.nQd:] = True
        for c in constant_q_list or ():
            held[self.get_config(c).index] = True
        return held

    def satisfy_constraints(self, tolerance: float = 1e-10, verbose: bool = False,
                            keep_kinematic: bool = False,
                            constant_q_list: Optional[Sequence[Any]] = None) -> np.ndarray:
        """Moves the configuration to the nearest one that satisfies every constraint,
        ``q = argmin |q − q₀|² s.t. h(q) = 0`` over the configs that may move (all; the
        dynamic ones with ``keep_kinematic``; less those in ``constant_q_list``), and sets the
        velocity to zero, as trep does. Sets and returns the configuration.

        Each iterate solves the optimality conditions with the constraints linearised at the
        current ``q`` (their curvature left out): ``δ = d − J⁺(J d + h)`` with ``d = q₀ − q``
        and ``J⁺`` the pseudo-inverse of ``∂h/∂q`` on the free configs, so redundant
        constraints are no obstacle; at its fixed point ``h = 0`` and ``q₀ − q`` is normal to
        the constraint surface. Stops when every ``|h|`` is below ``tolerance`` (trep's) and the
        step has settled; raises ``RuntimeError`` (trep's ``StandardError``) when it cannot.
        """
        if not self._constraints:
            self.dq = 0.0
            return self.q
        free = ~self._held(keep_kinematic, constant_q_list)
        q0 = self._q.copy()
        scale = 1.0 + float(np.max(np.abs(q0)))
        worst = math.inf
        for k in range(100):
            model = self._native_model()
            c = self._native_call(lambda: model.constraints_at(self._to_model(self._q),
                                                               second=False))
            h = np.asarray(c["h"], dtype=float)
            jac = np.asarray(c["dh_dq"], dtype=float)[:, self._perm][:, free]
            worst = float(np.max(np.abs(h)))
            d = (q0 - self._q)[free]
            delta = d - np.linalg.pinv(jac) @ (jac @ d + h)
            if verbose:
                print(f"satisfy_constraints: iteration {k}, max |h| = {worst:.3e}, "
                      f"step {float(np.max(np.abs(delta))):.3e}")
            if not np.all(np.isfinite(delta)):
                break
            if worst < tolerance and float(np.max(np.abs(delta))) <= 1e-12 * scale:
                break
            self._q[free] += delta
            self._state_changed()
        if not worst < tolerance:
            raise RuntimeError(
                f"satisfy_constraints: the constraints stay violated by {worst:.3e} "
                f"(tolerance {tolerance:.1e}) from this configuration")
        self.dq = 0.0
        return self.q

    def minimize_potential_energy(self, tolerance: float = 1e-10, verbose: bool = False,
                                  keep_kinematic: bool = False,
                                  constant_q_list: Optional[Sequence[Any]] = None
                                  ) -> np.ndarray:
        """A nearby equilibrium on the constraints: ``q = argmin V(q) s.t. h(q) = 0`` over the
        configs that may move (as :meth:`satisfy_constraints` chooses them), the velocity set
        to zero, as trep does. Sets and returns the configuration.

        A feasible path: the start is brought onto the constraints, then each step is Newton
        in the constraints' null space on the exact Hessian of ``V + μᵀh`` (``μ`` the
        multipliers at the current point; eigenvalues taken in magnitude, so a saddle is left;
        a direction ``V`` neither curves nor slopes along — a config it does not read — is not
        moved), brought back onto the constraints by minimum-norm corrections, and halved
        until ``V`` falls. Stops when the
        gradient along the constraints or the step is at rounding; raises ``RuntimeError``
        (trep's ``StandardError``) when it cannot (a potential unbounded below, say).
        """
        free = ~self._held(keep_kinematic, constant_q_list)
        model = self._native_model()
        perm, rest = self._perm, np.zeros(self.nQ)

        def onto(q: np.ndarray) -> Optional[np.ndarray]:
            """``q`` moved onto the constraints by minimum-norm corrections, or None."""
            q = q.copy()
            for _ in range(50):
                c = self._native_call(lambda: model.constraints_at(self._to_model(q),
                                                                   second=False))
                h = np.asarray(c["h"], dtype=float)
                if not h.size or float(np.max(np.abs(h))) < tolerance:
                    return q
                jac = np.asarray(c["dh_dq"], dtype=float)[:, perm][:, free]
                q[free] -= np.linalg.pinv(jac) @ h
                if not np.all(np.isfinite(q)):
                    return None
            return None

        def at(q: np.ndarray) -> Dict[str, Any]:
            return self._native_call(lambda: model.evaluate(self._to_model(q), rest),
                                     RuntimeError, "minimize_potential_energy: ")

        q = onto(self._q)
        if q is None:
            raise RuntimeError("minimize_potential_energy: the constraints cannot be satisfied "
                               "from this configuration")
        e = at(q)
        for k in range(200):
            g = -np.asarray(e["dL_dq"])[perm][free]
            hess = -np.asarray(e["d2L_dqdq"])[np.ix_(perm, perm)][np.ix_(free, free)]
            if self.nc:
                c = self._native_call(lambda: model.constraints_at(self._to_model(q)))
                jac = np.asarray(c["dh_dq"], dtype=float)[:, perm][:, free]
                _, sv, vt = np.linalg.svd(jac)
                rank = int(np.sum(sv > 1e-12 * max(float(sv[0]) if sv.size else 0.0, 1e-300)))
                z = vt[rank:].T
                # The Lagrangian's Hessian: V's plus the multipliers' share of the constraints'
                # curvature, μ from g + Jᵀμ = 0.
                mu = np.linalg.lstsq(jac.T, -g, rcond=None)[0]
                d2h = np.asarray(c["d2h_dqdq"], dtype=float)[:, perm][:, :, perm]
                hess = hess + np.einsum("s,sij->ij", mu, d2h)[np.ix_(free, free)]
            else:
                z = np.eye(int(free.sum()))
            reduced = z.T @ g
            w, v = np.linalg.eigh(z.T @ hess @ z)
            along = v.T @ reduced
            floor = 1e-12 * max(float(np.max(np.abs(w))) if w.size else 0.0, 1e-300)
            flat = np.abs(w) <= floor
            slope = 1e-9 * (1.0 + float(np.max(np.abs(g))) if g.size else 1.0)
            if np.any(flat & (np.abs(along) > slope)):
                raise RuntimeError(
                    "minimize_potential_energy: the potential falls without bound along the "
                    "constraints (it slopes where it has no curvature)")
            step = -z @ (v @ (np.where(flat, 0.0, 1.0 / np.maximum(np.abs(w), floor)) * along))
            gradient = float(np.max(np.abs(reduced))) if reduced.size else 0.0
            value = -float(e["L"])
            if verbose:
                print(f"minimize_potential_energy: iteration {k}, V = {value:.12g}, "
                      f"gradient along the constraints {gradient:.3e}")
            size = 1e-12 * (1.0 + float(np.max(np.abs(q))))
            if gradient <= 1e-12 * (1.0 + float(np.max(np.abs(g)))) or \
                    float(np.max(np.abs(step), initial=0.0)) <= size:
                break
            alpha, accepted = 1.0, None
            while alpha * float(np.max(np.abs(step))) > size:
                trial = q.copy()
                trial[free] += alpha * step
                trial = onto(trial)
                if trial is not None:
                    e_trial = at(trial)
                    if -float(e_trial["L"]) < value:
                        accepted = trial
                        break
                alpha *= 0.5
            if accepted is None:
                break  # V falls no further than rounding: a minimum on the constraints
            q, e = accepted, e_trial
        else:
            raise RuntimeError(
                "minimize_potential_energy: no equilibrium found in 200 iterations (is the "
                "potential bounded below on the constraints?)")
        self._q[:] = q
        self._state_changed()
        self.dq = 0.0
        return self.q


# The bases of potentials, forces and constraints (each kind lives in trep's module of its
# name: potentials.py, forces.py, constraints.py, and writes its own model text) ----------
class _Part:
    """Something a system holds in one of its lists (``_list`` names it); adding one is a
    structure change."""

    _list = ""

    def __init__(self, system: System, name: Optional[str] = None):
        self._system = system
        self.name = name
        getattr(system, self._list).append(self)
        system._structure_changed()

    @property
    def system(self) -> System:
        return self._system

    # What the part adds to the model file (each kind overrides what it has):
    def _toml(self) -> List[str]:
        """Its own tables of the model file."""
        return []

    def _gravity(self) -> Sequence[float]:
        """Its share of the uniform gravity."""
        return (0.0, 0.0, 0.0)

    def _damping_on(self, config: Config) -> float:
        """Its viscous damping coefficient on the dynamic ``config``."""
        return 0.0

    def _frames(self) -> tuple:
        """The frames it is attached to."""
        return ()


def _undefined(name: str, kind: str, what: str):
    """A derivative a script's element does not write: trep's error when it is needed."""
    def method(self, *args):
        raise NotImplementedError(f"{name}() is undefined for this {kind} "
                                  f"({type(self).__name__})")
    method.__name__ = name
    method.__doc__ = (f"{what} at the current state: a script's own {kind} writes it "
                      f"(NotImplementedError otherwise, as trep's).")
    return method


class Potential(_Part):
    """A potential energy term of the system. A script's own subclass writes ``V`` and the
    derivatives its use needs (``V_dq``, ``V_dqdq`` for steps, ``V_dqdqdq`` for second
    derivatives); the runtime calls them back."""

    _list = "_potentials"

    V = _undefined("V", "potential", "The potential energy")
    V_dq = _undefined("V_dq", "potential", "∂V/∂q1")
    V_dqdq = _undefined("V_dqdq", "potential", "∂²V/∂q1∂q2")
    V_dqdqdq = _undefined("V_dqdqdq", "potential", "∂³V/∂q1∂q2∂q3")


class _BetweenFrames:
    """An element attached to two frames' origins (``frame1``, ``frame2``)."""

    frame1: Frame
    frame2: Frame

    def _frames(self) -> tuple:
        return (self.frame1, self.frame2)

    def _frames_line(self, system: System) -> str:
        """The model file's ``frames = [...]`` of the two."""
        return (f"frames = [{_toml_string(system._frame_key(self.frame1))}, "
                f"{_toml_string(system._frame_key(self.frame2))}]")


class Force(_Part):
    """A generalized force of the system. A script's own subclass writes ``f(q)`` (the force
    on config ``q``) and the derivatives its use needs (``f_dq``, ``f_ddq``; for second
    derivatives ``f_dqdq``, ``f_ddqdq``, ``f_ddqddq``); the runtime calls them back."""

    _list = "_forces"

    f = _undefined("f", "force", "The force on config q")
    f_dq = _undefined("f_dq", "force", "∂f_q/∂q1")
    f_ddq = _undefined("f_ddq", "force", "∂f_q/∂q̇1")
    f_dqdq = _undefined("f_dqdq", "force", "∂²f_q/∂q1∂q2")
    f_ddqdq = _undefined("f_ddqdq", "force", "∂²f_q/∂q̇1∂q2")
    f_ddqddq = _undefined("f_ddqddq", "force", "∂²f_q/∂q̇1∂q̇2")
    f_du = _undefined("f_du", "force", "∂f_q/∂u1")
    f_dudq = _undefined("f_dudq", "force", "∂²f_q/∂u1∂q2")
    f_duddq = _undefined("f_duddq", "force", "∂²f_q/∂u1∂q̇2")
    f_dudu = _undefined("f_dudu", "force", "∂²f_q/∂u1∂u2")

    def _create_input(self, name: Optional[str] = None) -> "Input":
        """A new input the force reads (trep's): ``Input.u`` its value; the force's ``f``
        depends on it, ``f_du`` (and for second derivatives ``f_dudq``, ``f_duddq``,
        ``f_dudu``) give the derivatives the runtime needs."""
        created = Input(self._system, name)
        created._force, created._in_model = self, False
        self._system._structure_changed()
        return created


class Constraint:
    """A holonomic constraint ``h(q) = 0`` with ``index`` its row."""

    #: trep's row over tree-mech's (see ``System._signs``).
    _sign = 1.0

    def __init__(self, system: System, name: Optional[str] = None):
        self._system = system
        self.name = name if name is not None else f"constraint{len(system._constraints) + 1}"
        self.index = len(system._constraints)
        system._constraints.append(self)
        if defined_in_python(self):
            system._structure_changed()

    @property
    def system(self) -> System:
        """The system the constraint belongs to."""
        return self._system

    def _frames(self) -> tuple:
        """The frames it is attached to."""
        return ()

    def _toml(self) -> List[str]:
        """Its own table of the model file."""
        raise NotImplementedError(f"{type(self).__name__} has no model text")

    def h(self) -> float:
        """The constraint's value at the current state (trep's form)."""
        return self._sign * float(self._system._state()["h"][self.index])

    def h_dq(self, q1: Config) -> float:
        """``∂h/∂q1`` at the current state (trep's form)."""
        s = self._system
        return self._sign * float(np.asarray(s._state()["dh_dq"])[self.index][s._i(q1)])

    h_dqdq = _undefined("h_dqdq", "constraint", "∂²h/∂q1∂q2")
    h_dqdqdq = _undefined("h_dqdqdq", "constraint", "∂³h/∂q1∂q2∂q3")


class MidpointVI:
    """trep's midpoint variational integrator over tree-mech's: state ``(t1, q1, p1)`` →
    ``(t2, q2, p2)`` and ``lambda1`` by ``step(t2, u1, k2)``, trep's forcing (the force over
    a step on its left end) and trep's scaling of ``lambda1``; first derivatives
    (``q2_dq1`` …, ``lambda1_dq1`` …) and second ones of ``q2`` and ``p2`` on request.
    Newton runs to tree-mech's relative tolerance (1e-12), tighter than trep's default; a
    step that does not converge raises ``ConvergenceError``."""

    def __init__(self, system: System, tolerance: float = 1e-10,
                 num_threads: Optional[int] = None):
        self._system = system
        self.tolerance = tolerance
        model = system._native_model()
        # Any step, as trep's integrator takes it (a warning past a quarter turn: _turned).
        self._stepper = _native.VariationalStepper(model, forcing="left", max_turn=math.inf)
        #: The configs that turn a frame (trep's order), and whether a step past a quarter
        #: turn has been warned of.
        self._angles = np.array([c.index for c in system._configs if c.frame is not None
                                 and c.frame.transform_type in (RX, RY, RZ)], dtype=int)
        self._warned_turn = False
        nq, nd, nk, nc = system.nQ, system.nQd, system.nQk, system.nc
        self.t1 = self.t2 = 0.0
        self._q1, self._q2 = np.zeros(nq), np.zeros(nq)
        self._p1, self._p2 = np.zeros(nd), np.zeros(nd)
        self._u1 = np.zeros(system.nu)
        self._lambda1 = np.zeros(nc)
        self._lam = np.zeros(nc)
        self._derivs: Optional[Dict[str, np.ndarray]] = None
        self._order = 0
        self._k2: Optional[np.ndarray] = None
        self._blocks: Dict[Any, Any] = {}

    # State ----------------------------------------------------------------------------
    @property
    def system(self) -> System:
        """The system the integrator steps."""
        return self._system

    nq = property(lambda self: self._system.nQ, doc="The number of configs.")
    nd = property(lambda self: self._system.nQd, doc="The number of dynamic configs.")
    nk = property(lambda self: self._system.nQk, doc="The number of kinematic configs.")
    nu = property(lambda self: self._system.nu, doc="The number of inputs.")
    nc = property(lambda self: self._system.nc, doc="The number of constraints.")

    def _vec(self, value: Any, n: int, what: str) -> np.ndarray:
        if n == 0 and isinstance(value, tuple) and not value:
            return _NO_VALUES  # `step(t2)` on a system without inputs: every step
        v = np.asarray(value, dtype=float).reshape(-1)
        if len(v) != n:
            raise ValueError(f"{what} needs {n} entries, got {len(v)}")
        return v.copy()

    q1 = property(lambda self: self._q1.copy(),
                  lambda self, v: setattr(self, "_q1", self._vec(v, self.nq, "q1")),
                  doc="The configuration at ``t1`` (every config; settable).")
    q2 = property(lambda self: self._q2.copy(),
                  lambda self, v: setattr(self, "_q2", self._vec(v, self.nq, "q2")),
                  doc="The configuration at ``t2`` (every config; settable).")
    p1 = property(lambda self: self._p1.copy(),
                  lambda self, v: setattr(self, "_p1", self._vec(v, self.nd, "p1")),
                  doc="The dynamic configs' momenta at ``t1`` (settable).")
    p2 = property(lambda self: self._p2.copy(),
                  lambda self, v: setattr(self, "_p2", self._vec(v, self.nd, "p2")),
                  doc="The dynamic configs' momenta at ``t2`` (settable).")
    u1 = property(lambda self: self._u1.copy(),
                  lambda self, v: setattr(self, "_u1", self._vec(v, self.nu, "u1")),
                  doc="The inputs over the step from ``t1`` to ``t2`` (settable).")
    lambda1 = property(lambda self: self._lambda1.copy(),
                       lambda self, v: setattr(self, "_lambda1", self._vec(v, self.nc, "lambda1")),
                       doc="The constraint forces over the step, trep's ``λ₁`` (settable).")

    @property
    def v2(self) -> Optional[np.ndarray]:
        """The kinematic configs' discrete velocity ``(q2k − q1k)/(t2 − t1)``."""
        if self.t2 == self.t1:
            return None
        return ((self._q2 - self._q1) / (self.t2 - self.t1))[self.nd:]

    def initialize_from_state(self, t1: float, q1: Any, p1: Any, lambda1: Any = None) -> None:
        """Starts from a known time, configuration and (dynamic) momentum."""
        self.t1 = self.t2 = float(t1)
        self.q1 = self.q2 = q1
        self.p1 = self.p2 = p1
        self.lambda1 = np.zeros(self.nc) if lambda1 is None else lambda1
        self._lam = np.zeros(self.nc)
        self._derivs, self._k2 = None, None

    def initialize_from_configs(self, t0: float, q0: Any, t1: float, q1: Any,
                                lambda1: Any = None) -> None:
        """Starts from two consecutive configurations: ``p1 = D₂L_d(q0, q1)``."""
        s = self._system
        q0, q1 = self._vec(q0, self.nq, "q0"), self._vec(q1, self.nq, "q1")
        p = s._native_call(lambda: self._stepper.momentum(
            float(t0), s._to_model(q0), float(t1), s._to_model(q1)))
        self.t1, self.t2 = float(t0), float(t1)
        self._q1, self._q2 = q0, q1
        self._p1 = self._p2 = np.asarray(p)[s._dperm]
        self.lambda1 = np.zeros(self.nc) if lambda1 is None else lambda1
        self._lam = np.zeros(self.nc)
        self._derivs, self._k2 = None, None
        self._leave_system_at_midpoint()

    def _leave_system_at_midpoint(self) -> None:
        """Leaves the System where trep's integrator leaves it after a step (or
        ``initialize_from_configs``): at the step's midpoint — ``q = (q1 + q2)/2``, ``dq =
        (q2 − q1)/(t2 − t1)``, ``t = (t1 + t2)/2`` — with ``u`` the step's inputs, so a
        script that reads ``system.q`` or calls ``total_energy()`` in its loop sees the
        state trep shows it (``ddq`` untouched)."""
        dt = self.t2 - self.t1
        if dt == 0.0:
            return
        # Written in place (the shapes are the integrator's own): this runs every step.
        s = self._system
        np.add(self._q1, self._q2, out=s._q)
        s._q *= 0.5
        np.subtract(self._q2, self._q1, out=s._dq)
        s._dq /= dt
        s._u[:] = self._u1
        s.t = 0.5 * (self.t1 + self.t2)
        s._state_changed()

    def step(self, t2: float, u1: Any = (), k2: Any = (), max_iterations: int = 200,
             q2_hint: Any = None, lambda1_hint: Any = None) -> int:
        """Steps to ``t2`` with inputs ``u1`` over the step and the kinematic configs at
        ``k2`` at its end; returns Newton's iterations."""
        return self._step(t2, u1, k2, 0)

    def _step(self, t2: float, u1: Any, k2: Any, order: int) -> int:
        """:meth:`step`, with the step's derivatives up to ``order`` computed in the same
        solve (``trep.discopt`` asks for them at once)."""
        u1 = self._vec(u1, self.nu, "u1")
        k2 = self._vec(k2, self.nk, "k2")
        # A step that fails (a bad t2, Newton's failure) leaves the integrator where it was,
        # so the caller can retry from t1 with another t2.
        kept = (self._q1, self._p1, self.t1, self._u1, self.t2, self._k2, self._derivs,
                self._q2, self._p2, self._lam)
        self._q1, self._p1, self.t1 = self._q2.copy(), self._p2.copy(), self.t2
        self._u1, self.t2 = u1, float(t2)
        self._k2 = k2
        self._derivs = None
        try:
            self._solve(order)
        except BaseException:
            (self._q1, self._p1, self.t1, self._u1, self.t2, self._k2, self._derivs,
             self._q2, self._p2, self._lam) = kept
            raise
        return self._iterations

    def _solve(self, order: int) -> None:
        s = self._system
        same = s._model_order_is_trep  # nothing to move (the usual case): no copies
        if same:
            q1, p1, kin_model = self._q1, self._p1, self._k2
        else:
            kin_model = np.zeros(self.nk)
            kin_model[s._kperm] = self._k2
            p1 = np.zeros(self.nd)
            p1[s._dperm] = self._p1
            q1 = s._to_model(self._q1)
        # A force written in Python reads its inputs from the System while called back.
        kept_u = s._u.copy()
        s._u[:] = self._u1
        try:
            q2, p2, lam, iterations, derivs = s._native_call(
                lambda: self._stepper.step(self.t1, q1, p1, self.t2, s._model_u(self._u1),
                                           kin_model, self._lam, order),
                ConvergenceError, f"the step to t = {self.t2}: ")
        except BaseException:
            s._u[:] = kept_u
            raise
        if same:
            self._q2, self._p2 = np.asarray(q2), np.asarray(p2)
        else:
            self._q2, self._p2 = np.asarray(q2)[s._perm], np.asarray(p2)[s._dperm]
        self._lam = np.asarray(lam)
        self._iterations = iterations
        self._turned()
        # trep's λ₁ multiplies its rows (System._signs) with the opposite sign and Δt folded
        # in: λ₁ = −Δt·sign·λ (the native derivatives already carry the −Δt).
        self._lambda1 = (-(self.t2 - self.t1) * s._signs() * self._lam if len(self._lam)
                         else self._lam)
        if order:
            self._derivs = {k: np.asarray(v) for k, v in derivs.items()}
            self._order = order
            if s._through:
                self._derivs = self._through_forces(self._derivs, order == 2)
        self._leave_system_at_midpoint()

    def _turned(self) -> None:
        """Warns (once per integrator) of a step that turned a joint by more than a quarter
        turn: trep takes it and so does this layer, but such a step does not resolve the
        motion and may have found a spurious root (tree-mech's own integrators refuse it).
        The native step measures the turn; the joint is found only to name it."""
        if self._warned_turn or self._stepper.largest_turn <= 0.5 * math.pi:
            return
        self._warned_turn = True
        turn = np.abs(self._q2[self._angles] - self._q1[self._angles])
        k = int(np.argmax(turn))
        name = self._system._configs[self._angles[k]].name
        warnings.warn(f"the step to t = {self.t2} turned `{name}` by {turn[k]:.3g} rad, more "
                      "than a quarter turn: trep takes such a step, but it may not resolve "
                      "the motion (a smaller dt would); warned once", RuntimeWarning,
                      stacklevel=5)

    def _through_forces(self, derivs: Dict[str, np.ndarray], second: bool
                        ) -> Dict[str, np.ndarray]:
        """The step's derivatives with the inputs a Python force reads (``_force_inputs``),
        from that force's ``∂F/∂u`` and its derivatives at the step's quadrature point."""
        s = self._system
        dt = self.t2 - self.t1
        mid, vel = 0.5 * (self._q1 + self._q2), (self._q2 - self._q1) / dt
        kept_t, s.t = s.t, 0.5 * (self.t1 + self.t2)
        try:
            b, b_dq, b_dv, b_du = s._terms.input_map(mid.tolist(), vel.tolist(), self._u1,
                                                     second)
        finally:
            s.t = kept_t
        point = force_inputs.StepPoint(s._perm, s._dperm, s._kperm, dt)
        return force_inputs.complete(derivs, second, s._uin, s._hidden, point, b, b_dq, b_dv,
                                     b_du)

    def calc_f(self) -> np.ndarray:
        """The discrete Euler–Lagrange equations at the integrator's current values (``t1``,
        ``q1``, ``p1``, ``t2``, ``q2``, ``u1``, ``lambda1``), as trep computes them: the
        dynamic configs' rows ``p1 + D₁L_d + f⁻ − Dh(q1)ᵀλ₁``, then each constraint's
        ``h(q2)``. Zero for a step the integrator took; for a ``q2`` set by hand, what the
        inputs would have to supply (inverse dynamics)."""
        s = self._system
        dt = self.t2 - self.t1
        p1 = np.zeros(self.nd)
        p1[s._dperm] = self._p1
        # trep's λ₁ over ours: λ₁ = −Δt·sign·λ (see _solve).
        lam = -self._lambda1 / (dt * s._signs()) if self.nc else np.zeros(0)
        kept_u = s._u.copy()
        s._u[:] = self._u1  # what a force written in Python reads while called back
        try:
            r = np.asarray(s._native_call(lambda: self._stepper.residual(
                self.t1, s._to_model(self._q1), p1, self.t2, s._to_model(self._q2),
                s._model_u(self._u1), lam)))
        finally:
            s._u[:] = kept_u
            s._state_changed()
        return np.concatenate([r[: self.nd][s._dperm], s._signs() * r[self.nd:]])

    def calc_p2(self) -> None:
        """Sets ``p2`` to the momentum at the end of the step from ``(t1, q1)`` to
        ``(t2, q2)``, ``D₂L_d(q1, q2)`` (trep's forcing puts no force on this end)."""
        s = self._system
        p = s._native_call(lambda: self._stepper.momentum(
            self.t1, s._to_model(self._q1), self.t2, s._to_model(self._q2)))
        self._p2 = np.asarray(p)[s._dperm]

    # Derivatives ----------------------------------------------------------------------
    def _need(self, order: int) -> Dict[str, np.ndarray]:
        """The last step's derivatives up to `order` (the step solved again with them)."""
        if self._derivs is None or self._order < order:
            if self._k2 is None:
                raise ValueError("derivatives need a step (call step first)")
            self._solve(order)
        assert self._derivs is not None
        return self._derivs

    def _cols(self, by: str) -> np.ndarray:
        s = self._system
        # The u1 block: the model's inputs, or (ConfigForce inputs…, through…) when a
        # Python force reads some (_through_forces).
        u1 = s._ucols if s._through else s._uin
        return {"q1": s._perm, "p1": s._dperm, "u1": u1, "k2": s._kperm}[by]

    def _first(self, of: str, by: str) -> np.ndarray:
        s = self._system
        d = self._need(1)
        # The rows and columns in trep's order, worked out once per pair (trep.discopt
        # reads every block at every knot).
        where = self._blocks.get((of, by))
        if where is None:
            rows = {"q2": s._dperm, "p2": s._dperm, "lambda1": np.arange(self.nc)}[of]
            where = self._blocks[(of, by)] = np.ix_(rows, self._cols(by))
        m = d[f"{of}_d{by}"][where]
        return m * s._signs()[:, None] if of == "lambda1" else m

    def _second(self, of: str, a: str, b: str) -> np.ndarray:
        s = self._system
        d = self._need(2)
        key, swap = f"{of}_d{a}d{b}", False
        if key not in d:
            key, swap = f"{of}_d{b}d{a}", True
        rows = s._dperm if of != "lambda1" else np.arange(self.nc)
        stack = d[key][np.ix_(rows, self._cols(b if swap else a), self._cols(a if swap else b))]
        if swap:
            stack = stack.transpose(0, 2, 1)
        if of == "lambda1":
            stack = stack * s._signs()[:, None, None]
        # trep lays second derivatives out (input₁, input₂, output).
        return stack.transpose(1, 2, 0)

    def _pick(self, m: np.ndarray, kinds: str, args: Sequence[Any]) -> Any:
        if all(x is None for x in args):
            return m
        s = self._system
        return m[tuple(s._index(k, x) for k, x in zip(kinds, args))]

    def q2_dq1(self, q=None, q1=None):
        """∂q2/∂q1 (trep's first derivative of the last step; one entry, given both)."""
        return self._pick(self._first("q2", "q1"), "dq", (q, q1))

    def q2_dp1(self, q=None, p1=None):
        """∂q2/∂p1 (trep's first derivative of the last step; one entry, given both)."""
        return self._pick(self._first("q2", "p1"), "dd", (q, p1))

    def q2_du1(self, q=None, u1=None):
        """∂q2/∂u1 (trep's first derivative of the last step; one entry, given both)."""
        return self._pick(self._first("q2", "u1"), "du", (q, u1))

    def q2_dk2(self, q=None, k2=None):
        """∂q2/∂k2 (trep's first derivative of the last step; one entry, given both)."""
        return self._pick(self._first("q2", "k2"), "dk", (q, k2))

    def p2_dq1(self, p=None, q1=None):
        """∂p2/∂q1 (trep's first derivative of the last step; one entry, given both)."""
        return self._pick(self._first("p2", "q1"), "dq", (p, q1))

    def p2_dp1(self, p=None, p1=None):
        """∂p2/∂p1 (trep's first derivative of the last step; one entry, given both)."""
        return self._pick(self._first("p2", "p1"), "dd", (p, p1))

    def p2_du1(self, p=None, u1=None):
        """∂p2/∂u1 (trep's first derivative of the last step; one entry, given both)."""
        return self._pick(self._first("p2", "u1"), "du", (p, u1))

    def p2_dk2(self, p=None, k2=None):
        """∂p2/∂k2 (trep's first derivative of the last step; one entry, given both)."""
        return self._pick(self._first("p2", "k2"), "dk", (p, k2))

    def lambda1_dq1(self, constraint=None, q1=None):
        """∂λ₁/∂q1 (trep's first derivative of the last step, its rows and signs)."""
        return self._pick(self._first("lambda1", "q1"), "cq", (constraint, q1))

    def lambda1_dp1(self, constraint=None, p1=None):
        """∂λ₁/∂p1 (trep's first derivative of the last step, its rows and signs)."""
        return self._pick(self._first("lambda1", "p1"), "cd", (constraint, p1))

    def lambda1_du1(self, constraint=None, u1=None):
        """∂λ₁/∂u1 (trep's first derivative of the last step, its rows and signs)."""
        return self._pick(self._first("lambda1", "u1"), "cu", (constraint, u1))

    def lambda1_dk2(self, constraint=None, k2=None):
        """∂λ₁/∂k2 (trep's first derivative of the last step, its rows and signs)."""
        return self._pick(self._first("lambda1", "k2"), "ck", (constraint, k2))


def _second_derivative(of: str, a: str, b: str) -> Any:
    kinds = {"q1": "q", "p1": "d", "u1": "u", "k2": "k"}
    out_kind = "c" if of == "lambda1" else "d"

    def method(self: MidpointVI, x: Any = None, y: Any = None, z: Any = None) -> Any:
        # Arguments (output, input₁, input₂); trep's layout (input₁, input₂, output).
        return self._pick(self._second(of, a, b), kinds[a] + kinds[b] + out_kind, (y, z, x))

    method.__name__ = f"{of}_d{a}d{b}"
    method.__doc__ = f"The second derivative of {of} with respect to {a} and {b} (trep's)."
    return method


# trep's 30 second derivatives: each output by each unordered pair of (q1, p1, u1, k2).
for _of in ("q2", "p2", "lambda1"):
    _inputs = ("q1", "p1", "u1", "k2")
    for _k, _a in enumerate(_inputs):
        for _b in _inputs[_k:]:
            setattr(MidpointVI, f"{_of}_d{_a}d{_b}", _second_derivative(_of, _a, _b))
