"""tree-mech from Python: mechanical systems described as trees of frames, simulated,
linearised and optimised in generalized coordinates by a Rust runtime.

>>> import tree_mech as tm
>>> m = tm.loads('''
... [[frame]]
... name = "shoulder"
... rx = "theta"
... [[frame]]
... name = "bob"
... parent = "shoulder"
... tz = -1.0
... mass = 1.0
... [variables.theta]
... q0 = 0.5
... ''')
>>> m.variables
['theta']
>>> traj = m.simulate(duration=1.0, dt=0.01)
>>> traj.q.shape
(101, 1)

Models read at run time (``load``, ``loads``) are interpreted; compiled models are the Rust
crate's ``tree_model!``. Errors are ``ModelError`` (a model or task file; ``file`` and
``line`` say where) and ``SimulationError`` (``step`` says when).
"""
from __future__ import annotations

import os
from typing import Any, Callable, Mapping, Union

from ._native import (
    Model,
    ModelError,
    Rollouts,
    SimulationError,
    Stepper,
    Trajectory,
    load,
    loads,
    optimize_text,
)

__version__ = "0.1.0"

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


def _toml_value(v: Any) -> str:
    if hasattr(v, "item") and getattr(v, "shape", None) == ():
        v = v.item()  # a numpy scalar (np.float32(1.5), np.int64(3), np.bool_) or 0-d array
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, (int, float)):
        return repr(float(v)) if isinstance(v, float) else str(v)
    if isinstance(v, str):
        return '"' + v.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(v, Mapping):
        return "{ " + ", ".join(f"{_toml_key(k)} = {_toml_value(x)}" for k, x in v.items()) + " }"
    if hasattr(v, "tolist"):
        v = v.tolist()
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    raise TypeError(f"a task value must be a number, string, list or table, not {type(v).__name__}")


def _toml_key(k: str) -> str:
    return k if k.replace("_", "").replace("-", "").isalnum() else _toml_value(k)


def _task_toml(task: Mapping[str, Any]) -> str:
    """A task given as a dict (the task file's keys) as TOML text."""
    lines = []
    tables = {}
    for key, value in task.items():
        if key in ("cost", "terminal"):
            continue
        if isinstance(value, Mapping) and key in ("start", "limits"):
            tables[key] = value
        else:
            lines.append(f"{_toml_key(key)} = {_toml_value(value)}")
    for key, table in tables.items():
        lines.append(f"[{key}]")
        lines += [f"{_toml_key(k)} = {_toml_value(v)}" for k, v in table.items()]
    for key in ("cost", "terminal"):
        terms = task.get(key, [])
        if isinstance(terms, (Mapping, str)) or not hasattr(terms, "__iter__"):
            raise TypeError(f"`{key}` must be a list of terms (dicts), got a "
                            f"{type(terms).__name__}: write [{{...}}] for one term")
        for term in terms:
            if not isinstance(term, Mapping):
                raise TypeError(f"each term of `{key}` must be a dict of the term's keys, "
                                f"got a {type(term).__name__}")
            lines.append(f"[[{key}]]")
            lines += [f"{_toml_key(k)} = {_toml_value(v)}" for k, v in term.items()]
    return "\n".join(lines) + "\n"


def optimize(
    task: Union[str, os.PathLike, Mapping[str, Any]],
    solver: str | None = None,
    max_iterations: int | None = None,
    progress: Callable[[int, float], Any] | None = None,
) -> dict:
    """Solves an optimal-control task (see the README's task-file format): ``task`` is the
    path of a task file, or a dict with the same keys (``model`` relative to the current
    directory). Returns a dict: ``converged``, ``iterations``, ``cost``, ``q_final``,
    ``dq_final``, ``frames`` (final positions of the frames the costs name),
    ``solve_seconds``, and the trajectory ``t``, ``q``, ``dq``, ``u``, ``lam``, the states
    ``x``, the gains ``K`` (knots, controls, states) and ``feedforward``; through contact
    also ``kappa`` (the task's relaxations), ``kappa_history`` (each iteration's),
    ``continuation`` (why a smaller relaxation could not be started, else None),
    ``hard_replay`` and ``policy_replay`` (the plan at hard contact open loop and with its
    feedback: ``deviation``, ``penetration``, ``failure``, ``q_end``; None without
    contact). After every
    iteration ``progress(iteration, cost)``, if given, is called and Ctrl-C honoured; an
    exception from either ends the solve and is raised."""
    if isinstance(task, Mapping):
        return optimize_text(_task_toml(task), os.getcwd(), None, solver, max_iterations,
                             progress)
    path = os.fspath(task)
    try:
        with open(path, encoding="utf-8") as f:
            text = f.read()
    except OSError as e:
        raise ModelError(f"cannot read task file `{path}`: {e.strerror}") from None
    base = os.path.dirname(os.path.abspath(path))
    return optimize_text(text, base, path, solver, max_iterations, progress)
