import os
from typing import Any, Callable, Mapping, Optional, Union

from ._native import (
    Model as Model,
    ModelError as ModelError,
    Rollouts as Rollouts,
    SimulationError as SimulationError,
    Stepper as Stepper,
    Trajectory as Trajectory,
    load as load,
    loads as loads,
)

__all__ = [
    "Model",
    "ModelError",
    "Rollouts",
    "SimulationError",
    "Stepper",
    "Trajectory",
    "load",
    "loads",
    "optimize",
    "__version__",
]

__version__: str

def optimize(
    task: Union[str, os.PathLike, Mapping[str, Any]],
    solver: Optional[str] = None,
    max_iterations: Optional[int] = None,
    progress: Optional[Callable[[int, float], Any]] = None,
) -> dict: ...
