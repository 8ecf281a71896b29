"""trep 1.0.2's ``trep.discopt`` on Python 3: a midpoint VI as a discrete system
(``DSystem``), a tracking cost (``DCost``), the projection-operator trajectory optimiser
(``DOptimizer``) and the time-varying LQ solvers (``solve_tv_lqr``, ``solve_tv_lq``). Written
from trep's documented interface (no trep code), on tree-mech's exact VI derivatives.
"""
from . import dcost, dlqr, doptimizer, dsystem
from .dcost import DCost
from .dlqr import solve_tv_lq, solve_tv_lqr
from .doptimizer import (
    DOptimizer,
    DOptimizerDefaultMonitor,
    DOptimizerMonitor,
    DOptimizerVerboseMonitor,
)
from .dsystem import DSystem

__all__ = [
    "DCost", "DOptimizer", "DOptimizerDefaultMonitor", "DOptimizerMonitor",
    "DOptimizerVerboseMonitor", "DSystem", "dcost", "dlqr", "doptimizer", "dsystem",
    "solve_tv_lq", "solve_tv_lqr",
]
