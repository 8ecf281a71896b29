"""Computed-torque control of the UR5 from Python: the arm follows a joint-space sine, its
torques from the model's inverse dynamics, τ = ID(q, q̇, q̈_ref + Kp e + Kd ė), held over each
10 ms step of RK4, stepped one step at a time by `Model.stepper` from a pushed state. The
error decays as the closed loop ë + Kd ė + Kp e = 0 says it should.

    pip install ./python
    python python/examples/computed_torque.py
"""
from __future__ import annotations

import pathlib

import numpy as np

import tree_mech as tm

ROOT = pathlib.Path(__file__).resolve().parents[2]
DT = 0.01
# Critically damped: ë + 2ω ė + ω² e = 0 with ω = 10 rad/s.
KP, KD = 100.0, 20.0


def reference(t: float, q0: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A sine of 0.3 rad at 0.5 Hz on every joint about `q0`: q, q̇, q̈."""
    w = np.pi
    return (q0 + 0.3 * np.sin(w * t), 0.3 * w * np.cos(w * t) * np.ones_like(q0),
            -0.3 * w * w * np.sin(w * t) * np.ones_like(q0))


def track(duration: float = 2.0, push: float = 0.2) -> tuple[np.ndarray, np.ndarray]:
    """Runs the loop; returns the times and the largest joint error at each."""
    arm = tm.load(str(ROOT / "models/ur5.urdf"))
    q0 = arm.q0.copy()
    # Started off the reference.
    loop = arm.stepper(DT, integrator="rk4", q0=q0 + push, dq0=np.zeros_like(q0))
    times, errors = [], []
    for _ in range(round(duration / DT)):
        q, dq = loop.q, loop.dq
        q_ref, dq_ref, ddq_ref = reference(loop.t, q0)
        e, de = q_ref - q, dq_ref - dq
        loop.step(arm.inverse_dynamics(q, dq, ddq_ref + KP * e + KD * de))
        times.append(loop.t)
        errors.append(float(np.max(np.abs(reference(loop.t, q0)[0] - loop.q))))
    return np.array(times), np.array(errors)


if __name__ == "__main__":
    times, errors = track()
    for t, e in zip(times[::20], errors[::20]):
        print(f"t = {t:4.2f} s   max |e| = {e:.2e} rad")
