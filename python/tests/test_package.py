"""The Python package over the Rust runtime: every call, numpy shapes and dtypes, errors,
the GIL released, rollouts against single runs and across thread counts, optimisation."""
import _thread
import math
import pathlib
import threading
import time

import numpy as np
import pytest

import tree_mech as tm

ROOT = pathlib.Path(__file__).resolve().parents[2]
PENDULUM = str(ROOT / "models/pendulum.toml")
CART = str(ROOT / "tests/models/cart.toml")


def test_a_model_names_its_parts():
    m = tm.load(str(ROOT / "models/marionette.toml"))
    assert len(m.variables) == 42 and len(m.dynamic) == 24 and len(m.kinematic) == 18
    assert len(m.constraints) == 6 and m.inputs == []
    assert m.q0.dtype == np.float64 and m.q0.shape == (42,)
    assert m.variables[2] == "torso_z" and m.q0[2] == 0.5
    cart = tm.load(CART)
    assert cart.inputs == ["push"] and cart.variables == ["x", "theta"]
    assert "bob" in tm.load(PENDULUM).frames
    assert tm.__version__ == "0.1.0"


def test_evaluate_gives_the_pendulums_terms():
    m = tm.load(PENDULUM)
    theta, omega = 0.4, 1.3
    e = m.evaluate(q=[theta], dq=[omega])
    # 1 kg on a 1 m rod: M = 1, q̈ = −g sin θ, E = ½ω² − g cos θ.
    g = 9.81
    assert e["M"].shape == (1, 1) and e["M"].dtype == np.float64
    assert e["M"][0, 0] == pytest.approx(1.0, rel=1e-14)
    assert e["qdd"][0] == pytest.approx(-g * math.sin(theta), rel=1e-12)
    assert e["energy"] == pytest.approx(0.5 * omega**2 - g * math.cos(theta), rel=1e-12)
    assert e["poses"]["bob"].shape == (4, 4)
    assert set(e) >= {"L", "dL_dq", "dL_ddq", "d2L_ddqdq", "d2L_dqdq", "lambda", "h", "dh_dq"}


def test_bad_input_is_an_exception_with_a_sentence():
    m = tm.load(PENDULUM)
    with pytest.raises(ValueError, match="q has 2 entries; the model has 1 variable"):
        m.evaluate(q=[0.1, 0.2])
    with pytest.raises(tm.SimulationError, match="not finite"):
        m.evaluate(q=[0.1], dq=[1e200])
    with pytest.raises(ValueError, match="integrator `euler`"):
        m.simulate(1.0, 0.01, integrator="euler")
    with pytest.raises(tm.ModelError) as err:
        tm.loads('[[frame]]\nname = "a"\nrx = "q"\nmass = -1.0\n')
    assert "mass -1" in str(err.value) and err.value.line == 4


def test_a_model_file_error_names_its_file_and_line(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text('[[frame]]\nname = "a"\nrx = "q"\n\nmass = -2.0\n')
    with pytest.raises(tm.ModelError) as err:
        tm.load(str(bad))
    assert err.value.line == 5 and err.value.file.endswith("bad.toml")
    assert str(err.value).startswith(f"{bad}:5:")


def test_simulate_returns_arrays_and_conserves_energy():
    m = tm.load(str(ROOT / "models/double-pendulum.toml"))
    traj = m.simulate(duration=2.0, dt=0.01)
    assert len(traj) == 201 and traj.q.shape == (201, 2) and traj.dq.shape == (201, 2)
    assert traj.t[-1] == pytest.approx(2.0)
    assert abs(traj.energy - traj.energy[0]).max() < 1e-3 * abs(traj.energy[0])
    sparse = m.simulate(duration=2.0, dt=0.01, every=10)
    assert sparse.q.shape == (21, 2)
    np.testing.assert_array_equal(sparse.q[-1], traj.q[-1])
    rk = m.simulate(duration=0.5, dt=0.001, integrator="rk4")
    vi = m.simulate(duration=0.5, dt=0.001)
    assert abs(rk.q[-1] - vi.q[-1]).max() < 1e-5


def test_inputs_push_the_cart():
    m = tm.load(CART)
    still = m.simulate(1.0, 0.01, q0=[0.0, 0.0])
    pushed = m.simulate(1.0, 0.01, q0=[0.0, 0.0], u=[2.0])
    assert pushed.u.shape == (101, 1) and pushed.u[0, 0] == 2.0
    assert pushed.q[-1, 0] > still.q[-1, 0] + 0.1
    # Per step: pushing only in the first half.
    per_step = np.zeros((100, 1))
    per_step[:50] = 2.0
    half = m.simulate(1.0, 0.01, q0=[0.0, 0.0], u=per_step)
    assert half.u[49, 0] == 2.0 and half.u[60, 0] == 0.0
    assert still.q[-1, 0] < half.q[-1, 0] < pushed.q[-1, 0]


def test_a_failed_run_names_its_step():
    m = tm.load(str(ROOT / "models/double-pendulum.toml"))
    with pytest.raises(tm.SimulationError) as err:
        m.simulate(10.0, 0.1, integrator="rk45", rtol=1e-14, atol=1e-16, max_steps=10)
    assert err.value.step is not None and err.value.step <= 10


def test_errors_name_keyword_arguments_not_command_line_options():
    m = tm.load(str(ROOT / "models/double-pendulum.toml"))
    with pytest.raises(tm.SimulationError, match="lower dt") as err:
        m.simulate(1.0, 0.1, dq0=[1000.0, 0.0])
    assert "--" not in str(err.value)
    out = m.rollouts(np.zeros((1, 2)), np.array([[1000.0, 0.0]]), duration=1.0, dt=0.1)
    assert "lower dt" in out.errors[0] and "--" not in out.errors[0]


def test_bad_batch_arguments_fail_the_call_with_a_sentence():
    m = tm.load(str(ROOT / "models/double-pendulum.toml"))
    zeros = np.zeros((2, 2))
    with pytest.raises(ValueError, match="every must be at least 1"):
        m.rollouts(zeros, zeros, 1.0, 0.01, every=0)
    with pytest.raises(ValueError, match="every must be at least 1"):
        m.simulate(1.0, 0.01, every=0)
    # Negative counts are a sentence naming the argument, not Python's OverflowError.
    with pytest.raises(ValueError, match="every must be at least 1, got -1"):
        m.simulate(1.0, 0.01, every=-1)
    with pytest.raises(ValueError, match="threads must be at least 1, got -2"):
        m.rollouts(zeros, zeros, 1.0, 0.01, threads=-2)
    with pytest.raises(ValueError, match="max_steps must be at least 1, got -5"):
        m.simulate(1.0, 0.01, integrator="rk45", max_steps=-5)
    # A mistyped thread count is refused, not started (a million threads would hang).
    with pytest.raises(tm.SimulationError, match="threads asked for"):
        m.rollouts(zeros, zeros, 0.1, 0.01, threads=10**6)
    with pytest.raises(tm.SimulationError, match=r"shorter than one step of 1e300 s"):
        m.simulate(1.0, 1e300)


def test_an_array_of_the_wrong_dimensions_is_refused_in_a_sentence():
    m = tm.load(str(ROOT / "models/double-pendulum.toml"))
    with pytest.raises(TypeError, match="expected a 2-D array of numbers, got a 3-D one"):
        m.rollouts(np.zeros((2, 2, 1)), np.zeros((2, 2)), 1.0, 0.01)
    with pytest.raises(TypeError, match="expected a 1-D array of numbers, got a 2-D one"):
        m.simulate(1.0, 0.01, q0=[[0.1, 0.2]])
    # Not numbers at all: numpy's own message stands.
    with pytest.raises(ValueError, match="could not convert"):
        m.evaluate(q=["a", 0.0])


@pytest.mark.parametrize("integrator", ["vi", "rk4"])
def test_rollouts_equal_single_runs_whatever_the_threads(integrator):
    # RK4 batches run four rollouts at a time in SIMD lanes (here a group of four; the two
    # left run alone): each still the single run's, bit for bit.
    m = tm.load(CART)
    rng = np.random.default_rng(7)
    q0 = np.column_stack([np.zeros(6), rng.uniform(-0.5, 0.5, 6)])
    dq0 = rng.normal(0, 0.2, (6, 2))
    u = rng.normal(0, 1, (6, 1))
    run = dict(duration=1.0, dt=0.01, integrator=integrator)
    one = m.rollouts(q0, dq0, u=u, threads=1, **run)
    two = m.rollouts(q0, dq0, u=u, threads=2, **run)
    assert one.q.shape == (6, 101, 2) and one.t.shape == (101,)
    assert one.errors == [None] * 6
    np.testing.assert_array_equal(one.q, two.q)
    np.testing.assert_array_equal(one.dq, two.dq)
    for b in range(6):
        single = m.simulate(q0=q0[b], dq0=dq0[b], u=u[b], **run)
        np.testing.assert_array_equal(single.q, one.q[b])
        np.testing.assert_array_equal(single.dq, one.dq[b])
    # Inputs per step and rollout: (batch, steps, inputs).
    steps = np.repeat(u[:, None, :], 100, axis=1)
    again = m.rollouts(q0, dq0, u=steps, **run)
    np.testing.assert_array_equal(again.q, one.q)


def test_a_failing_rollout_fails_alone():
    m = tm.load(CART)
    q0 = np.zeros((3, 2))
    q0[1, 1] = np.nan
    r = m.rollouts(q0, np.zeros((3, 2)), duration=0.2, dt=0.01)
    assert r.errors[0] is None and r.errors[2] is None
    assert "not finite" in r.errors[1]
    assert np.isnan(r.q[1]).all() and np.isfinite(r.q[0]).all()
    with pytest.raises(ValueError, match=r"must both be \(batch, 2\); got \(3, 3\)"):
        m.rollouts(np.zeros((3, 3)), np.zeros((3, 3)), 0.1, 0.01)
    with pytest.raises(ValueError, match=r"u must be \(3, 1\) or \(3, steps, 1\); got \(3, 2\)"):
        m.rollouts(np.zeros((3, 2)), np.zeros((3, 2)), 0.1, 0.01, u=np.zeros((3, 2)))
    pendulum = tm.load(str(ROOT / "models/pendulum.toml"))
    with pytest.raises(ValueError, match="the model has no inputs: leave u out"):
        pendulum.rollouts(np.zeros((2, 1)), np.zeros((2, 1)), 0.1, 0.01, u=np.ones((2, 1)))
    with pytest.raises(ValueError, match=r"u must be \(3, 1\) or .*; got no array of numbers"):
        m.rollouts(np.zeros((3, 2)), np.zeros((3, 2)), 0.1, 0.01, u="fast")


def test_a_model_read_from_text_names_the_line_of_its_error():
    with pytest.raises(tm.ModelError, match=r"^line 2: TOML error: invalid type") as e:
        tm.loads("[[frame]]\nname = 1\n")
    assert e.value.line == 2 and e.value.file is None
    with pytest.raises(tm.SimulationError, match="duration must be a positive finite number"):
        tm.load(CART).simulate(float("inf"), 0.01)


def test_long_calls_release_the_gil():
    m = tm.load(str(ROOT / "models/marionette.toml"))
    counter = [0]
    done = threading.Event()

    def count():
        while not done.is_set():
            counter[0] += 1

    worker = threading.Thread(target=count)
    worker.start()
    time.sleep(0.05)
    before = counter[0]
    start = time.perf_counter()
    m.simulate(duration=30.0, dt=0.01, every=100)
    elapsed = time.perf_counter() - start
    during = counter[0] - before
    done.set()
    worker.join()
    # Holding the GIL, the counting thread would not run at all during the call.
    assert elapsed > 0.1, f"the run must be long enough to see: {elapsed:.3f} s"
    assert during > 1000, f"the other thread counted {during} in {elapsed:.2f} s"


def test_optimize_swings_the_cartpole_up_from_a_file_or_a_dict():
    path = ROOT / "tasks/cartpole-swingup.toml"
    plan = tm.optimize(str(path))
    assert plan["converged"] and plan["stopped"] == "converged"
    assert abs(plan["q_final"][1]) < 0.02 and abs(plan["q_final"][0]) < 0.02
    assert plan["q"].shape == (126, 2) and plan["u"].shape == (125, 1)
    assert plan["K"].shape[0] == 125 and plan["K"].shape[1] == 1
    assert np.all(np.abs(plan["u"]) <= 20.0 + 1e-12)
    task = {
        "model": str(ROOT / "models/cartpole.toml"),
        "dt": 0.02,
        "knots": 125,
        "start": {"q": {"theta": math.pi}},
        "cost": [
            {"kind": "state", "q_weight": {"x": 0.5, "theta": 0.0}, "dq_weight": 0.01,
             "q_ref": {"x": 0.0, "theta": 0.0}, "dq_ref": 0.0},
            {"kind": "control", "weight": 0.01, "about": "zero"},
        ],
        "terminal": [
            {"kind": "state", "q_ref": {"x": 0.0, "theta": 0.0}, "dq_ref": 0.0,
             "q_weight": {"x": 100.0, "theta": 1000.0}, "dq_weight": 100.0},
        ],
    }
    same = tm.optimize(task)
    assert same["cost"] == pytest.approx(plan["cost"], rel=1e-12)
    with pytest.raises(tm.ModelError, match="frame `hat` is not in the model"):
        tm.optimize(dict(task, terminal=[{"kind": "frame", "frame": "hat", "target": [0, 0, 0], "weight": 1.0}]))


def test_linearize_gives_the_exact_step_derivatives():
    m = tm.load(CART)
    q, dq, u = np.array([0.1, 0.4]), np.array([0.2, -0.3]), np.array([0.7])
    lin = m.linearize(q=q, dq=dq, u=u, dt=0.01)
    e = m.evaluate(q=q, dq=dq, u=u)
    # ∂q̈/∂u is M⁻¹'s column of the pushed variable; q̈ itself is evaluate's.
    np.testing.assert_allclose(lin["qdd_du"][:, 0], np.linalg.inv(e["M"])[:, 0], rtol=1e-12)
    np.testing.assert_allclose(lin["qdd"], e["qdd"], rtol=1e-12)
    vi = lin["vi"]
    assert vi["q2_dq1"].shape == (2, 2) and vi["q2_du1"].shape == (2, 1)
    # The step is simulate's first step; its derivative by q₁ matches central differences.
    first = m.simulate(0.01, 0.01, q0=q, dq0=dq, u=u, newton_tol=1e-14)
    np.testing.assert_allclose(vi["q2"], first.q[1], rtol=1e-9)
    # p₁ held at its default, ∂L/∂q̇ at the unperturbed state, while q₁ moves.
    p1 = e["dL_ddq"]
    h = 1e-6
    for j in range(2):
        dq1 = np.zeros(2)
        dq1[j] = h
        plus = m.linearize(q=q + dq1, dq=dq, u=u, dt=0.01, p=p1)["vi"]["q2"]
        minus = m.linearize(q=q - dq1, dq=dq, u=u, dt=0.01, p=p1)["vi"]["q2"]
        np.testing.assert_allclose((plus - minus) / (2 * h), vi["q2_dq1"][:, j], rtol=1e-6, atol=1e-8)
    second = m.linearize(q=q, dq=dq, u=u, dt=0.01, second_order=True)["vi"]
    assert second["q2_dq1dq1"].shape == (2, 2, 2)
    with pytest.raises(tm.SimulationError, match="second-order derivatives are for the VI step"):
        m.linearize(second_order=True)


def test_a_trajectory_linearises_step_by_step():
    # A constrained run with a moving kinematic hand and an input that changes each step.
    m = tm.load(str(ROOT / "tests/models/trep-vi.toml"))
    u = np.sin(0.7 * np.arange(25))[:, None]
    run = m.simulate(0.25, 0.01, u=u)
    assert run.p.shape == run.q.shape and run.p.dtype == np.float64
    lin = m.linearize_trajectory(run, threads=1)
    steps, nd, n = len(run) - 1, len(m.dynamic), len(m.variables)
    assert lin["q2_dq1"].shape == (steps, nd, n)
    assert lin["lambda1_dk2"].shape == (steps, len(m.constraints), len(m.kinematic))
    assert lin["dynamic"] == m.dynamic
    # Step k is the one-step linearisation from its recorded (q_k, p_k) with its inputs.
    for k in (3, 17):
        dynamic = [m.variables.index(v) for v in m.dynamic]
        one = m.linearize(q=run.q[k], dq=run.dq[k], u=run.u[k], t=run.t[k], dt=0.01,
                          p=run.p[k][dynamic])["vi"]
        np.testing.assert_allclose(one["q2"], run.q[k + 1], rtol=1e-9, atol=1e-12)
        for key in ("q2_dq1", "p2_dp1", "q2_du1", "lambda1_dq1"):
            scale = max(np.abs(one[key]).max(), 1.0)
            np.testing.assert_allclose(lin[key][k], one[key], rtol=0, atol=1e-7 * scale)
    # The same numbers on any number of threads.
    for threads in (2, None):
        again = m.linearize_trajectory(run, threads=threads)
        blocks = [key for key in lin if key.startswith(("q2", "p2", "lambda1"))]
        assert all(np.array_equal(again[key], lin[key]) for key in blocks)
    with pytest.raises(tm.SimulationError, match="step 0 of the trajectory"):
        m.linearize_trajectory(m.simulate(0.1, 0.01, u=u[:10], every=2))
    with pytest.raises(ValueError, match="no momenta"):
        m.linearize_trajectory(m.simulate(0.1, 0.01, integrator="rk4"))
    # Another model's run: its arrays are not this model's samples.
    cart_run = tm.load(CART).simulate(0.1, 0.01)
    with pytest.raises(ValueError, match=r"do not fit this model: q, dq and p must be \(11, 4\)"):
        m.linearize_trajectory(cart_run)


def test_rollouts_take_a_model_each_for_a_sweep():
    m = tm.load(PENDULUM)
    heavy = m.with_parameters(masses={"bob": 3.0})
    assert heavy.evaluate(q=[0.0])["M"][0, 0] == pytest.approx(3.0, rel=1e-14)
    longer = m.with_parameters(constants={"bob": -4.0}, gravity=[0.0, 0.0, -9.81])
    r = m.rollouts(np.full((2, 1), 0.05), np.zeros((2, 1)), 1.0, 0.001, models=[m, longer])
    # The same model alone gives the same run; the 4 m rod swings slower.
    alone = m.simulate(1.0, 0.001, q0=[0.05])
    np.testing.assert_array_equal(r.q[0], alone.q)
    assert r.q[1, -1, 0] > r.q[0, -1, 0]
    with pytest.raises(ValueError, match="driven by variable"):
        m.with_parameters(constants={"pivot": 1.0})
    with pytest.raises(ValueError, match="no frame `hat`"):
        m.with_parameters(masses={"hat": 1.0})
    with pytest.raises(ValueError, match="1 models for 2 rollouts"):
        m.rollouts(np.zeros((2, 1)), np.zeros((2, 1)), 0.1, 0.01, models=[m])
    with pytest.raises(ValueError, match="other variables"):
        m.rollouts(np.zeros((1, 1)), np.zeros((1, 1)), 0.1, 0.01, models=[tm.load(CART)])


def test_progress_is_reported_and_an_exception_in_it_stops_the_run():
    m = tm.load(PENDULUM)
    seen = []
    traj = m.simulate(2.0, 0.001, progress=lambda t, total: seen.append((t, total)))
    assert 90 <= len(seen) <= 102, len(seen)
    assert all(total == 2.0 for _, total in seen)
    times = [t for t, _ in seen]
    assert times == sorted(times) and times[-1] > 1.95 and len(traj) == 2001

    calls = []

    def stop(t, total):
        calls.append(t)
        if t > 0.5:
            raise KeyError("enough")

    with pytest.raises(KeyError, match="enough"):
        m.simulate(2.0, 0.001, progress=stop)
    assert 0.5 < calls[-1] < 0.6


def test_a_batch_reports_its_progress_and_stops_on_an_exception_or_ctrl_c():
    m = tm.load(CART)
    seen = []
    r = m.rollouts(np.zeros((16, 2)) + [0.0, 0.2], np.zeros((16, 2)), 2.0, 0.001,
                   progress=lambda done, total: seen.append((done, total)))
    assert all(e is None for e in r.errors)
    done = [d for d, _ in seen]
    assert done == sorted(done) and len(set(done)) == len(done), seen
    assert seen[-1] == (16, 16) and all(total == 16 for _, total in seen)

    def stop(done, total):
        if done > 0:
            raise KeyError("enough")

    many = np.zeros((64, 2)) + [0.0, 0.2]
    with pytest.raises(KeyError, match="enough"):
        m.rollouts(many, np.zeros((64, 2)), 20.0, 0.001, threads=2, progress=stop)
    # Ctrl-C (SIGINT to this thread) stops a long batch too, without a callback.
    timer = threading.Timer(0.2, _thread.interrupt_main)
    timer.start()
    with pytest.raises(KeyboardInterrupt):
        m.rollouts(many, np.zeros((64, 2)), 200.0, 0.001, threads=2)
    timer.join()
    # And the next batch runs as before.
    again = m.rollouts(np.zeros((2, 2)) + [0.0, 0.2], np.zeros((2, 2)), 0.1, 0.01)
    assert all(e is None for e in again.errors)


def test_linearising_a_trajectory_reports_its_progress_and_stops_on_an_exception():
    m = tm.load(str(ROOT / "models/marionette.toml"))
    traj = m.simulate(1.0, 0.01)
    seen = []
    steps = m.linearize_trajectory(traj, threads=2,
                                   progress=lambda done, total: seen.append((done, total)))
    assert steps["q2_dq1"].shape[0] == 100
    done = [d for d, _ in seen]
    assert done == sorted(done) and len(set(done)) == len(done), seen
    assert seen[-1] == (100, 100) and all(total == 100 for _, total in seen)
    # The same numbers as without a callback.
    np.testing.assert_array_equal(m.linearize_trajectory(traj)["q2_dq1"], steps["q2_dq1"])

    def stop(done, total):
        raise KeyError("enough")

    with pytest.raises(KeyError, match="enough"):
        m.linearize_trajectory(traj, progress=stop)


def test_non_finite_states_and_inputs_and_mismatched_schedules_are_refused():
    m = tm.load(CART)
    # A NaN is named where it is given, not reported later as a failure of the dynamics.
    with pytest.raises(ValueError, match=r"q\[1\] \(`\w+`\) is NaN: every entry must be a finite"):
        m.evaluate(q=[0.0, np.nan])
    with pytest.raises(ValueError, match=r"dq0\[0\] .* is inf"):
        m.simulate(1.0, 0.01, dq0=[np.inf, 0.0])
    with pytest.raises(ValueError, match=r"u\[0\] .* is NaN"):
        m.simulate(1.0, 0.01, u=[np.nan])
    with pytest.raises(ValueError, match=r"u\[1\]\[0\] .* is NaN"):
        m.rollouts(np.zeros((2, 2)), np.zeros((2, 2)), 1.0, 0.01, u=np.array([[0.0], [np.nan]]))
    with pytest.raises(tm.SimulationError, match=r"p\[0\] \(the momentum of `x`\) is NaN"):
        m.linearize(dt=0.01, p=[np.nan, 0.0])
    # Inputs per step: one row a step, exactly (50 rows for a 100-step run is a mistake).
    with pytest.raises(ValueError, match="u has 50 rows of inputs, one a step; the run has 100 steps"):
        m.simulate(1.0, 0.01, u=np.zeros((50, 1)))
    with pytest.raises(ValueError, match="u has 150 rows of inputs, one a step; the run has 100 steps"):
        m.rollouts(np.zeros((2, 2)), np.zeros((2, 2)), 1.0, 0.01, u=np.zeros((2, 150, 1)))


def test_evaluate_linearize_and_forward_dynamics_refuse_bad_inputs_by_name():
    m = tm.load(CART)
    for call in (m.evaluate, m.forward_dynamics, m.linearize):
        with pytest.raises(ValueError, match=r"u\[0\] \(`push`\) is NaN"):
            call(u=[np.nan])
        with pytest.raises(ValueError, match=r"u has 2 entries; the model has 1 input \(push\)"):
            call(u=[1.0, 2.0])
        # Finite but too large for the model: the overflow names the input behind it.
        with pytest.raises(tm.SimulationError, match=r"under the inputs push = 1e308, is not finite"):
            call(u=[1e308])


def test_forward_dynamics_and_the_mass_matrix_alone_equal_the_evaluation():
    rng = np.random.default_rng(3)
    # Unconstrained (the articulated-body algorithm) and constrained (the KKT system).
    for path in (CART, str(ROOT / "models/marionette.toml")):
        m = tm.load(path)
        n = len(m.variables)
        for _ in range(3):
            q = m.q0 + rng.uniform(-0.2, 0.2, n)
            dq = rng.uniform(-1.0, 1.0, n)
            u = rng.uniform(-1.0, 1.0, len(m.inputs))
            e = m.evaluate(q, dq, t=0.3, u=u)
            qdd = m.forward_dynamics(q, dq, t=0.3, u=u)
            assert qdd.shape == (len(m.dynamic),) and qdd.dtype == np.float64
            assert np.array_equal(qdd, e["qdd"]), path
            M = m.mass_matrix(q)
            assert M.shape == (n, n)
            assert np.allclose(M, e["M"], rtol=1e-13, atol=1e-13 * np.abs(e["M"]).max()), path
    # The cart pushed at rest, bob hanging: ẍ = F / m_cart (the massless rod takes none).
    cart = tm.load(CART)
    qdd = cart.forward_dynamics(q=[0.0, 0.0], dq=[0.0, 0.0], u=[1.2])
    assert abs(qdd[0] - 1.2) < 1e-12
    with pytest.raises(ValueError, match=r"q has 3 entries; the model has 2 variables"):
        cart.mass_matrix([0.0, 0.0, 0.0])
    with pytest.raises(ValueError, match=r"u has 1 entry; the model has no inputs$"):
        tm.load(PENDULUM).forward_dynamics(u=[1.0])


def test_inverse_dynamics_undoes_forward_dynamics():
    m = tm.load(CART)
    rng = np.random.default_rng(5)
    for _ in range(3):
        q, dq, u = rng.uniform(-1, 1, 2), rng.uniform(-1, 1, 2), rng.uniform(-5, 5, 1)
        qdd = m.forward_dynamics(q, dq, u=u)
        tau = m.inverse_dynamics(q, dq, qdd)
        assert tau.shape == (2,)
        # The push on the cart, nothing on the free pendulum.
        assert np.allclose(tau, [u[0], 0.0], atol=1e-12 * (1 + abs(u[0])))
    # At rest, gravity compensation: the UR5's shoulder holds its arm up.
    ur5 = tm.load(str(ROOT / "models/ur5.urdf"))
    g = ur5.inverse_dynamics(ur5.q0)
    assert np.allclose(ur5.forward_dynamics(ur5.q0, np.zeros(6), u=g), 0.0, atol=1e-9)
    with pytest.raises(ValueError, match=r"ddq\[0\] .* is NaN"):
        m.inverse_dynamics(ddq=[np.nan, 0.0])


def test_the_constraints_alone_equal_the_evaluation():
    m = tm.load(str(ROOT / "models/marionette.toml"))
    q = m.q0 + np.linspace(-0.1, 0.1, len(m.variables))
    c, e = m.constraints_at(q), m.evaluate(q)
    assert c["h"].shape == (len(m.constraints),)
    assert c["dh_dq"].shape == (len(m.constraints), len(m.variables))
    assert np.array_equal(c["h"], e["h"]) and np.array_equal(c["dh_dq"], e["dh_dq"])
    # D²h against central differences of Dh.
    n, step = len(m.variables), 1e-6
    assert c["d2h_dqdq"].shape == (len(m.constraints), n, n)
    for j in range(n):
        dq = np.zeros(n)
        dq[j] = step
        fd = (m.constraints_at(q + dq)["dh_dq"] - m.constraints_at(q - dq)["dh_dq"]) / (2 * step)
        assert np.allclose(c["d2h_dqdq"][:, :, j], fd, rtol=1e-6, atol=1e-7), j
    assert np.abs(c["d2h_dqdq"]).max() > 0.1  # the strings' curvature is there to see
    with pytest.raises(ValueError, match=r"q\[0\] .* is NaN"):
        m.constraints_at(np.full(len(m.variables), np.nan))


def test_the_computed_torque_example_tracks_its_reference():
    import importlib.util

    path = ROOT / "python/examples/computed_torque.py"
    spec = importlib.util.spec_from_file_location("computed_torque", path)
    example = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(example)
    times, errors = example.track(duration=1.5, push=0.2)
    # The loop ë + 20 ė + 100 e = 0 from e = 0.2: (0.2 + 2 t) e^(-10 t), 3.5e-3 at 0.6 s;
    # the torque held over each step leaves about 1e-3.
    assert errors[0] > 0.15
    assert errors[times.searchsorted(0.6)] < 5e-3
    assert errors[times >= 1.0].max() < 2e-3


def test_optimize_reports_each_iteration_and_stops_on_an_exception():
    path = str(ROOT / "tasks/ur5-reach.toml")
    seen = []
    plan = tm.optimize(path, progress=lambda k, cost: seen.append((k, cost)))
    assert [k for k, _ in seen] == list(range(1, plan["iterations"] + 1))
    assert seen[-1][1] == plan["cost"]
    assert all(b[1] <= a[1] for a, b in zip(seen, seen[1:]))  # the cost never rises

    class Enough(Exception):
        pass

    calls = []

    def stop_at_two(k, cost):
        calls.append(k)
        if k == 2:
            raise Enough("two iterations are enough")

    with pytest.raises(Enough, match="two iterations are enough"):
        tm.optimize(path, progress=stop_at_two)
    assert calls == [1, 2]  # the solve ended there


def test_frame_kinematics_agree_with_the_evaluation_and_their_own_differences():
    rng = np.random.default_rng(11)
    m = tm.load(str(ROOT / "models/ur5.urdf"))
    n = len(m.variables)
    q, dq, ddq = rng.uniform(-1, 1, n), rng.uniform(-1, 1, n), rng.uniform(-1, 1, n)
    e = m.evaluate(q, dq)
    for frame in ("tool0", "wrist_2_link"):
        pose = m.frame_pose(frame, q)
        assert pose.shape == (4, 4) and pose.dtype == np.float64
        assert np.allclose(pose, e["poses"][frame], rtol=0, atol=1e-14)
        # The body twist is evaluate()'s; J @ dq is the twist in every reference.
        assert np.allclose(m.frame_velocity(frame, q, dq, reference="local"),
                           e["body_velocities"][frame], rtol=0, atol=1e-13)
        for reference in ("local", "local_world_aligned", "world"):
            J = m.frame_jacobian(frame, q, reference=reference)
            assert J.shape == (6, n)
            assert np.allclose(J @ dq, m.frame_velocity(frame, q, dq, reference=reference),
                               rtol=0, atol=1e-13)
        # The origin's velocity and classical acceleration against differences of the pose.
        h = 1e-5
        path = lambda t: q + t * dq + 0.5 * t * t * ddq
        p = lambda t: m.frame_pose(frame, path(t))[:3, 3]
        v = m.frame_velocity(frame, q, dq)[:3]
        assert np.allclose(v, (p(h) - p(-h)) / (2 * h), rtol=0, atol=1e-8)
        a = m.frame_acceleration(frame, q, dq, ddq, classical=True)
        assert a.shape == (3,)
        assert np.allclose(a, (p(h) - 2 * p(0) + p(-h)) / h**2, rtol=0, atol=1e-4)
        assert m.frame_acceleration(frame, q, dq, ddq).shape == (6,)
    com = m.center_of_mass(q, dq)
    assert set(com) == {"mass", "com", "vcom", "acom"}
    assert com["mass"] > 0 and com["com"].shape == (3,)
    assert np.allclose(m.com_jacobian(q) @ dq, com["vcom"], rtol=0, atol=1e-13)
    with pytest.raises(ValueError, match=r"there is no frame `hand`; the frames are `"):
        m.frame_jacobian("hand")
    with pytest.raises(ValueError, match=r'reference `body` is not one of "local", "local_world_aligned", "world"'):
        m.frame_velocity("tool0", reference="body")
    with pytest.raises(ValueError, match=r"q has 2 entries; the model has 6 variables"):
        m.frame_pose("tool0", [0.0, 0.0])


def test_a_newton_tolerance_too_loose_to_solve_the_step_is_refused():
    """newton_tol=1e-3 let Newton accept its predictor (the pendulum gained 40 J in 100 s):
    refused above 1e-6, as the command line refuses it; the stepper's tolerance too."""
    m = tm.load(PENDULUM)
    with pytest.raises(tm.SimulationError, match="looser than 1e-6"):
        m.simulate(1.0, 0.01, newton_tol=1e-3)
    loose = m.simulate(100.0, 0.01, newton_tol=1e-6).energy[-1]
    tight = m.simulate(100.0, 0.01).energy[-1]
    assert abs(loose - tight) < 1e-6 * abs(tight)
    from tree_mech import _native
    with pytest.raises(ValueError, match="looser than 1e-6"):
        _native.VariationalStepper(m, tolerance=1e-4)


def test_what_would_not_fit_in_memory_is_a_memory_error_not_a_dead_interpreter():
    """A run, or a batch, whose recorded samples would not fit in memory raises MemoryError
    before anything is taken (the marionette for 10⁶ s: about 100 GB)."""
    m = tm.load(str(ROOT / "models/marionette.toml"))
    with pytest.raises(MemoryError, match="would need about"):
        m.simulate(1e6, 0.01)
    q0 = np.tile(m.q0, (1000, 1))
    with pytest.raises(MemoryError, match="1000 runs"):
        m.rollouts(q0, np.zeros_like(q0), 1e4, 0.01)
    # The interpreter is alive and the model still runs.
    assert len(m.simulate(0.02, 0.01).t) == 3


def test_one_rule_for_every_front_end_and_no_argument_taken_for_what_it_is_not():
    """A run shorter than its step and a solve of no iterations are refused here as on the
    command line; bytes, text and masked entries are not numbers; a task dict takes numpy
    scalars and says what is wrong with a cost that is not a list of terms."""
    m = tm.load(PENDULUM)
    with pytest.raises(tm.SimulationError, match="shorter than one step"):
        m.simulate(1.0, 2.0)
    with pytest.raises(TypeError, match="got bytes"):
        m.simulate(0.1, 0.01, q0=b"a")
    with pytest.raises(TypeError, match="got str"):
        m.simulate(0.1, 0.01, q0="1")
    masked = np.ma.masked_array([0.3], mask=[True])
    with pytest.raises(ValueError, match="masked entries"):
        m.simulate(0.1, 0.01, q0=masked)
    unmasked = np.ma.masked_array([0.3], mask=[False])
    assert m.simulate(0.1, 0.01, q0=unmasked).q[0, 0] == 0.3
    task = {
        "model": str(ROOT / "models/cartpole.toml"),
        "dt": np.float32(0.02),
        "knots": np.int64(10),
        "start": {"q": {"theta": np.float64(3.0)}},
        "cost": [{"kind": "control", "weight": np.float32(0.5), "about": "zero"}],
    }
    assert tm.optimize(task, max_iterations=2)["iterations"] >= 1
    with pytest.raises(tm.SimulationError, match="at least one iteration"):
        tm.optimize(task, max_iterations=0)
    with pytest.raises(TypeError, match="`cost` must be a list of terms"):
        tm.optimize(dict(task, cost={"kind": "control", "weight": 1.0}))


def test_a_newcomers_calls_lock_sizes_and_values_by_name():
    """load(lock=…) as the command line's --lock; nq and nv; q and dq by name as task files
    allow, the rest at the model's own start."""
    panda = str(ROOT / "models/panda.urdf")
    full = tm.load(panda)
    fingers = [v for v in full.variables if "finger" in v]
    assert len(fingers) == 2
    for lock in (",".join(fingers), fingers, {f: None for f in fingers}):
        held = tm.load(panda, lock=lock)
        assert held.nq == held.nv == full.nq - 2 and not set(fingers) & set(held.variables)
    at = tm.load(panda, lock={fingers[0]: 0.02, fingers[1]: 0.01})
    assert at.nq == full.nq - 2
    with pytest.raises(tm.ModelError, match="no such variable"):
        tm.load(panda, lock=["nowhere"])
    with pytest.raises(ValueError, match="lock `a=x`: `x` is not a finite number"):
        tm.load(panda, lock="a=x")
    m = tm.load(str(ROOT / "models/cartpole.toml"))
    by_name = m.simulate(0.5, 0.01, q0={"theta": 0.3})
    q0 = np.array(m.q0)
    q0[m.variables.index("theta")] = 0.3
    by_array = m.simulate(0.5, 0.01, q0=q0)
    assert np.array_equal(by_name.q, by_array.q)
    assert np.array_equal(m.evaluate(q={"theta": 0.3})["M"], m.evaluate(q=q0)["M"])
    with pytest.raises(ValueError, match="q0 names `thta`, which is not a variable of the model; the names are `theta`"):
        m.simulate(0.5, 0.01, q0={"thta": 0.3})
    with pytest.raises(ValueError, match=r"dq0\[0\] \(`x`\) is NaN"):
        m.simulate(0.5, 0.01, dq0={"x": float("nan")})


def test_a_mimic_joint_follows_its_leader_or_stands_alone_when_asked():
    """The Panda with its hand: the second finger mirrors the first (one variable for both,
    its frame moving with it); independent_mimics=True gives it a variable of its own."""
    path = ROOT / "models/panda-hand.urdf"
    hand = tm.load(str(path))
    assert hand.nq == 8 and "panda_finger_joint2" not in hand.variables
    independent = tm.load(path, independent_mimics=True)
    assert independent.nq == 9 and "panda_finger_joint2" in independent.variables
    text = path.read_text()
    assert tm.loads(text, format="urdf").nq == 8
    assert tm.loads(text, format="urdf", independent_mimics=True).nq == 9
    run = hand.simulate(0.2, 0.01)
    assert np.all(np.isfinite(run.q))


@pytest.mark.parametrize("integrator", ["vi", "rk4"])
def test_a_stepper_steps_as_simulate_runs_under_the_same_inputs(integrator):
    # The cart-pole pushed by u_k at step k: stepped one step at a time (the VI keeping its
    # momentum between steps) it is the run simulate takes under the same schedule.
    m = tm.load(CART)
    u = 2.0 * np.sin(0.05 * np.arange(150))[:, None]
    run = m.simulate(1.5, 0.01, integrator=integrator, u=u)
    s = m.stepper(0.01, integrator=integrator)
    assert isinstance(s, tm.Stepper) and s.t == 0.0 and s.dt == 0.01
    for k in range(len(run)):
        assert s.t == pytest.approx(run.t[k], abs=1e-12)
        np.testing.assert_allclose(s.q, run.q[k], rtol=1e-13, atol=1e-13)
        np.testing.assert_allclose(s.dq, run.dq[k], rtol=1e-13, atol=1e-13)
        assert s.energy == pytest.approx(run.energy[k], rel=1e-12, abs=1e-12)
        if k < len(u):
            s.step(u[k])
    assert s.steps == 150 and (s.p is None) == (integrator == "rk4")
    # reset starts again from the model's start, or from a state by name.
    s.reset()
    assert s.t == 0.0 and s.steps == 0 and np.array_equal(s.q, m.q0)
    s.reset(q0={"theta": 0.3})
    assert list(s.q) == [0.0, 0.3]


def test_a_stepper_closes_the_loop():
    # PD on the pendulum's torque-free joint via a model with an input: the loop reads the
    # state each step and brings the pendulum from 0.5 rad to rest (ω² = kp + g, ζ ≈ 0.73).
    m = tm.loads(
        '[[frame]]\nname = "pivot"\nrx = "theta"\n[[frame]]\nname = "bob"\nparent = "pivot"\n'
        'tz = -1.0\nmass = 1.0\n[variables.theta]\nq0 = 0.5\n'
        '[[input]]\nname = "torque"\nvariable = "theta"\n'
    )
    s = m.stepper(0.01)
    for _ in range(1000):
        s.step([-20.0 * s.q[0] - 8.0 * s.dq[0]])
    assert abs(s.q[0]) < 1e-6 and s.t == pytest.approx(10.0, abs=1e-12)
    free = m.stepper(0.01)
    for _ in range(1000):
        free.step()
    # Without the loop it keeps swinging: the VI holds its energy.
    assert free.energy == pytest.approx(-9.81 * math.cos(0.5), rel=1e-4)


def test_a_stepper_refuses_bad_arguments_and_stops_after_a_failure():
    m = tm.load(CART)
    with pytest.raises(ValueError, match="rk45 chooses its own"):
        m.stepper(0.01, integrator="rk45")
    with pytest.raises(ValueError, match="time step must be a positive finite number"):
        m.stepper(0.0)
    with pytest.raises(ValueError, match="looser than"):
        m.stepper(0.01, newton_tol=1e-3)
    s = m.stepper(0.01)
    with pytest.raises(ValueError, match=r"u has 2 entries; the model has 1 input \(push\)"):
        s.step([1.0, 2.0])
    with pytest.raises(ValueError, match="input `push` is NaN, not a finite number"):
        s.step([float("nan")])
    with pytest.raises(TypeError):
        s.step("ab")
    assert s.steps == 0
    with pytest.raises(tm.SimulationError, match="not finite") as failed:
        for _ in range(1000):
            s.step([1e308])
    k = failed.value.step
    assert k is not None and k <= s.steps + 1
    with pytest.raises(tm.SimulationError, match="the stepper stopped .* start it again with reset"):
        s.step([0.0])
    with pytest.raises(ValueError, match="q0 names `thta`.*theta"):
        s.reset(q0={"thta": 0.1})
    s.reset()
    s.step([1.0])
    assert s.steps == 1
