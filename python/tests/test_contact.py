"""Contact from Python: a model with a ground and a contact sphere simulates on the VI, its
impulses and gaps come back as arrays, and RK4 refuses it with the runtime's sentence."""
import pathlib

import numpy as np
import pytest

import tree_mech as tm

ROOT = pathlib.Path(__file__).resolve().parents[2]
BALL = str(ROOT / "tests/models/ball.toml")


def test_a_ball_lands_and_its_impulses_and_gaps_are_arrays():
    m = tm.load(BALL)
    dt = 1e-3
    traj = m.simulate(duration=1.0, dt=dt)
    assert traj.unilateral == ["ball", "ball.t1", "ball.t2"]
    assert traj.impulse.shape == (len(traj), 3) and traj.gap.shape == (len(traj), 3)
    # Dropped 1 m, it lands at √(2h/g) and rests at its radius, pressing m g Δt a step.
    landed = np.argmax(traj.gap[:, 0] < 1e-9)
    assert traj.t[landed] == pytest.approx((2.0 / 9.81) ** 0.5, abs=2 * dt)
    assert traj.gap[:, 0].min() > -1e-9
    assert traj.q[-1, 2] == pytest.approx(0.1, abs=1e-9)
    assert traj.impulse[-1, 0] == pytest.approx(9.81 * dt, rel=1e-9)
    assert traj.dq[-1, 2] == pytest.approx(0.0, abs=1e-9)


def test_rk4_refuses_a_model_with_contact():
    m = tm.load(BALL)
    with pytest.raises(tm.SimulationError, match="only the variational integrator enforces"):
        m.simulate(duration=0.1, dt=1e-3, integrator="rk4")
