"""Contact against MuJoCo 4.0, side by side: the cases of benches/contact.rs built in MuJoCo
(elliptic cones, its default Newton solver, Euler, Δt = 1 ms) — the ball drop, the box sliding
from 1 m/s, the box on slopes of 0.3 and 0.6 rad, the Solo-12 dropped 5 cm with its joints held
by PD, 27 balls poured on the ground — each measured as that bench measures tree-mech's:
the case's number against its analytic answer, the deepest penetration, the largest rise of
the energy, and steps a second (MuJoCo's own C loop, `mujoco.rollout`, one thread). Then a
linearised contact step of the Solo-12 standing on its feet: `mjd_transitionFD` (forward and
centred differences) against tree-mech's exact `A`, `B` of the step.

    python3 -m venv mj && mj/bin/pip install mujoco==4.0.0 numpy
    mj/bin/python tools/reference/mujoco_contact.py            # MuJoCo's side alone
    mj/bin/pip install ./python  # optional: checks MuJoCo's Solo-12 is tree-mech's
    mj/bin/python tools/reference/mujoco_contact.py --cargo    # runs `cargo bench --bench
                                                               # contact -- --json` first:
                                                               # both sides in one table

The models are the same bodies: the ball and the 27 balls on three slide joints each, as
tests/models/ball.toml and benches/models/balls-27.toml (frictionless between balls: MuJoCo
takes the larger of two geoms' friction and condim, so the balls carry none and the floor its
μ); the box a free body with a box geom (MuJoCo's box–plane contacts are its corners, as
tests/models/box.toml's eight corner points); the Solo-12 from models/solo12.urdf (meshes
dropped, fixed joints kept) on a free joint, with a sphere of 1.6 cm on each foot frame as
tasks/solo12-stand.toml, and the PD of benches/contact.rs as position actuators (kp = 10,
kv = 0.3: the force from each step's start state, as tree-mech's 1 kHz PD inputs).
"""
from __future__ import annotations

import json
import math
import pathlib
import re
import subprocess
import sys
import time
from typing import Callable, Dict, List

import mujoco
import numpy as np
from mujoco import rollout

ROOT = pathlib.Path(__file__).resolve().parents[2]
DT = 1e-3
G = 9.81
CROUCH = [0.0, 0.8, -1.6, 0.0, 0.8, -1.6, 0.0, -0.8, 1.6, 0.0, -0.8, 1.6]
FEET = ["FL_FOOT", "FR_FOOT", "HL_FOOT", "HR_FOOT"]
FOOT_RADIUS = 0.016

OPTION = (f'<option timestep="{DT}" gravity="{{gravity}}" cone="elliptic" '
          'integrator="Euler"><flag energy="enable"/></option>')


def slide_ball(name: str, pos, radius: float, mass: float, inertia: float) -> str:
    """A sphere on three slide joints (x, y, z) whose zero is at `pos`."""
    x, y, z = pos
    return (f'<body name="{name}" pos="{x} {y} {z}">'
            f'<joint name="{name}x" type="slide" axis="1 0 0"/>'
            f'<joint name="{name}y" type="slide" axis="0 1 0"/>'
            f'<joint name="{name}z" type="slide" axis="0 0 1"/>'
            f'<inertial pos="0 0 0" mass="{mass}" diaginertia="{inertia} {inertia} {inertia}"/>'
            f'<geom type="sphere" size="{radius}" friction="0 0 0" condim="1"/></body>')


def floor(mu: float) -> str:
    return f'<geom name="floor" type="plane" size="0 0 1" friction="{mu} 0 0" condim="3"/>'


def mjcf(body: str, mu: float, gravity=(0.0, 0.0, -G), extra: str = "") -> mujoco.MjModel:
    g = " ".join(repr(x) for x in gravity)
    text = (f'<mujoco>{OPTION.format(gravity=g)}<worldbody>{floor(mu)}{body}</worldbody>'
            f'{extra}</mujoco>')
    return mujoco.MjModel.from_xml_string(text)


def ball_model() -> mujoco.MjModel:
    return mjcf(slide_ball("ball", (0, 0, 0), 0.1, 1.0, 0.004), 0.5)


def box_model(theta: float = 0.0) -> mujoco.MjModel:
    """The 1 kg cube of side 0.2 m (its inertia as tests/models/box.toml) on a free joint,
    resting on the floor, gravity tilted by `theta`."""
    i = 1.0 * 0.2 ** 2 / 6.0
    body = ('<body name="box" pos="0 0 0.1"><freejoint/>'
            f'<inertial pos="0 0 0" mass="1" diaginertia="{i} {i} {i}"/>'
            '<geom type="box" size="0.1 0.1 0.1" friction="0.5 0 0" condim="3"/></body>')
    gravity = (G * math.sin(theta), 0.0, -G * math.cos(theta))
    return mjcf(body, 0.5, gravity)


def balls_model() -> mujoco.MjModel:
    """benches/models/balls-27.toml's balls, read from that file."""
    text = (ROOT / "benches/models/balls-27.toml").read_text()
    q0 = {k: float(v) for k, v in re.findall(r"\[variables\.(\w+)\]\nq0 = (\S+)", text)}
    body = "".join(slide_ball(f"b{k}", (q0[f"x{k}"], q0[f"y{k}"], q0[f"z{k}"]), 0.05, 0.1, 1e-4)
                   for k in range(1, 28))
    return mjcf(body, 0.5)


def solo_model() -> mujoco.MjModel:
    """The Solo-12 of models/solo12.urdf on a free joint, its feet spheres, PD actuators."""
    urdf = (ROOT / "models/solo12.urdf").read_text()
    urdf = re.sub(r"<visual>.*?</visual>", "", urdf, flags=re.S)
    urdf = re.sub(r"<collision>.*?</collision>", "", urdf, flags=re.S)
    urdf = urdf.replace("</robot>", '<mujoco><compiler fusestatic="false" '
                        'discardvisual="true" angle="radian"/></mujoco></robot>', 1)
    spec = mujoco.MjSpec.from_string(urdf)
    base = spec.body("base_link")
    base.add_freejoint()
    for foot in FEET:
        spec.body(foot).add_geom(type=mujoco.mjtGeom.mjGEOM_SPHERE, size=[FOOT_RADIUS, 0, 0],
                                 friction=[0.8, 0, 0], condim=3)
    spec.worldbody.add_geom(type=mujoco.mjtGeom.mjGEOM_PLANE, size=[0, 0, 1],
                            friction=[0.8, 0, 0], condim=3)
    for joint in spec.joints:
        if joint.type == mujoco.mjtJoint.mjJNT_HINGE:
            joint.limited = mujoco.mjtLimited.mjLIMITED_FALSE
            act = spec.add_actuator(target=joint.name, trntype=mujoco.mjtTrn.mjTRN_JOINT)
            act.set_to_position(kp=10.0, kv=0.3)
            act.ctrllimited = mujoco.mjtLimited.mjLIMITED_FALSE
            act.forcelimited = mujoco.mjtLimited.mjLIMITED_FALSE
    spec.option.timestep = DT
    spec.option.cone = mujoco.mjtCone.mjCONE_ELLIPTIC
    spec.option.integrator = mujoco.mjtIntegrator.mjINT_EULER
    spec.option.enableflags |= mujoco.mjtEnableBit.mjENBL_ENERGY
    return spec.compile()


def solo_start(m: mujoco.MjModel, d: mujoco.MjData, lift: float = 0.05) -> None:
    """The crouch, its lowest foot sphere `lift` above the floor, at rest, PD at the crouch."""
    mujoco.mj_resetData(m, d)
    d.qpos[7:] = CROUCH
    d.ctrl[:] = CROUCH
    mujoco.mj_kinematics(m, d)
    lowest = min(d.body(f).xpos[2] for f in FEET) - FOOT_RADIUS
    d.qpos[2] = lift - lowest


def energy(d: mujoco.MjData) -> float:
    return float(d.energy[0] + d.energy[1])


def run(m: mujoco.MjModel, d: mujoco.MjData, steps: int,
        penetration: Callable[[mujoco.MjData], float]) -> Dict[str, object]:
    """Steps `steps` times from `d`'s state, recording the deepest penetration and the energy's
    largest rise; then times the same run in MuJoCo's C loop (best of three)."""
    state0 = np.zeros(mujoco.mj_stateSize(m, mujoco.mjtState.mjSTATE_FULLPHYSICS))
    mujoco.mj_getState(m, d, state0, mujoco.mjtState.mjSTATE_FULLPHYSICS)
    ctrl = np.tile(d.ctrl, (steps, 1))
    mujoco.mj_forward(m, d)
    e0, deepest, gain, qpos = energy(d), 0.0, 0.0, [d.qpos.copy()]
    for _ in range(steps):
        mujoco.mj_step(m, d)
        mujoco.mj_forward(m, d)  # the energy and contacts of the state stepped to
        deepest = max(deepest, penetration(d))
        gain = max(gain, energy(d) - e0)
        qpos.append(d.qpos.copy())
    best = math.inf
    with rollout.Rollout(nthread=1) as r:
        for _ in range(3):
            start = time.perf_counter()
            r.rollout(m, [mujoco.MjData(m)], state0[None, :], ctrl[None, :, :] if m.nu else None,
                      nstep=steps)
            best = min(best, time.perf_counter() - start)
    return {"qpos": np.array(qpos), "penetration": deepest, "energy_gain": gain,
            "steps_per_second": steps / best}


def contact_depth(d: mujoco.MjData) -> float:
    """The deepest of MuJoCo's contacts (its `dist`, negative inside)."""
    return max([0.0] + [-c.dist for c in d.contact[:d.ncon]])


def row(case: str, value: float, answer: float, r: Dict[str, object]) -> Dict[str, object]:
    return {"case": case, "path": "MuJoCo", "value": value, "answer": answer,
            "penetration": r["penetration"], "energy_gain": r["energy_gain"],
            "steps_per_second": r["steps_per_second"]}


def cases() -> List[Dict[str, object]]:
    rows = []
    m = ball_model()
    d = mujoco.MjData(m)
    d.qpos[2] = 1.1
    r = run(m, d, 1000, lambda d: max(0.0, 0.1 - d.qpos[2]))
    landed = int(np.argmax(r["qpos"][:, 2] - 0.1 <= 1e-9))
    rows.append(row("ball drop: landing time (s)", landed * DT, math.sqrt(2.0 / G), r))

    m = box_model()
    d = mujoco.MjData(m)
    d.qvel[0] = 1.0
    r = run(m, d, 400, contact_depth)
    rows.append(row("box slide: stopping distance (m)", r["qpos"][-1, 0], 1.0 / (2 * 0.5 * G), r))
    for theta, name in [(0.3, "slope 0.3 rad (sticks): distance (m)"),
                        (0.6, "slope 0.6 rad (slides): distance (m)")]:
        m = box_model(theta)
        d = mujoco.MjData(m)
        r = run(m, d, 500, contact_depth)
        a = max(0.0, G * (math.sin(theta) - 0.5 * math.cos(theta)))
        rows.append(row(name, r["qpos"][-1, 0], 0.5 * a * 0.25, r))

    m = solo_model()
    d = mujoco.MjData(m)
    solo_start(m, d)
    r = run(m, d, 1000, contact_depth)
    rows.append(row("Solo-12 drop, PD: base height at 1 s (m)", r["qpos"][-1, 2], math.nan, r))

    m = balls_model()
    d = mujoco.MjData(m)
    r = run(m, d, 1000, contact_depth)
    z = r["qpos"][-1].reshape(27, 3)[:, 2] + m.body_pos[1:, 2]
    rows.append(row("27 balls poured: lowest centre at 1 s (m)", float(z.min()), 0.05, r))
    return rows


def linearised_step() -> List[Dict[str, object]]:
    """`mjd_transitionFD` of the Solo-12 standing on its feet (the PD drop settled for 1 s),
    forward and centred, best of three rounds of 200 calls, in microseconds."""
    m = solo_model()
    d = mujoco.MjData(m)
    solo_start(m, d)
    for _ in range(1000):
        mujoco.mj_step(m, d)
    nx, nu = 2 * m.nv + m.na, m.nu
    a, b = np.zeros((nx, nx)), np.zeros((nx, nu))
    out = []
    for centred in (0, 1):
        best = math.inf
        for _ in range(3):
            start = time.perf_counter()
            for _ in range(200):
                mujoco.mjd_transitionFD(m, d, 1e-6, centred, a, b, None, None)
            best = min(best, (time.perf_counter() - start) / 200)
        out.append({"case": "Solo-12 linearised contact step (µs)",
                    "path": "MuJoCo FD " + ("centred" if centred else "forward"),
                    "microseconds": 1e6 * best, "contacts": int(d.ncon)})
    return out


def same_solo() -> float:
    """How far MuJoCo's Solo-12 is from tree-mech's: the joints' block of the mass matrix
    (independent of how the free base is parametrised) at three random poses about the
    crouch, the largest difference relative to the largest entry (needs `tree_mech`)."""
    import tree_mech as tm
    m, ours = solo_model(), tm.load(str(ROOT / "models/solo12.urdf"), floating_base=True)
    d, rng, worst = mujoco.MjData(m), np.random.default_rng(0), 0.0
    for _ in range(3):
        joints = np.array(CROUCH) + rng.uniform(-0.5, 0.5, 12)
        d.qpos[:] = 0.0
        d.qpos[3], d.qpos[7:] = 1.0, joints
        mujoco.mj_forward(m, d)
        theirs = np.zeros((m.nv, m.nv))
        mujoco.mj_fullM(m, d, theirs)
        q = np.concatenate([np.zeros(6), joints])
        mass = np.asarray(ours.evaluate(q, np.zeros(18))["M"])[6:, 6:]
        worst = max(worst, float(np.abs(theirs[6:, 6:] - mass).max() / np.abs(mass).max()))
    return worst


def ours() -> List[Dict[str, object]]:
    out = subprocess.run(["cargo", "bench", "--bench", "contact", "--", "--json"], cwd=ROOT,
                         check=True, capture_output=True, text=True).stdout
    rows = [json.loads(line) for line in out.splitlines() if line.startswith("{")]
    # JSON has no NaN: an answer the case does not have comes as null.
    return [{k: math.nan if v is None else v for k, v in r.items()} for r in rows]


def main() -> None:
    rows = (ours() if "--cargo" in sys.argv else []) + cases() + linearised_step()
    try:
        rows.append({"case": "Solo-12 joints' mass matrix, MuJoCo against tree-mech",
                     "relative": same_solo()})
    except ImportError:
        pass
    if "--json" in sys.argv:
        for r in rows:
            print(json.dumps(r))
        return
    print(f"{'case':<44} {'path':<22} {'value':>10} {'answer':>10} {'penetr. m':>10} "
          f"{'E gain J':>10} {'steps/s':>10}")
    for r in sorted((r for r in rows if "value" in r), key=lambda r: r["case"]):
        print(f"{r['case']:<44} {r['path']:<22} {r['value']:>10.6f} {r['answer']:>10.6f} "
              f"{r['penetration']:>10.2e} {r['energy_gain']:>10.2e} "
              f"{r['steps_per_second']:>10.0f}")
    for r in rows:
        if "microseconds" in r:
            print(f"{r['case']:<44} {r['path']:<22} {r['microseconds']:>10.1f} µs")
        if "relative" in r:
            print(f"{r['case']}: {r['relative']:.1e} relative")


if __name__ == "__main__":
    main()
