#!/usr/bin/env python3
"""Writes tests/fixtures/pinocchio-<model>.json: Pinocchio's numbers for every shipped URDF
at seeded random states, for tests/pinocchio.rs (which reads them without Python).

    pip install pin==4.1.0
    python3 tools/reference/pinocchio_fixtures.py

For each state: q, v, tau, a (random), and from Pinocchio the mass matrix (CRBA), the
generalized gravity, the nonlinear effects C(q,v)v + g, ABA's acceleration for tau, RNEA's
torque for a, every link's pose (4×4, row-major), the kinetic and potential energy, and
computeABADerivatives' ∂q̈/∂q, ∂q̈/∂v and M⁻¹ (= ∂q̈/∂τ) at (q, v, tau); and, for the first two states, the
kinematics at (q, v, a): every link's Jacobian (6 × nv, linear rows first), spatial velocity and
spatial acceleration in each of LOCAL, LOCAL_WORLD_ALIGNED and WORLD, its classical
acceleration (LOCAL_WORLD_ALIGNED), and the centre of mass with its velocity, acceleration
and Jacobian.
Vectors are in Pinocchio's joint order; `variables` names it (joint names), so the Rust
side maps by name. The floating base is a composite joint PX PY PZ RZ RY RX, whose q and v
are tree-mech's root_x … root_roll. Pinocchio's ABA ignores joint damping; so do these
numbers.

computeABADerivatives is wrong for composite joints in Pinocchio 4.1.0 (on solo12 its ∂q̈/∂v
differs from central differences of its own ABA by 2.3, its ∂q̈/∂q by 570), so for the
floating base the derivatives are taken on the same base built as six 1-DoF joints with
massless links between them (`chain_base`), whose ABA equals the composite's to 1e-12 and
whose derivatives agree with central differences of ABA.
"""
import json
import pathlib

import numpy as np
import pinocchio as pin

ROOT = pathlib.Path(__file__).resolve().parents[2]
MODELS = [
    ("ur5", "models/ur5.urdf", False),
    ("panda", "models/panda.urdf", False),
    ("solo12", "models/solo12.urdf", True),
    ("ur10", "models/ur10.urdf", False),  # last: the others keep their seeded states
]
STATES = 5
# The states that also carry the kinematics (every link in three references: large).
KINEMATIC_STATES = 2


def build(path, floating):
    if floating:
        base = pin.JointModelComposite()
        for joint in (pin.JointModelPX(), pin.JointModelPY(), pin.JointModelPZ(),
                      pin.JointModelRZ(), pin.JointModelRY(), pin.JointModelRX()):
            base.addJoint(joint)
        return pin.buildModelFromUrdf(str(path), base)
    return pin.buildModelFromUrdf(str(path))


def chain_base(path):
    """The floating base PX PY PZ RZ RY RX as six 1-DoF joints (massless links between
    them), the robot appended at the last one: the same dynamics as `build(path, True)`."""
    base = pin.Model()
    parent = 0
    for name, joint in (("root_x", pin.JointModelPX()), ("root_y", pin.JointModelPY()),
                        ("root_z", pin.JointModelPZ()), ("root_yaw", pin.JointModelRZ()),
                        ("root_pitch", pin.JointModelRY()), ("root_roll", pin.JointModelRX())):
        parent = base.addJoint(parent, joint, pin.SE3.Identity(), name)
    frame = base.addFrame(pin.Frame("root_end", parent, 0, pin.SE3.Identity(),
                                    pin.FrameType.OP_FRAME))
    return pin.appendModel(base, pin.buildModelFromUrdf(str(path)), frame, pin.SE3.Identity())


def variables(model, floating):
    names = []
    for j in range(1, model.njoints):
        name = model.names[j]
        if model.nqs[j] == 6 and floating and j == 1:
            names += ["root_x", "root_y", "root_z", "root_yaw", "root_pitch", "root_roll"]
        else:
            assert model.nqs[j] == 1, f"{name}: {model.nqs[j]} coordinates"
            names.append(name)
    return names


REFERENCES = {
    "local": pin.ReferenceFrame.LOCAL,
    "local_world_aligned": pin.ReferenceFrame.LOCAL_WORLD_ALIGNED,
    "world": pin.ReferenceFrame.WORLD,
}


def frame_kinematics(model, data, links, q, v, a):
    """Every link's Jacobian, velocity and acceleration in the three references, its
    classical acceleration, and the centre of mass with its derivatives, at (q, v, a)."""
    pin.forwardKinematics(model, data, q, v, a)
    pin.computeJointJacobians(model, data, q)
    pin.updateFramePlacements(model, data)
    frames = {}
    for f in links:
        fid = model.getFrameId(f.name, pin.FrameType.BODY)
        entry = {}
        for label, ref in REFERENCES.items():
            entry[f"jacobian_{label}"] = pin.getFrameJacobian(model, data, fid, ref).tolist()
            entry[f"velocity_{label}"] = pin.getFrameVelocity(model, data, fid, ref).vector.tolist()
            entry[f"acceleration_{label}"] = pin.getFrameAcceleration(model, data, fid, ref).vector.tolist()
        entry["classical_acceleration"] = pin.getFrameClassicalAcceleration(
            model, data, fid, pin.ReferenceFrame.LOCAL_WORLD_ALIGNED).linear.tolist()
        frames[f.name] = entry
    com = pin.centerOfMass(model, data, q, v, a)
    jcom = pin.jacobianCenterOfMass(model, data, q)
    return {
        "frames": frames,
        "com": com.tolist(), "vcom": data.vcom[0].tolist(), "acom": data.acom[0].tolist(),
        "jcom": jcom.tolist(),
    }


def main():
    rng = np.random.default_rng(20261201)
    for label, rel, floating in MODELS:
        model = build(ROOT / rel, floating)
        data = model.createData()
        # The model computeABADerivatives is right on (see the module docs).
        smooth = chain_base(ROOT / rel) if floating else model
        smooth_data = smooth.createData()
        assert [smooth.names[j] for j in range(1, smooth.njoints)][6 if floating else 0:] == \
            [model.names[j] for j in range(2 if floating else 1, model.njoints)]
        links = [f for f in model.frames if f.type == pin.FrameType.BODY]
        out = {
            "model": label,
            "file": rel,
            "floating_base": floating,
            "pinocchio": pin.__version__,
            "variables": variables(model, floating),
            "states": [],
        }
        for state in range(STATES):
            q = rng.uniform(-1.5, 1.5, model.nq)
            v = rng.uniform(-2.0, 2.0, model.nv)
            tau = rng.uniform(-5.0, 5.0, model.nv)
            a = rng.uniform(-3.0, 3.0, model.nv)
            M = pin.crba(model, data, q)
            M = np.triu(M) + np.triu(M, 1).T
            g = pin.computeGeneralizedGravity(model, data, q).copy()
            nle = pin.nonLinearEffects(model, data, q, v).copy()
            ddq = pin.aba(model, data, q, v, tau).copy()
            rnea = pin.rnea(model, data, q, v, a).copy()
            kinetic = pin.computeKineticEnergy(model, data, q, v)
            potential = pin.computePotentialEnergy(model, data, q)
            pin.computeABADerivatives(smooth, smooth_data, q, v, tau)
            ddq_dq, ddq_dv = smooth_data.ddq_dq.copy(), smooth_data.ddq_dv.copy()
            minv = smooth_data.Minv.copy()
            assert np.abs(pin.aba(smooth, smooth_data, q, v, tau) - ddq).max() <= 1e-9 * max(1.0, np.abs(ddq).max())
            minv = np.triu(minv) + np.triu(minv, 1).T
            pin.framesForwardKinematics(model, data, q)
            poses = {f.name: data.oMf[model.getFrameId(f.name, pin.FrameType.BODY)].homogeneous.flatten().tolist()
                     for f in links}
            kinematics = frame_kinematics(model, data, links, q, v, a) if state < KINEMATIC_STATES else {}
            if floating and kinematics:
                # The composite joint's Jacobian columns against the chain of six joints'.
                chained = frame_kinematics(smooth, smooth.createData(), links, q, v, a)
                for name, entry in kinematics["frames"].items():
                    for key, value in entry.items():
                        assert np.abs(np.array(value) - np.array(chained["frames"][name][key])).max() <= 1e-10, (name, key)
            out["states"].append({
                "q": q.tolist(), "v": v.tolist(), "tau": tau.tolist(), "a": a.tolist(),
                "M": M.tolist(), "g": g.tolist(), "nle": nle.tolist(), "ddq": ddq.tolist(),
                "rnea": rnea.tolist(), "kinetic": kinetic, "potential": potential, "poses": poses,
                "ddq_dq": ddq_dq.tolist(), "ddq_dv": ddq_dv.tolist(), "minv": minv.tolist(),
                **kinematics,
            })
        path = ROOT / "tests" / "fixtures" / f"pinocchio-{label}.json"
        path.write_text(json.dumps(out, indent=1) + "\n")
        print(f"wrote {path.relative_to(ROOT)}: {model.nq} coordinates, {len(links)} links")


if __name__ == "__main__":
    main()
