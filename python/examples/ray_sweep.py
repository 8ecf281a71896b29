"""A parameter sweep over Ray: a pendulum's small-swing period against its rod length.

Each Ray task takes a chunk of lengths and runs them as one batch of rollouts
(`Model.rollouts(..., models=[...])`, every core of its worker), so the sweep scales from one
machine to a cluster without code of our own for distribution:

    python python/examples/ray_sweep.py            # ray.init() starts a local Ray
    RAY_ADDRESS=auto python python/examples/ray_sweep.py       # on a cluster's head node
    ray job submit --address http://HEAD:8265 --working-dir . -- python python/examples/ray_sweep.py

(the workers need `tree_mech` installed: `pip install ./python` on each node, or a Ray
runtime environment). The model travels as TOML text; each task reads it.
"""
from __future__ import annotations

import math
import os

import numpy as np
import ray

import tree_mech as tm

PENDULUM = """
name = "pendulum"
gravity = [0.0, 0.0, -9.81]
[[frame]]
name = "pivot"
rx = "theta"
[[frame]]
name = "bob"
parent = "pivot"
tz = -1.0
mass = 1.0
"""

AMPLITUDE = 0.05  # rad


@ray.remote
def periods(text: str, lengths: list[float], dt: float, duration: float) -> list[float]:
    """The periods of the pendulum of `text` with its rod at each length (one batch)."""
    base = tm.loads(text)
    models = [base.with_parameters(constants={"bob": -length}) for length in lengths]
    batch = len(lengths)
    runs = base.rollouts(
        q0=np.full((batch, 1), AMPLITUDE),
        dq0=np.zeros((batch, 1)),
        duration=duration,
        dt=dt,
        models=models,
    )
    out = []
    for b in range(batch):
        if runs.errors[b] is not None:
            raise RuntimeError(runs.errors[b])
        theta = runs.q[b, :, 0]
        # The first downward zero crossing, interpolated: a quarter period.
        k = int(np.argmax(theta <= 0.0))
        t0, t1 = runs.t[k - 1], runs.t[k]
        quarter = t0 + (t1 - t0) * theta[k - 1] / (theta[k - 1] - theta[k])
        out.append(4.0 * quarter)
    return out


def sweep(lengths, chunks: int = 4, dt: float = 0.001, duration: float = 6.0) -> np.ndarray:
    """The period at each length, the lengths split into `chunks` Ray tasks."""
    if not ray.is_initialized():
        # RAY_ADDRESS (if set) names a cluster; otherwise a local Ray on this machine.
        ray.init(address=os.environ.get("RAY_ADDRESS"), include_dashboard=False)
    parts = [list(map(float, c)) for c in np.array_split(np.asarray(lengths, float), chunks) if len(c)]
    return np.concatenate(ray.get([periods.remote(PENDULUM, p, dt, duration) for p in parts]))


def expected(length: float, g: float = 9.81) -> float:
    """The small-swing period 2π√(l/g), corrected to second order in the amplitude."""
    return 2 * math.pi * math.sqrt(length / g) * (1 + AMPLITUDE**2 / 16)


if __name__ == "__main__":
    lengths = np.linspace(0.5, 4.0, 16)
    found = sweep(lengths)
    print("  l [m]   period [s]   2π√(l/g)(1 + θ₀²/16) [s]")
    for length, period in zip(lengths, found):
        print(f"  {length:5.2f}   {period:9.5f}    {expected(length):9.5f}")
    ray.shutdown()
