from os import PathLike
from typing import Any, Callable, Mapping, Optional, Sequence, Union, final

import numpy as np
import numpy.typing as npt
from numpy.typing import ArrayLike

# A number per variable: an array in the model's order, or a dict of some by name.
_PerVariable = Union[ArrayLike, Mapping[str, float]]

__all__ = [
    "Model",
    "Trajectory",
    "Rollouts",
    "Stepper",
    "VariationalStepper",
    "load",
    "loads",
    "optimize_text",
    "ModelError",
    "SimulationError",
]

class ModelError(ValueError):
    file: Optional[str]
    line: Optional[int]

class SimulationError(RuntimeError):
    step: Optional[int]

@final
class Trajectory:
    t: npt.NDArray[np.float64]
    q: npt.NDArray[np.float64]
    dq: npt.NDArray[np.float64]
    p: Optional[npt.NDArray[np.float64]]
    energy: npt.NDArray[np.float64]
    lam: npt.NDArray[np.float64]
    violation: npt.NDArray[np.float64]
    u: npt.NDArray[np.float64]
    impulse: npt.NDArray[np.float64]
    gap: npt.NDArray[np.float64]
    unilateral: list[str]
    variables: list[str]
    newton_iterations: int
    dissipated: float
    def __len__(self) -> int: ...

@final
class Rollouts:
    t: npt.NDArray[np.float64]
    q: npt.NDArray[np.float64]
    dq: npt.NDArray[np.float64]
    energy: npt.NDArray[np.float64]
    errors: list[Optional[str]]

@final
class Model:
    name: str
    variables: list[str]
    nq: int
    nv: int
    dynamic: list[str]
    kinematic: list[str]
    inputs: list[str]
    constraints: list[str]
    frames: list[str]
    q0: npt.NDArray[np.float64]
    dq0: npt.NDArray[np.float64]
    def evaluate(
        self,
        q: Optional[_PerVariable] = None,
        dq: Optional[_PerVariable] = None,
        t: float = 0.0,
        u: Optional[ArrayLike] = None,
        ddq: Optional[_PerVariable] = None,
    ) -> dict: ...
    def forward_dynamics(
        self,
        q: Optional[_PerVariable] = None,
        dq: Optional[_PerVariable] = None,
        t: float = 0.0,
        u: Optional[ArrayLike] = None,
        ddq: Optional[_PerVariable] = None,
    ) -> npt.NDArray[np.float64]: ...
    def inverse_dynamics(
        self,
        q: Optional[_PerVariable] = None,
        dq: Optional[_PerVariable] = None,
        ddq: Optional[_PerVariable] = None,
    ) -> npt.NDArray[np.float64]: ...
    def constraints_at(
        self, q: Optional[_PerVariable] = None, second: bool = True
    ) -> dict: ...
    def add_python_terms(self, terms: Any, constraints: Sequence[str] = ...) -> None: ...
    def mass_matrix(self, q: Optional[_PerVariable] = None) -> npt.NDArray[np.float64]: ...
    def frame_pose(self, frame: str, q: Optional[_PerVariable] = None) -> npt.NDArray[np.float64]: ...
    def frame_jacobian(
        self,
        frame: str,
        q: Optional[_PerVariable] = None,
        reference: str = "local_world_aligned",
    ) -> npt.NDArray[np.float64]: ...
    def frame_velocity(
        self,
        frame: str,
        q: Optional[_PerVariable] = None,
        dq: Optional[_PerVariable] = None,
        reference: str = "local_world_aligned",
    ) -> npt.NDArray[np.float64]: ...
    def frame_acceleration(
        self,
        frame: str,
        q: Optional[_PerVariable] = None,
        dq: Optional[_PerVariable] = None,
        ddq: Optional[_PerVariable] = None,
        reference: str = "local_world_aligned",
        classical: bool = False,
    ) -> npt.NDArray[np.float64]: ...
    def center_of_mass(
        self,
        q: Optional[_PerVariable] = None,
        dq: Optional[_PerVariable] = None,
        ddq: Optional[_PerVariable] = None,
    ) -> dict: ...
    def com_jacobian(self, q: Optional[_PerVariable] = None) -> npt.NDArray[np.float64]: ...
    def simulate(
        self,
        duration: float,
        dt: float,
        integrator: str = "vi",
        q0: Optional[_PerVariable] = None,
        dq0: Optional[_PerVariable] = None,
        u: Optional[ArrayLike] = None,
        every: int = 1,
        alpha: float = 0.5,
        forcing: str = "split",
        newton_tol: Optional[float] = None,
        rtol: float = 1e-8,
        atol: float = 1e-10,
        max_steps: int = 1_000_000,
        progress: Optional[Callable[[float, float], object]] = None,
        kappa: float = 0.0,
    ) -> Trajectory: ...
    def linearize(
        self,
        q: Optional[_PerVariable] = None,
        dq: Optional[_PerVariable] = None,
        u: Optional[ArrayLike] = None,
        t: float = 0.0,
        dt: Optional[float] = None,
        p: Optional[ArrayLike] = None,
        integrator: str = "vi",
        forcing: str = "split",
        alpha: float = 0.5,
        second_order: bool = False,
        ddq: Optional[_PerVariable] = None,
        kappa: float = 0.0,
    ) -> dict: ...
    def linearize_trajectory(
        self,
        trajectory: Trajectory,
        alpha: float = 0.5,
        forcing: str = "split",
        newton_tol: Optional[float] = None,
        threads: Optional[int] = None,
        progress: Optional[Callable[[int, int], object]] = None,
    ) -> dict: ...
    def rollouts(
        self,
        q0: ArrayLike,
        dq0: ArrayLike,
        duration: float,
        dt: float,
        integrator: str = "vi",
        u: Optional[ArrayLike] = None,
        threads: Optional[int] = None,
        every: int = 1,
        models: Optional[Sequence["Model"]] = None,
        progress: Optional[Callable[[int, int], object]] = None,
    ) -> Rollouts: ...
    def stepper(
        self,
        dt: float,
        integrator: str = "vi",
        q0: Optional[_PerVariable] = None,
        dq0: Optional[_PerVariable] = None,
        alpha: float = 0.5,
        forcing: str = "split",
        newton_tol: Optional[float] = None,
    ) -> Stepper: ...
    def with_parameters(
        self,
        masses: Optional[dict[str, float]] = None,
        constants: Optional[dict[str, float]] = None,
        gravity: Optional[Sequence[float]] = None,
    ) -> "Model": ...
    def with_contacts(
        self,
        ground: Optional[float] = None,
        friction: Optional[float] = None,
        normal: Optional[Sequence[float]] = None,
        contacts: Optional[Sequence[Union[str, dict[str, Any]]]] = None,
        limits: Optional[bool] = None,
    ) -> "Model": ...

@final
class Stepper:
    """A model stepped by fixed steps of dt under inputs given a step at a time."""
    t: float
    q: npt.NDArray[np.float64]
    dq: npt.NDArray[np.float64]
    p: Optional[npt.NDArray[np.float64]]
    energy: float
    dt: float
    steps: int
    def step(self, u: Optional[ArrayLike] = None) -> None: ...
    def reset(
        self, q0: Optional[_PerVariable] = None, dq0: Optional[_PerVariable] = None
    ) -> None: ...

@final
class VariationalStepper:
    """The midpoint VI one step at a time with everything given (tree_mech.trep's engine)."""
    largest_turn: float
    def __new__(
        cls,
        model: Model,
        forcing: str = "left",
        tolerance: Optional[float] = None,
        max_turn: Optional[float] = None,
    ) -> "VariationalStepper": ...
    def step(
        self,
        t1: float,
        q1: ArrayLike,
        p1: ArrayLike,
        t2: float,
        u1: ArrayLike,
        k2: ArrayLike,
        lam: ArrayLike,
        order: int = 0,
    ) -> tuple: ...
    def momentum(self, t1: float, q1: ArrayLike, t2: float, q2: ArrayLike) -> np.ndarray: ...
    def residual(
        self, t1: float, q1: ArrayLike, p1: ArrayLike, t2: float, q2: ArrayLike, u1: ArrayLike,
        lam: ArrayLike,
    ) -> np.ndarray: ...

def load(
    path: Union[str, PathLike],
    floating_base: bool = False,
    lock: Union[str, Sequence[str], Mapping[str, Optional[float]], None] = None,
    independent_mimics: bool = False,
    contacts: bool = False,
) -> Model: ...
def loads(
    text: str,
    format: str = "toml",
    floating_base: bool = False,
    lock: Union[str, Sequence[str], Mapping[str, Optional[float]], None] = None,
    independent_mimics: bool = False,
    contacts: bool = False,
) -> Model: ...
def optimize_text(
    text: str,
    base: Union[str, PathLike],
    source: Optional[str] = None,
    solver: Optional[str] = None,
    max_iterations: Optional[int] = None,
    progress: Optional[Callable[[int, float], Any]] = None,
) -> dict: ...
