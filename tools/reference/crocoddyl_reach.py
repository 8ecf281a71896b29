#!/usr/bin/env python3
"""Solves the reach tasks' problems with Crocoddyl 3.2.1 and writes their fixtures, for
tests/tasks.rs (same optimum) and docs/benchmarks.md (timing):
* tasks/ur5-reach.toml — the UR5 within its URDF's effort limits, box-FDDP →
  tests/fixtures/crocoddyl-reach.json;
* tasks/ur10-reach.toml — the UR10 without limits, plain FDDP (Crocoddyl at its best) →
  tests/fixtures/crocoddyl-reach-ur10.json.

    python3 -m venv croc && croc/bin/pip install pin==4.0.0 libpinocchio==4.0.0 crocoddyl==3.2.1
    croc/bin/python tools/reference/crocoddyl_reach.py          # writes the fixtures
    croc/bin/python tools/reference/crocoddyl_reach.py --print  # prints the figures only

(Crocoddyl 3.2.1's wheel crashes in frame residuals with pin 4.1.0, hence pin 4.0.0.)

The same problem as each task file: the arm from q0 (shoulder_lift −1.2, elbow 1.5,
wrist_1 −1.0) at rest, Δt = 0.01, 100 knots, running ½·0.01·|v|² + ½·10⁻³·|u − g(q)|²
(times Δt, Crocoddyl's integrated models scale running costs by Δt as tree-mech does),
terminal ½·10⁵·|p_ee_link − (p_start + (0.1, 0, 0.2))|² + ½·10·|v|², torques within the
URDF's effort limits (box-FDDP) or unbounded (FDDP). The dynamics differ by integrator:
Crocoddyl's symplectic Euler, tree-mech's midpoint VI; both converge to the same continuous optimum as Δt → 0, so
the optima agree to O(Δt). Timing: the best of 5 solves from the same initial guess (the
gravity compensation at q0, as tree-mech's), in this Python process (the solve itself is
C++).
"""
import json
import pathlib
import sys
import time

import crocoddyl
import numpy as np
import pinocchio as pin

ROOT = pathlib.Path(__file__).resolve().parents[2]
DT, KNOTS = 0.01, 100


def solve(robot, limited):
    """Solves one reach: `robot` names models/ROBOT.urdf; `limited`: box-FDDP within the
    effort limits, else FDDP unbounded. Returns the fixture's contents."""
    model = pin.buildModelFromUrdf(str(ROOT / f"models/{robot}.urdf"))
    data = model.createData()
    q0 = pin.neutral(model)
    for name, value in [("shoulder_lift_joint", -1.2), ("elbow_joint", 1.5), ("wrist_1_joint", -1.0)]:
        q0[model.joints[model.getJointId(name)].idx_q] = value
    x0 = np.concatenate([q0, np.zeros(model.nv)])
    frame = model.getFrameId("ee_link")
    pin.framesForwardKinematics(model, data, q0)
    target = data.oMf[frame].translation + np.array([0.1, 0.0, 0.2])

    state = crocoddyl.StateMultibody(model)
    actuation = crocoddyl.ActuationModelFull(state)
    nu = actuation.nu
    weighted = lambda w: crocoddyl.ActivationModelWeightedQuad(np.asarray(w, dtype=float))
    velocity = np.concatenate([np.zeros(model.nv), np.ones(model.nv)])

    running = crocoddyl.CostModelSum(state, nu)
    running.addCost(
        "velocity",
        crocoddyl.CostModelResidual(
            state, weighted(0.01 * velocity), crocoddyl.ResidualModelState(state, x0, nu)
        ),
        1.0,
    )
    running.addCost(
        "gravity",
        crocoddyl.CostModelResidual(
            state, weighted([1e-3] * nu), crocoddyl.ResidualModelControlGrav(state, nu)
        ),
        1.0,
    )
    terminal = crocoddyl.CostModelSum(state, nu)
    terminal.addCost(
        "reach",
        crocoddyl.CostModelResidual(
            state,
            weighted([1e5] * 3),
            crocoddyl.ResidualModelFrameTranslation(state, frame, target, nu),
        ),
        1.0,
    )
    terminal.addCost(
        "rest",
        crocoddyl.CostModelResidual(
            state, weighted(10.0 * velocity), crocoddyl.ResidualModelState(state, x0, nu)
        ),
        1.0,
    )
    effort = model.effortLimit
    dam = crocoddyl.DifferentialActionModelFreeFwdDynamics(state, actuation, running)
    dam_end = crocoddyl.DifferentialActionModelFreeFwdDynamics(state, actuation, terminal)
    step = crocoddyl.IntegratedActionModelEuler(dam, DT)
    if limited:
        step.u_lb, step.u_ub = -effort, effort
    end = crocoddyl.IntegratedActionModelEuler(dam_end, 0.0)
    problem = crocoddyl.ShootingProblem(x0, [step] * KNOTS, end)

    hold = pin.computeGeneralizedGravity(model, data, q0)
    best, solver = None, None
    for _ in range(5):
        solver = crocoddyl.SolverBoxFDDP(problem) if limited else crocoddyl.SolverFDDP(problem)
        solver.th_stop = 1e-9
        xs = [x0] * (KNOTS + 1)
        us = [hold.copy() for _ in range(KNOTS)]
        start = time.perf_counter()
        solver.solve(xs, us, 500, False)
        elapsed = time.perf_counter() - start
        best = elapsed if best is None else min(best, elapsed)
    q_end = np.asarray(solver.xs[-1][: model.nq])
    pin.framesForwardKinematics(model, data, q_end)
    name = "box-FDDP" if limited else "FDDP"
    return {
        "note": f"tools/reference/crocoddyl_reach.py: Crocoddyl 3.2.1 {name} on tasks/{robot}-reach.toml's problem (symplectic Euler)",
        "cost": solver.cost,
        "iterations": solver.iter,
        "solve_seconds": best,
        "q_final": q_end.tolist(),
        "ee_final": data.oMf[frame].translation.tolist(),
        "target": target.tolist(),
        "variables": [model.names[j] for j in range(1, model.njoints)],
    }


def main():
    """Writes the fixtures; with `--print`, prints each reach's iterations, cost and best
    solve time instead (benches/reach.rs runs it so between its own solves)."""
    quiet = "--print" in sys.argv[1:]
    for robot, limited, fixture in [
        ("ur5", True, "crocoddyl-reach.json"),
        ("ur10", False, "crocoddyl-reach-ur10.json"),
    ]:
        out = solve(robot, limited)
        if quiet:
            print(out["iterations"], out["cost"], out["solve_seconds"])
            continue
        path = ROOT / "tests/fixtures" / fixture
        path.write_text(json.dumps(out, indent=1) + "\n")
        print(
            f"wrote {path}: cost {out['cost']:.6e} in {out['iterations']} iterations, "
            f"best {out['solve_seconds'] * 1e3:.1f} ms"
        )


if __name__ == "__main__":
    main()
