"""trep's trajectory files: ``save_trajectory`` and ``load_trajectory``, a MATLAB file
(``.mat`` appended to a name without it) holding ``time`` and each part of a trajectory
(``Q``, ``p``, ``v``, ``u``, ``rho``) with the names of its columns (``Q_index`` …), so a
file written by trep loads here and one written here loads in trep."""
from __future__ import annotations

from typing import Any, List, Optional, Tuple

import numpy as np

from . import _matfile

# Each part and the names its columns carry, from a system.
_PARTS = (
    ("Q", lambda s: [c.name for c in s.configs]),
    ("p", lambda s: [c.name for c in s.dyn_configs]),
    ("v", lambda s: [c.name for c in s.kin_configs]),
    ("u", lambda s: [i.name for i in s.inputs]),
    ("rho", lambda s: [c.name for c in s.kin_configs]),
)


def _mat_path(filename: str) -> str:
    return filename if str(filename).endswith(".mat") else f"{filename}.mat"


def save_trajectory(filename: str, system: Any, t: Any, Q: Any = None, p: Any = None,
                    v: Any = None, u: Any = None, rho: Any = None) -> None:
    """Saves a trajectory of ``system`` at times ``t``: ``Q`` (N × nQ), ``p`` (N × nQd),
    ``v`` (N × nQk), ``u`` ((N−1) × nu), ``rho`` ((N−1) × nQk); a part not given is left
    out (its names are kept)."""
    t = np.asarray(t, dtype=float).reshape(-1)
    values: dict = {"time": t.reshape(1, -1)}
    given = {"Q": Q, "p": p, "v": v, "u": u, "rho": rho}
    for part, names_of in _PARTS:
        names = names_of(system)
        values[f"{part}_index"] = names
        if given[part] is None:
            continue
        rows = len(t) - 1 if part in ("u", "rho") else len(t)
        a = np.asarray(given[part], dtype=float)
        if a.ndim == 1 and len(names) == 1:
            a = a.reshape(-1, 1)
        if a.shape != (rows, len(names)):
            raise ValueError(f"{part} has shape {a.shape}; {len(t)} times and this system need "
                             f"{(rows, len(names))}")
        values[part] = a
    _matfile.write(_mat_path(filename), values)


def load_trajectory(filename: str, system: Any = None) -> Tuple[Any, ...]:
    """``(t, Q, p, v, u, rho)`` from a trajectory file. With ``system``, each part's columns
    in the system's order (a column the file lacks is zero; a part it lacks is ``None``);
    without, each part as ``(names, array or None)``."""
    data = _matfile.read(_mat_path(filename))
    if "time" not in data:
        raise ValueError(f"{filename} holds no `time`: it is not a trajectory file")
    t = np.asarray(data["time"], dtype=float).reshape(-1)
    out: List[Any] = [t]
    for part, names_of in _PARTS:
        names = list(data.get(f"{part}_index", []))
        values: Optional[np.ndarray] = data.get(part)
        if values is not None:
            values = np.asarray(values, dtype=float).reshape(-1, len(names)) if names else None
        if system is None:
            out.append((names, values))
            continue
        if values is None:
            out.append(None)
            continue
        wanted = names_of(system)
        moved = np.zeros((values.shape[0], len(wanted)))
        where = {name: i for i, name in enumerate(names)}
        for j, name in enumerate(wanted):
            if name in where:
                moved[:, j] = values[:, where[name]]
        out.append(moved)
    return tuple(out)
