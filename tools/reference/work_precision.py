"""Work–precision without contact: trajectory error against wall time as Δt shrinks, for
tree-mech's midpoint VI and RK4 (the Python package: the interpreted system) and MuJoCo 4.0's
Euler, implicitfast and RK4, on the 19-link pendulum (benches/models/pendulum-19.toml) and
the UR5 (models/ur5.urdf), 2 s from a pose away from rest. The error is the largest
`|q_i(t) − q_ref,i(t)|` over the run's samples every 20 ms; the reference is tree-mech's RK4 at
Δt = 10⁻⁵ s, checked against MuJoCo's RK4 at the same step (the two models agree to the
figure printed). Wall time: the whole run, best of three (tree-mech's `Model.simulate`
recording every step; MuJoCo's own C loop, `mujoco.rollout`, one thread). Writes
docs/work-precision.png and prints the table.

    python3 -m venv mj && mj/bin/pip install mujoco==4.0.0 numpy matplotlib ./python
    mj/bin/python tools/reference/work_precision.py

trep's Puppet, the issue's second model, is not here: its strings are distance constraints
from prescribed hands, and MuJoCo has no hard distance constraint to hold them (its equality
constraints are soft), so its error would measure that softness, not an integrator.
"""
from __future__ import annotations

import math
import pathlib
import re
import time
from typing import Callable, Dict, List, Tuple

import matplotlib
import mujoco
import numpy as np
from mujoco import rollout

import tree_mech as tm

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

ROOT = pathlib.Path(__file__).resolve().parents[2]
T = 2.0
SAMPLE = 0.02
REFERENCE_DT = 1e-5
STEPS = [0.02, 0.01, 0.005, 0.0025, 0.00125, 0.000625, 0.0003125]


def best(f: Callable[[], object], repeats: int = 3) -> Tuple[float, object]:
    out, times = None, []
    for _ in range(repeats):
        start = time.perf_counter()
        out = f()
        times.append(time.perf_counter() - start)
    return min(times), out


def pendulum_mujoco(n: int) -> mujoco.MjModel:
    bodies, close = "", ""
    for k in range(n):
        pos = "0 0 0" if k == 0 else "0 0 -1"
        bodies += (f'<body pos="{pos}"><joint type="hinge" axis="1 0 0"/>'
                   '<inertial pos="0 0 -1" mass="1" diaginertia="1e-12 1e-12 1e-12"/>')
        close += "</body>"
    return mujoco.MjModel.from_xml_string(
        '<mujoco><option gravity="0 0 -9.81"><flag contact="disable"/></option>'
        f'<worldbody>{bodies}{close}</worldbody></mujoco>')


def ur5_mujoco() -> mujoco.MjModel:
    text = (ROOT / "models/ur5.urdf").read_text()
    text = re.sub(r"<visual>.*?</visual>", "", text, flags=re.S)
    text = re.sub(r"<collision>.*?</collision>", "", text, flags=re.S)
    m = mujoco.MjModel.from_xml_string(text)
    m.opt.disableflags |= mujoco.mjtDisableBit.mjDSBL_CONTACT
    m.opt.disableflags |= mujoco.mjtDisableBit.mjDSBL_LIMIT
    return m


def ours(m: tm.Model, q0: np.ndarray, dt: float, integrator: str) -> Tuple[float, np.ndarray]:
    """tree-mech's run: its wall time and q at the samples."""
    every = int(round(SAMPLE / dt))
    seconds, traj = best(lambda: m.simulate(duration=T, dt=dt, integrator=integrator, q0=q0,
                                            dq0=np.zeros_like(q0)))
    return seconds, np.asarray(traj.q)[::every]


def theirs(model: mujoco.MjModel, q0: np.ndarray, dt: float,
           integrator: str) -> Tuple[float, np.ndarray]:
    """MuJoCo's run: its wall time and q at the samples."""
    model.opt.timestep = dt
    model.opt.integrator = getattr(mujoco.mjtIntegrator, f"mjINT_{integrator.upper()}")
    d = mujoco.MjData(model)
    d.qpos[:] = q0
    kind = mujoco.mjtState.mjSTATE_FULLPHYSICS
    state = np.zeros(mujoco.mj_stateSize(model, kind))
    mujoco.mj_getState(model, d, state, kind)
    steps = int(round(T / dt))
    with rollout.Rollout(nthread=1) as r:
        seconds, (states, _) = best(lambda: r.rollout(model, [mujoco.MjData(model)],
                                                     state[None, :], nstep=steps))
    every = int(round(SAMPLE / dt))
    # The states after each step; q is after the time entry.
    q = np.vstack([q0, states[0, :, 1:1 + model.nq]])
    return seconds, q[::every]


def error(q: np.ndarray, reference: np.ndarray) -> float:
    k = min(len(q), len(reference))
    return float(np.abs(q[:k] - reference[:k]).max())


def measure(name: str, m: tm.Model, model: mujoco.MjModel,
            q0: np.ndarray) -> Dict[str, List[Tuple[float, float, float]]]:
    _, reference = ours(m, q0, REFERENCE_DT, "rk4")
    _, check = theirs(model, q0, REFERENCE_DT, "rk4")
    print(f"{name}: reference (tree-mech RK4, Δt = 1e-5) against MuJoCo's RK4 at 1e-5: "
          f"{error(check, reference):.1e} rad")
    lines: Dict[str, List[Tuple[float, float, float]]] = {}
    runs = [("tree-mech VI", lambda dt: ours(m, q0, dt, "vi")),
            ("tree-mech RK4", lambda dt: ours(m, q0, dt, "rk4")),
            ("MuJoCo Euler", lambda dt: theirs(model, q0, dt, "euler")),
            ("MuJoCo implicitfast", lambda dt: theirs(model, q0, dt, "implicitfast")),
            ("MuJoCo RK4", lambda dt: theirs(model, q0, dt, "rk4"))]
    for label, run in runs:
        for dt in STEPS:
            try:
                seconds, q = run(dt)
            except Exception as e:  # a run that fails is a point not drawn, said so
                print(f"  {label} Δt = {dt}: {e}")
                continue
            e = error(q, reference) if np.all(np.isfinite(q)) else math.inf
            lines.setdefault(label, []).append((dt, seconds, e))
            print(f"  {label:<20} Δt = {dt:<10} {seconds * 1e3:9.2f} ms   error {e:.2e}")
    return lines


def main() -> None:
    pendulum = tm.load(str(ROOT / "benches/models/pendulum-19.toml"))
    q_pendulum = np.full(19, 0.1)
    # Its limits unenforced: RK4 cannot enforce them, and MuJoCo's model here is the smooth one.
    ur5 = tm.load(str(ROOT / "models/ur5.urdf")).with_contacts(limits=False)
    q_ur5 = np.array([0.3, -1.0, 1.2, -0.5, 0.8, 0.2])
    panels = [("19-link pendulum", measure("19-link pendulum", pendulum, pendulum_mujoco(19),
                                           q_pendulum)),
              ("UR5", measure("UR5", ur5, ur5_mujoco(), q_ur5))]
    fig, axes = plt.subplots(1, 2, figsize=(12, 5))
    for ax, (title, lines) in zip(axes, panels):
        for label, points in lines.items():
            pts = [(s, e) for _, s, e in points if math.isfinite(e)]
            style = "-o" if label.startswith("tree-mech") else "--s"
            ax.loglog([s for s, _ in pts], [max(e, 1e-16) for _, e in pts], style, label=label)
        ax.set_title(f"{title}: 2 s, error against wall time")
        ax.set_xlabel("wall time of the run (s)")
        ax.set_ylabel("largest |q − q_ref| (rad)")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend()
    fig.tight_layout()
    out = ROOT / "docs/work-precision.png"
    fig.savefig(out, dpi=100)
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
