#!/usr/bin/env python3
"""Copies example-robot-data 6.0.0's URDF files into tests/robots/example-robot-data/ and
writes tests/fixtures/pinocchio-collection.json: Pinocchio 4.1's numbers for every one it
loads, for tests/runtime/collection.rs (which reads them without Python).

    python3 -m venv v && v/bin/pip install example-robot-data==6.0.0 pin==4.1.0
    v/bin/python tools/reference/robot_collection.py

Each URDF is loaded with a fixed base and — when its root link is not `world` — with a
floating base (the composite joint PX PY PZ RZ RY RX, tree-mech's root_x … root_roll).
Mimic joints are loaded as followers (`mimic=True`); a file whose mimic joints name joints
it does not have, which Pinocchio then refuses, is loaded with `mimic=False` (independent
joints, Pinocchio's default), and the entry says so. At one seeded state: q, v, tau, and the
mass matrix (CRBA), the generalized gravity, the nonlinear effects, the forward dynamics (ABA,
or M⁻¹(τ − nle) where ABA refuses mimic joints), the kinetic energy ½vᵀMv, the potential
energy at q less that at q = 0 (Pinocchio leaves bodies welded to the ground out; both
sides' constants cancel), and every link's pose (4×4, row-major). Damping is left out, as
Pinocchio's dynamics leaves it out. The meshes are not copied (the files name them; nothing
here reads them).
"""
import json
import pathlib
import shutil

import numpy as np
import pinocchio as pin
import sysconfig

ROOT = pathlib.Path(__file__).resolve().parents[2]
OUT = ROOT / "tests" / "robots" / "example-robot-data"


SITE = pathlib.Path(sysconfig.get_paths()["purelib"])


def robots_dir():
    return SITE / "cmeel.prefix" / "share" / "example-robot-data" / "robots"


def build(path, floating, mimic):
    if floating:
        base = pin.JointModelComposite()
        for joint in (pin.JointModelPX(), pin.JointModelPY(), pin.JointModelPZ(),
                      pin.JointModelRZ(), pin.JointModelRY(), pin.JointModelRX()):
            base.addJoint(joint)
        return pin.buildModelFromUrdf(str(path), base, mimic=mimic)
    return pin.buildModelFromUrdf(str(path), mimic=mimic)


def variables(model, floating):
    names = []
    for j in range(1, model.njoints):
        if model.nqs[j] == 0:
            continue  # a mimic joint
        if model.nqs[j] == 6 and floating and j == 1:
            names += ["root_x", "root_y", "root_z", "root_yaw", "root_pitch", "root_roll"]
        else:
            assert model.nvs[j] == 1, f"{model.names[j]}: {model.nvs[j]} velocities"
            names.append(model.names[j])
    return names


def configuration(model, angles):
    """Pinocchio's q for one coordinate per velocity (tree-mech's): a continuous joint's
    (cos θ, sin θ)."""
    q = np.zeros(model.nq)
    for j in range(1, model.njoints):
        iq, iv, nq, nv = model.idx_qs[j], model.idx_vs[j], model.nqs[j], model.nvs[j]
        if nq == 2 and nv == 1:
            q[iq:iq + 2] = np.cos(angles[iv]), np.sin(angles[iv])
        else:
            q[iq:iq + nq] = angles[iv:iv + nv]
    return q


def entry(model, rel, floating, mimic, rng):
    data = model.createData()
    angles = rng.uniform(-1.0, 1.0, model.nv)
    q = configuration(model, angles)
    v = rng.uniform(-1.0, 1.0, model.nv)
    tau = rng.uniform(-2.0, 2.0, model.nv)
    M = pin.crba(model, data, q)
    M = np.triu(M) + np.triu(M, 1).T
    g = pin.computeGeneralizedGravity(model, data, q).copy()
    nle = pin.nonLinearEffects(model, data, q, v).copy()
    try:
        ddq = pin.aba(model, data, q, v, tau).copy()
    except RuntimeError:
        ddq = np.linalg.solve(M, tau - nle)
    # Pinocchio's ABA on a robot whose joints move no mass (Romeo's hands) is NaN: kept as
    # null, such a robot being refused by tree-mech.
    ddq = ddq.tolist() if np.all(np.isfinite(ddq)) else None
    links = [f for f in model.frames if f.type == pin.FrameType.BODY]
    pin.framesForwardKinematics(model, data, q)
    poses = {f.name: data.oMf[model.getFrameId(f.name, pin.FrameType.BODY)].homogeneous.flatten().tolist()
             for f in links}
    # The potential energy as the generalized gravity's work: g is −∂V/∂q... measured from
    # q = 0 by the Pinocchio function itself where it takes mimic joints.
    try:
        potential = pin.computePotentialEnergy(model, data, q) - pin.computePotentialEnergy(
            model, data, configuration(model, np.zeros(model.nv)))
    except RuntimeError:
        potential = None
    return {
        "file": rel, "floating_base": floating, "mimic": mimic,
        "variables": variables(model, floating),
        "q": angles.tolist(), "v": v.tolist(), "tau": tau.tolist(), "M": M.tolist(),
        "g": g.tolist(), "nle": nle.tolist(), "ddq": ddq,
        "kinetic": 0.5 * v @ M @ v, "potential": potential, "poses": poses,
    }


def main():
    src = robots_dir()
    if OUT.exists():
        shutil.rmtree(OUT)
    rng = np.random.default_rng(20261206)
    entries, refused = [], {}
    for path in sorted(src.rglob("*.urdf")):
        rel = path.relative_to(src).as_posix()
        target = OUT / rel
        target.parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(path, target)
        for licence in path.parents:
            if (licence / "LICENSE").exists() and licence != src and src in licence.parents:
                shutil.copyfile(licence / "LICENSE", OUT / licence.relative_to(src) / "LICENSE")
                break
        try:
            model, mimic = build(path, False, True), True
        except (RuntimeError, ValueError) as e:
            try:
                model, mimic = build(path, False, False), False
            except (RuntimeError, ValueError) as e2:
                refused[rel] = str(e2).splitlines()[0]
                continue
        entries.append(entry(model, rel, False, mimic, rng))
        if model.frames[1].name != "world":  # the root link; `world`: bolted to the ground
            entries.append(entry(build(path, True, mimic), rel, True, mimic, rng))
    for dist in SITE.glob("example_robot_data-*.dist-info/licenses/LICENSE"):
        shutil.copyfile(dist, OUT / "LICENSE")
    out = {"package": "example-robot-data 6.0.0", "pinocchio": pin.__version__,
           "refused_by_pinocchio": refused, "entries": entries}
    path = ROOT / "tests" / "fixtures" / "pinocchio-collection.json"
    path.write_text(json.dumps(out, separators=(",", ":")) + "\n")
    print(f"wrote {path.relative_to(ROOT)}: {len(entries)} entries; Pinocchio refuses {sorted(refused)}")


if __name__ == "__main__":
    main()
