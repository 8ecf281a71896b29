#!/usr/bin/env python3
"""Writes tests/fixtures/pinocchio-mimic-<model>.json: Pinocchio's numbers for the shipped
URDF robots with mimic joints, for tests/pinocchio.rs.

    pip install pin==4.1.0
    python3 tools/reference/pinocchio_mimic.py

Pinocchio 4.1 loads a mimic joint (`buildModelFromUrdf(path, mimic=True)`) as a joint of no
coordinates of its own, driven by `multiplier·q + offset` of the joint it follows — as
tree-mech does. Its CRBA and RNEA take mimic joints, its ABA does not ("This algorithm does
not support Joint Mimic type"), so the forward dynamics here is `M⁻¹(τ − nle)` from CRBA
and RNEA. Pinocchio's mimic model leaves a follower's own damping out; so do these numbers
(the Rust side compares a model without damping).

For each seeded state: q, v, tau (random), and from Pinocchio the mass matrix, the
generalized gravity, the nonlinear effects C(q,v)v + g, the forward dynamics, the kinetic
energy ½vᵀMv (computeKineticEnergy refuses mimic joints too), and every link's pose (4×4, row-major). `variables` names the
coordinates in Pinocchio's order (joint names; mimic joints have none).
"""
import json
import pathlib

import numpy as np
import pinocchio as pin

ROOT = pathlib.Path(__file__).resolve().parents[2]
MODELS = [("panda-hand", "models/panda-hand.urdf"), ("baxter", "models/baxter.urdf")]
STATES = 4


def main():
    rng = np.random.default_rng(20261206)
    for label, rel in MODELS:
        model = pin.buildModelFromUrdf(str(ROOT / rel), mimic=True)
        data = model.createData()
        variables = [model.names[j] for j in range(1, model.njoints) if model.nqs[j] == 1]
        assert len(variables) == model.nq == model.nv
        links = [f for f in model.frames if f.type == pin.FrameType.BODY]
        out = {"model": label, "file": rel, "pinocchio": pin.__version__,
               "variables": variables, "states": []}
        for _ in range(STATES):
            q = rng.uniform(-1.0, 1.0, model.nq)
            v = rng.uniform(-2.0, 2.0, model.nv)
            tau = rng.uniform(-5.0, 5.0, model.nv)
            M = pin.crba(model, data, q)
            M = np.triu(M) + np.triu(M, 1).T
            g = pin.computeGeneralizedGravity(model, data, q).copy()
            nle = pin.nonLinearEffects(model, data, q, v).copy()
            ddq = np.linalg.solve(M, tau - nle)
            kinetic = 0.5 * v @ M @ v  # computeKineticEnergy refuses mimic joints
            pin.framesForwardKinematics(model, data, q)
            poses = {f.name: data.oMf[model.getFrameId(f.name, pin.FrameType.BODY)]
                     .homogeneous.flatten().tolist() for f in links}
            out["states"].append({
                "q": q.tolist(), "v": v.tolist(), "tau": tau.tolist(), "M": M.tolist(),
                "g": g.tolist(), "nle": nle.tolist(), "ddq": ddq.tolist(),
                "kinetic": kinetic, "poses": poses,
            })
        path = ROOT / "tests" / "fixtures" / f"pinocchio-mimic-{label}.json"
        path.write_text(json.dumps(out, indent=1) + "\n")
        print(f"wrote {path.relative_to(ROOT)}: {model.nq} coordinates, {len(links)} links")


if __name__ == "__main__":
    main()
