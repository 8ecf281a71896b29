"""trep 1.0.2's core API on Python 3, computed by tree-mech: change ``import trep`` to
``from tree_mech import trep`` and a script building a system of frames, configs,
potentials, forces and constraints, evaluating its Lagrangian and dynamics, and stepping it
with ``MidpointVI`` runs unchanged. trep is GPL; this is an independent implementation of
its documented interface (no trep code). What is covered and what is not: the package
README, "trep on Python 3".
"""
from . import constraints, forces, potentials
from ._core import (
    CONST_SE3,
    RX,
    RY,
    RZ,
    TX,
    TY,
    TZ,
    WORLD,
    Config,
    Constraint,
    ConvergenceError,
    Force,
    Frame,
    Input,
    MidpointVI,
    Potential,
    System,
    const_se3,
    const_txyz,
    rx,
    ry,
    rz,
    tx,
    ty,
    tz,
)
from ._spline import Spline
from ._tape import TapeMeasure
from ._trajectory import load_trajectory, save_trajectory
from . import discopt  # noqa: E402 (needs the core above)
from . import puppets, system, visual  # noqa: E402 (need the core above)

#: The trep release whose API this matches.
__version__ = "v1.0.2"

__all__ = [
    "CONST_SE3", "RX", "RY", "RZ", "TX", "TY", "TZ", "WORLD", "Config", "Constraint",
    "ConvergenceError", "Force", "Frame", "Input", "MidpointVI", "Potential", "Spline", "System",
    "TapeMeasure",
    "constraints", "discopt", "forces", "potentials", "__version__", "tx", "ty", "tz", "rx", "ry", "rz",
    "const_se3", "const_txyz", "load_trajectory", "puppets", "save_trajectory", "system",
    "visual",
]
