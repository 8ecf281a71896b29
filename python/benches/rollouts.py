"""Rollout throughput (steps per second) of tree-mech's Python package against MuJoCo's
`mujoco.rollout`, side by side in one process, and the package's per-call overhead.

    pip install ./python mujoco==4.0.0
    python python/benches/rollouts.py

Models: the N-link pendulums of benches/models, N = 8, 19 and 40 (1 kg point masses on 1 m
links, every q0 0.5 rad; in MuJoCo the same chain of hinges with 1 kg bodies whose inertia is 10⁻⁹ kg m²,
no contacts, no damping) and the UR5 (models/ur5.urdf; MuJoCo reads the same URDF with its
meshes left out). Both at Δt = 0.01, a batch of 64 rollouts of 1000 steps, zero controls.
tree-mech runs its midpoint VI (one rollout at a time) and RK4 (four rollouts at a time in
SIMD lanes, each bitwise its single run); MuJoCo its default semi-implicit Euler and RK4.
Each figure is the best of 3 runs. Prints Markdown tables.
"""
from __future__ import annotations

import pathlib
import re
import time

import mujoco
import numpy as np
from mujoco import rollout

import tree_mech as tm

ROOT = pathlib.Path(__file__).resolve().parents[2]
BATCH, STEPS, DT = 64, 1000, 0.01
# The chains measured: the 8-link one of the target, and longer ones to show how each side
# grows with the chain (ours O(N) a stage for RK4; MuJoCo factors a dense chain's M).
PENDULUMS = (8, 19, 40)


def best(f, repeats=3):
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        f()
        times.append(time.perf_counter() - start)
    return min(times)


def pendulum_mjcf(n: int, integrator: str) -> str:
    bodies, close = "", ""
    for k in range(n):
        pos = "0 0 0" if k == 0 else "0 0 -1"
        bodies += (
            f'<body pos="{pos}"><joint type="hinge" axis="1 0 0"/>'
            f'<inertial pos="0 0 -1" mass="1" diaginertia="1e-9 1e-9 1e-9"/>'
        )
        close += "</body>"
    return (
        f'<mujoco><option timestep="{DT}" gravity="0 0 -9.81" integrator="{integrator}">'
        f'<flag contact="disable"/></option><worldbody>{bodies}{close}</worldbody></mujoco>'
    )


def ur5_model(integrator: str) -> mujoco.MjModel:
    text = (ROOT / "models/ur5.urdf").read_text()
    text = re.sub(r"<visual>.*?</visual>", "", text, flags=re.S)
    text = re.sub(r"<collision>.*?</collision>", "", text, flags=re.S)
    m = mujoco.MjModel.from_xml_string(text)
    m.opt.timestep = DT
    m.opt.integrator = getattr(mujoco.mjtIntegrator, f"mjINT_{integrator.upper()}")
    m.opt.disableflags |= mujoco.mjtDisableBit.mjDSBL_CONTACT
    return m


def mujoco_rate(model: mujoco.MjModel, q0: np.ndarray, threads: int) -> float:
    data = [mujoco.MjData(model) for _ in range(threads)]
    state = np.zeros((BATCH, mujoco.mj_stateSize(model, mujoco.mjtState.mjSTATE_FULLPHYSICS)))
    d = data[0]
    for b in range(BATCH):
        d.qpos[:] = q0[b]
        d.qvel[:] = 0.0
        mujoco.mj_getState(model, d, state[b], mujoco.mjtState.mjSTATE_FULLPHYSICS)
    control = np.zeros((BATCH, STEPS, model.nu))
    with rollout.Rollout(nthread=threads) as r:
        seconds = best(lambda: r.rollout(model, data, state, control))
    return BATCH * STEPS / seconds


def ours_rate(m: tm.Model, q0: np.ndarray, integrator: str, threads: int, every: int = 1) -> float:
    dq0 = np.zeros_like(q0)

    def run():
        out = m.rollouts(q0, dq0, duration=STEPS * DT, dt=DT, integrator=integrator, threads=threads, every=every)
        # A rollout that stopped early would flatter the rate.
        failed = [e for e in out.errors if e is not None]
        assert not failed, failed[0]

    return BATCH * STEPS / best(run)


def main():
    rng = np.random.default_rng(1)
    rows = []
    for name, ours, theirs in [
        *[
            (f"{n}-link pendulum", tm.load(str(ROOT / f"benches/models/pendulum-{n}.toml")),
             lambda i, n=n: mujoco.MjModel.from_xml_string(pendulum_mjcf(n, i)))
            for n in PENDULUMS
        ],
        # Its limits unenforced: RK4 cannot enforce them, and MuJoCo's model is the smooth one.
        ("UR5", tm.load(str(ROOT / "models/ur5.urdf")).with_contacts(limits=False), ur5_model),
    ]:
        n = len(ours.variables)
        q0 = ours.q0 + rng.uniform(-0.1, 0.1, (BATCH, n))
        assert theirs("Euler").nq == n
        for threads in (1, 2):
            rows.append((name, threads, ours_rate(ours, q0, "vi", threads),
                         ours_rate(ours, q0, "vi", threads, every=STEPS), ours_rate(ours, q0, "rk4", threads),
                         mujoco_rate(theirs("Euler"), q0, threads), mujoco_rate(theirs("RK4"), q0, threads)))
    print("Steps per second (millions); \"recorded\": every step's q, q̇, energy kept, as MuJoCo keeps every state.")
    print()
    print("| model | threads | tree-mech VI, recorded | tree-mech VI, end only | tree-mech RK4, recorded | MuJoCo Euler | MuJoCo RK4 | VI recorded / MuJoCo Euler (2 threads) | RK4 recorded / MuJoCo RK4 (2 threads) |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|---:|")
    for name, threads, vi, vi_end, rk4, euler, mrk4 in rows:
        mj2 = next(r[5] for r in rows if r[0] == name and r[1] == 2)
        mrk2 = next(r[6] for r in rows if r[0] == name and r[1] == 2)
        print(f"| {name} | {threads} | {vi / 1e6:.3f} | {vi_end / 1e6:.3f} | {rk4 / 1e6:.3f} | {euler / 1e6:.3f} | {mrk4 / 1e6:.3f} | {vi / mj2:.2f}× | {rk4 / mrk2:.2f}× |")
    # Per-call overhead of the package.
    m = tm.load(str(ROOT / "benches/models/pendulum-8.toml"))
    calls = 2000

    def each(call):
        # Each result dropped at once (a list of 2000 results would time the allocator and
        # the garbage collector too).
        def run():
            for _ in range(calls):
                call()
        return best(run) / calls

    evaluate = each(lambda: m.evaluate())
    step = each(lambda: m.simulate(DT, DT))
    stepper = m.stepper(DT)
    stepped = each(lambda: stepper.step())
    # A closed loop's iteration: read the state, step under a PD on it (the chain has no
    # inputs, so the law's output is computed and dropped: the reading is what is timed).
    gain = np.full(len(m.q0), 0.1)

    def loop():
        _ = gain * stepper.q + gain * stepper.dq
        stepper.step()

    looped = each(loop)
    q, dq = m.q0, np.zeros_like(m.q0)
    aba = each(lambda: m.forward_dynamics(q, dq))
    crba = each(lambda: m.mass_matrix(q))
    print()
    print("| 8-link pendulum, one Python call | µs |")
    print("|---|---:|")
    print(f"| `Model.evaluate()` (L, M, every derivative, q̈, poses) | {evaluate * 1e6:.1f} |")
    print(f"| `Model.simulate(dt, dt)` (one VI step, both samples) | {step * 1e6:.1f} |")
    print(f"| `Stepper.step()` (one VI step, its momentum kept) | {stepped * 1e6:.1f} |")
    print(f"| `Stepper.q`, `.dq` read, a PD on them, `.step()` | {looped * 1e6:.1f} |")
    print(f"| `Model.forward_dynamics(q, dq)` (q̈ alone) | {aba * 1e6:.1f} |")
    print(f"| `Model.mass_matrix(q)` (M alone) | {crba * 1e6:.1f} |")


if __name__ == "__main__":
    main()
