"""Contact from Python: a model with a ground and a contact sphere simulates on the VI, its
impulses and gaps come back as arrays, smooth contact (κ) rests on its central path, and RK4
runs until a contact closes, then stops with the runtime's sentence; a plan through contact
reports its relaxations and its replays at hard contact."""
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


def test_rk4_runs_while_the_ball_falls_and_stops_where_it_lands():
    m = tm.load(BALL)
    # In flight nothing acts: RK4's fall is exact (z = 1.1 − g t²/2).
    traj = m.simulate(duration=0.3, dt=1e-3, integrator="rk4")
    assert traj.q[-1, 2] == pytest.approx(1.1 - 0.5 * 9.81 * 0.3**2, abs=1e-9)
    # Reaching the ground it cannot hold the contact, and says so rather than pass through.
    with pytest.raises(tm.SimulationError, match=r"`ball` closed .*only the variational integrator"):
        m.simulate(duration=1.0, dt=1e-3, integrator="rk4")


def test_smooth_contact_rests_on_its_central_path():
    m = tm.load(BALL)
    dt, kappa = 1e-3, 1e-6
    traj = m.simulate(duration=1.0, dt=dt, kappa=kappa)
    # Resting: γ = m g Δt a step, and the gap holds γ φ = κ above the ground.
    gamma = traj.impulse[-1, 0]
    assert gamma == pytest.approx(9.81 * dt, rel=1e-6)
    assert traj.gap[-1, 0] == pytest.approx(kappa / gamma, rel=1e-6)
    with pytest.raises((ValueError, tm.SimulationError), match="relaxation κ must be finite"):
        m.simulate(duration=0.1, dt=dt, kappa=-1.0)



def test_a_plan_through_contact_reports_its_relaxations_and_replays():
    res = tm.optimize(str(ROOT / "tasks/cartpole-rail.toml"))
    assert res["converged"]
    assert res["kappa"] == [1e-2, 1e-3, 1e-4, 1e-5, 1e-6]
    stages = [k for i, k in enumerate(res["kappa_history"])
              if i == 0 or k != res["kappa_history"][i - 1]]
    assert stages == res["kappa"] and res["continuation"] is None
    # Open loop at hard contact it keeps within 2.4e-3 of the plan; with its feedback closer.
    hard, policy = res["hard_replay"], res["policy_replay"]
    assert hard["failure"] is None and policy["failure"] is None
    assert policy["deviation"] < hard["deviation"] < 1e-2
    assert hard["penetration"] < 1e-9 and hard["q_end"].shape == (2,)
    np.testing.assert_allclose(policy["q_end"], res["q_final"], atol=1e-3)


def test_a_plan_without_contact_has_no_replays():
    res = tm.optimize(str(ROOT / "tasks/cartpole-swingup.toml"), max_iterations=2)
    assert res["kappa"] == [] and res["kappa_history"] == [0.0, 0.0]
    assert res["hard_replay"] is None and res["policy_replay"] is None
    assert res["continuation"] is None


def test_a_ground_and_contacts_are_added_from_python():
    # The ball's model without its ground and sphere: a point mass over nothing.
    text = pathlib.Path(BALL).read_text().split("[ground]")[0]
    free = tm.loads(text)
    assert free.simulate(duration=0.6, dt=1e-3).q[-1, 2] < 0.0
    for contact in ["ball:0.1", {"frame": "ball", "radius": 0.1, "name": "ball"}]:
        m = free.with_contacts(ground=0.0, friction=0.5, contacts=[contact])
        traj = m.simulate(duration=1.0, dt=1e-3)
        # Named after its frame (the dict names it so too).
        assert traj.unilateral[:3] == ["ball", "ball.t1", "ball.t2"]
        # As the model that writes them: lands at √(2h/g), rests at its radius.
        landed = np.argmax(traj.gap[:, 0] < 1e-9)
        assert traj.t[landed] == pytest.approx((2.0 / 9.81) ** 0.5, abs=2e-3)
        assert traj.q[-1, 2] == pytest.approx(0.1, abs=1e-9)
    # A lifted ground: the ball rests on it.
    m = free.with_contacts(ground=0.25, contacts=["ball:0.1"])
    assert m.simulate(duration=1.0, dt=1e-3).q[-1, 2] == pytest.approx(0.35, abs=1e-9)
    with pytest.raises(tm.ModelError, match="no_such_frame"):
        free.with_contacts(ground=0.0, contacts=["no_such_frame"])
    with pytest.raises(tm.ModelError, match="radius"):
        free.with_contacts(contacts=[{"frame": "ball", "radius": -1.0}])
    with pytest.raises(ValueError, match=r"contacts\[0\] has `size`"):
        free.with_contacts(contacts=[{"frame": "ball", "size": 1.0}])
    with pytest.raises(ValueError, match=r"contacts\[0\]: contact `ball:big`: the radius after `:` must be a number \(metres\), got `big`"):
        free.with_contacts(contacts=["ball:big"])
    with pytest.raises(tm.ModelError, match="friction"):
        free.with_contacts(ground=0.0, friction=-0.5)
    with pytest.raises(tm.ModelError, match="height"):
        free.with_contacts(ground=float("nan"))


def test_readme_s_solo12_with_contacts_lands_on_its_feet():
    # README's "From Python" contact line, as written there.
    m = tm.load(str(ROOT / "models/solo12.urdf"), floating_base=True).with_contacts(
        ground=0.0, friction=0.8,
        contacts=["FL_FOOT:0.016", "FR_FOOT:0.016", "HL_FOOT:0.016", "HR_FOOT:0.016"])
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    assert 'contacts=["FL_FOOT:0.016", "FR_FOOT:0.016", "HL_FOOT:0.016", "HR_FOOT:0.016"]' in readme
    q0 = np.zeros(18)
    q0[6:] = [0.0, 0.8, -1.6, 0.0, 0.8, -1.6, 0.0, -0.8, 1.6, 0.0, -0.8, 1.6]
    q0[2] = 0.3
    traj = m.simulate(duration=0.5, dt=1e-3, q0=q0)
    feet = [traj.unilateral.index(f) for f in ["FL_FOOT", "FR_FOOT", "HL_FOOT", "HR_FOOT"]]
    # Added spheres touch each other too (a pair row each), as written in a model.
    assert "FL_FOOT|FR_FOOT" in traj.unilateral
    # It falls limp onto its feet: no foot sphere into the ground, and some land.
    assert traj.gap[:, feet].min() > -1e-9
    assert (traj.gap[-1, feet] < 1e-9).any()
