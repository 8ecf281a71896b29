"""tree_mech.trep.discopt against trep 1.0.2's ``trep.discopt``: the scripts of
trep_discopt_scripts.py, run here on the layer, match what they recorded on trep
(fixtures/trep-discopt.json, written by tools/reference/trep_api.py under Python 2.7); and
what the fixtures cannot show — derivative checks, errors, monitors — on its own."""
import json
import pathlib

import numpy as np
import pytest

from tree_mech import trep
from tree_mech.trep import discopt

import trep_discopt_scripts

HERE = pathlib.Path(__file__).parent
FIXTURE = json.loads((HERE / "fixtures" / "trep-discopt.json").read_text())
# trep's Newton stops at its own tolerance (1e-10 on the residual); ours goes on to 1e-12,
# so quantities that pass through a constrained step agree to about 1e-9 of their scale.
TOLERANCE = 1e-8


def compare(ours, theirs, path):
    if isinstance(theirs, dict):
        assert set(ours) == set(theirs), f"{path}: keys differ"
        for key in theirs:
            compare(ours[key], theirs[key], f"{path}.{key}")
        return
    if isinstance(theirs, (bool, str)) or (isinstance(theirs, list) and theirs
                                          and isinstance(theirs[0], str)):
        assert ours == theirs, f"{path}: {ours!r} against trep's {theirs!r}"
        return
    a, b = np.asarray(ours, dtype=float), np.asarray(theirs, dtype=float)
    assert a.shape == b.shape, f"{path}: shape {a.shape} against trep's {b.shape}"
    scale = max(1.0, float(np.max(np.abs(b)))) if b.size else 1.0
    err = float(np.max(np.abs(a - b))) if b.size else 0.0
    assert err <= TOLERANCE * scale, f"{path}: off by {err:.3e} (scale {scale:.3e})"


@pytest.fixture(scope="module", params=[s[0] for s in trep_discopt_scripts.SYSTEMS])
def recorded(request):
    name, build, dt, n = next(s for s in trep_discopt_scripts.SYSTEMS if s[0] == request.param)
    return name, trep_discopt_scripts.record(trep, build, dt, n), FIXTURE[name]


@pytest.mark.parametrize("group", [
    ["nX", "nU", "kf", "X", "U", "split_p"],
    ["f", "fdx", "fdu", "fdxdx", "fdxdu", "fdudu"],
    ["A", "B", "K", "K_weighted", "project_X", "project_U", "dproject_dX", "dproject_dU"],
    ["lq_K", "lq_C", "lq_P", "lq_b", "lqr_P"],
    ["l", "l_dx", "l_du", "m", "m_dx", "cost"],
    ["steepest", "quasi", "newton"],
    ["armijo", "step", "optimize"],
], ids=["trajectory", "step-map", "linearisation", "lq", "cost", "descent", "optimiser"])
def test_discopt_matches_trep(recorded, group):
    name, ours, theirs = recorded
    for key in group:
        compare(ours[key], theirs[key], f"{name}.{key}")


def test_the_optimiser_takes_treps_steps(recorded):
    """The same methods in the same order (quasi, then newton, with its fallbacks), to an
    optimum in as many steps."""
    _, ours, theirs = recorded
    assert ours["optimize"]["methods"] == theirs["optimize"]["methods"]
    assert ours["optimize"]["converged"] and theirs["optimize"]["converged"]


def system_and_trajectory(n=11, dt=0.05):
    s = trep_discopt_scripts.pendulum_on_cart(trep)
    mvi = trep.MidpointVI(s)
    q0 = np.array(s.q)
    mvi.initialize_from_configs(0.0, q0, dt, q0)
    d = discopt.DSystem(mvi, np.arange(n) * dt)
    t = d.time
    X, U = d.build_trajectory(u=0.2 * np.sin(t[:-1]), rho=0.3 * t[1:] ** 2)
    X = trep_discopt_scripts.rollout(d, d.build_state(mvi.q2, mvi.p2), U)
    return d, X, U


@pytest.mark.parametrize("which", ["fdx", "fdu", "fdxdx", "fdxdu", "fdudu"])
def test_every_step_derivative_passes_its_own_check(which):
    d, X, U = system_and_trajectory()
    delta = 1e-5
    error, exact, approx = getattr(d, f"check_{which}")(X[4], U[4], 4, delta)
    # Central differences of the lower derivative: truncation O(δ²), rounding about
    # ε·|lower derivative|/δ.
    d.set(X[4], U[4], 4)
    lower = np.linalg.norm(d.fdx()) + np.linalg.norm(d.fdu())
    allowed = 1e-6 * exact + 100 * np.finfo(float).eps * lower / delta
    assert exact > 0 and error <= allowed, (which, error, exact, approx)


def test_the_cost_derivatives_pass_the_optimisers_checks():
    d, X, U = system_and_trajectory()
    xd = np.zeros((len(X), d.nX))
    cost = discopt.DCost(xd, np.zeros(U.shape), np.eye(d.nX), 0.1 * np.eye(d.nU))
    opt = discopt.DOptimizer(d, cost, monitor=discopt.DOptimizerMonitor())
    for method in ("steepest", "quasi", "newton"):
        check = opt.check_dcost(X, U, method)
        assert check.result and abs(check.exact_dcost) > 0, (method, check)
    check = opt.check_ddcost(X, U, "newton", delta=1e-5, tolerance=1e-3)
    assert abs(check.error) <= 1e-3 * abs(check.exact_ddcost), check


def test_model_weights_are_treps_functions_of_k_and_arrays():
    d, X, U = system_and_trajectory()
    cost = discopt.DCost(np.zeros((len(X), d.nX)), np.zeros(U.shape), np.eye(d.nX),
                         np.eye(d.nU))
    opt = discopt.DOptimizer(d, cost, monitor=discopt.DOptimizerMonitor())
    Q, R, S = opt.calc_quasi_model(X, U)
    assert np.array_equal(Q(3), Q[3]) and Q.shape == (len(X), d.nX, d.nX)
    assert R(0).shape == (d.nU, d.nU) and S(0).shape == (d.nX, d.nU)
    # calc_ddcost takes trep's functions as well as the stacks.
    dX, dU = np.ones(X.shape), np.ones(U.shape)
    stacks = opt.calc_ddcost(X, U, dX, dU, Q, R, S)
    functions = opt.calc_ddcost(X, U, dX, dU, lambda k: Q[k], lambda k: R[k], lambda k: S[k])
    assert stacks == functions and stacks > 0


def test_the_default_monitor_prints_and_keeps_the_history(capsys):
    d, X, U = system_and_trajectory()
    xd = np.tile(X[0], (len(X), 1))
    xd[:, 0] = 0.0
    cost = discopt.DCost(xd, np.zeros(U.shape), np.eye(d.nX), 0.1 * np.eye(d.nU))
    opt = discopt.DOptimizer(d, cost)
    converged, nX, nU = opt.optimize(X, U, max_steps=30)
    out = capsys.readouterr().out
    assert converged and "converged" in out and "quasi" in out
    history = opt.monitor.cost_history
    costs = [history[k] for k in sorted(history)]
    assert all(b <= a for a, b in zip(costs, costs[1:])), costs
    assert opt.calc_cost(nX, nU) < opt.calc_cost(X, U)


def test_projection_keeps_a_trajectory_and_dproject_its_tangent():
    d, X, U = system_and_trajectory()
    K = d.calc_feedback_controller(X, U)
    pX, pU = d.project(X, U, K)
    assert np.allclose(pX, X, rtol=0, atol=1e-12) and np.allclose(pU, U, rtol=0, atol=1e-12)
    A, B = d.linearize_trajectory(X, U)
    dX, dU = d.dproject(A, B, np.zeros(X.shape), np.ones(U.shape), K)
    for k in range(len(U)):
        assert np.allclose(dX[k + 1], A[k] @ dX[k] + B[k] @ dU[k], rtol=0, atol=1e-12)


def test_optimising_the_start_moves_it():
    d, X, U = system_and_trajectory()
    xd = np.tile(X[0], (len(X), 1))
    xd[:, 0] = 0.0
    cost = discopt.DCost(xd, np.zeros(U.shape), np.eye(d.nX), 0.1 * np.eye(d.nU))
    opt = discopt.DOptimizer(d, cost, monitor=discopt.DOptimizerMonitor())
    opt.optimize_ic = True
    _, dX, _, _, _, _ = opt.calc_descent_direction(X, U, "quasi")
    assert np.abs(dX[0]).max() > 0
    converged, nX, nU = opt.optimize(X, U, max_steps=30)
    assert converged and abs(nX[0, 0]) < abs(X[0, 0])


def test_convert_trajectory_moves_parts_by_name():
    """Into a system with a config and an input of its own, made first (so every column
    moves): what both have keeps its values under its name, the rest is zero; and back."""
    d, X, U = system_and_trajectory()
    s = trep.System()
    lift = trep.Frame(s.world_frame, trep.TZ, "lift", name="lift", mass=1.0)
    trep.forces.ConfigForce(s, "lift", "raise")
    cart = trep.Frame(lift, trep.TX, "x", kinematic=True, name="cart", mass=1.0)
    pivot = trep.Frame(cart, trep.RX, "theta", name="pivot")
    trep.Frame(pivot, trep.TZ, -1.0, name="bob", mass=1.0)
    trep.forces.ConfigForce(s, "theta", "torque")
    mvi = trep.MidpointVI(s)
    other = discopt.DSystem(mvi, d.time)
    assert [c.name for c in s.configs] == ["lift", "theta", "x"]
    Xb, Ub = other.convert_trajectory(d, X, U)
    Q, p, v, u, rho = other.split_trajectory(Xb, Ub)
    Qa, pa, va, ua, rhoa = d.split_trajectory(X, U)
    assert np.array_equal(Q[:, 0], np.zeros(len(X))) and np.array_equal(p[:, 0], np.zeros(len(X)))
    assert np.array_equal(Q[:, 1:], Qa) and np.array_equal(p[:, 1], pa[:, 0])
    assert np.array_equal(v, va) and np.array_equal(rho, rhoa)
    assert np.array_equal(u[:, 0], np.zeros(len(U))) and np.array_equal(u[:, 1], ua[:, 0])
    back = d.convert_trajectory(other, Xb, Ub)
    assert np.array_equal(back.X, X) and np.array_equal(back.U, U)


def test_bad_arguments_are_plain_errors():
    d, X, U = system_and_trajectory()
    with pytest.raises(ValueError, match="shape"):
        d.build_state(Q=[1.0, 2.0, 3.0])
    with pytest.raises(ValueError, match="outside the time base"):
        d.set(X[0], U[0], 99)
    d.set(X[-1], U[-1], d.kf())
    with pytest.raises(ValueError, match="no next state"):
        d.f()
    with pytest.raises(ValueError, match="increasing"):
        discopt.DSystem(d.varint, [0.0, 0.0])
    with pytest.raises(ValueError, match="Q has shape"):
        discopt.DCost(X, U, np.eye(2), np.eye(d.nU))
    opt = discopt.DOptimizer(d, discopt.DCost(X, U, np.eye(d.nX), np.eye(d.nU)))
    with pytest.raises(ValueError, match="unknown descent method"):
        opt.calc_descent_direction(X, U, "sideways")


def test_parts_are_taken_as_trep_assigns_them():
    # trep assigns each part into its slice, so what numpy broadcasts there is accepted: rho
    # of shape (N − 1, 1) on a system without kinematic configs (its slice is (N − 1, 0)),
    # and a z longer than the state (trep reads the rows it needs).
    s = trep.System()
    s.import_frames([trep.rx("theta", name="pivot"), [trep.tz(-1.0, mass=1.0, name="bob")]])
    trep.potentials.Gravity(s)
    trep.forces.ConfigForce(s, "theta", "torque")
    mvi = trep.MidpointVI(s)
    mvi.initialize_from_configs(0.0, [0.2], 0.01, [0.2])
    d = discopt.DSystem(mvi, np.arange(5) * 0.01)
    X, U = d.build_trajectory(u=np.ones((4, 1)), rho=np.zeros((4, 1)))
    assert U.shape == (4, 1) and np.all(U == 1.0)
    with pytest.raises(ValueError, match="rho has shape"):
        d.build_trajectory(rho=np.zeros((4, 2)))
    d.set(X[0], U[0], 0)
    z = np.array([0.3, -0.7])
    np.testing.assert_array_equal(d.fdxdx(np.concatenate([z, [5.0]])), d.fdxdx(z))
    with pytest.raises(ValueError, match="at least"):
        d.fdxdx(z[:1])


def test_solve_tv_lqr_is_the_riccati_recursion():
    """On a fixed system over a long horizon the gains settle to the DARE's: the cost-to-go
    P satisfies P = Q + AᵀPA − AᵀPB(R + BᵀPB)⁻¹BᵀPA."""
    A = np.array([[1.0, 0.1], [0.0, 1.0]])
    B = np.array([[0.005], [0.1]])
    K, P = discopt.solve_tv_lqr([A] * 400, [B] * 400, lambda k: np.eye(2), lambda k: np.eye(1))
    gamma = np.eye(1) + B.T @ P @ B
    residual = np.eye(2) + A.T @ P @ A - A.T @ P @ B @ np.linalg.solve(gamma, B.T @ P @ A) - P
    assert np.abs(residual).max() < 1e-9 * np.abs(P).max()
    assert np.allclose(K[0], np.linalg.solve(gamma, B.T @ P @ A), rtol=1e-12, atol=0)


def test_descent_plot_draws_the_cost_along_the_direction(monkeypatch):
    """With a stand-in for matplotlib: the true cost change along the direction starts as
    the model does (zero, then falling at the rate Dh·ζ), and the Armijo points lie on
    the line search's steps."""
    import sys
    import types

    drawn = {}

    def plot(x, y, *style, label=None):
        drawn[label] = (np.asarray(x, dtype=float), np.asarray(y, dtype=float))

    pyplot = types.SimpleNamespace(plot=plot, legend=lambda: drawn.setdefault("legend", None))
    package = types.ModuleType("matplotlib")
    package.pyplot = pyplot
    monkeypatch.setitem(sys.modules, "matplotlib", package)
    monkeypatch.setitem(sys.modules, "matplotlib.pyplot", pyplot)
    d, X, U = system_and_trajectory()
    xd = np.tile(X[0], (len(X), 1))
    xd[:, 0] = 0.0
    cost = discopt.DCost(xd, np.zeros(U.shape), np.eye(d.nX), 0.1 * np.eye(d.nU))
    opt = discopt.DOptimizer(d, cost, monitor=discopt.DOptimizerMonitor())
    opt.descent_plot(X, U, method="quasi", points=23)
    z, true = drawn["cost"]
    _, model = drawn["model"]
    assert len(z) == 23 and "legend" in drawn
    near = np.argsort(np.abs(z))[:3]
    assert np.allclose(true[near], model[near], rtol=0.05, atol=1e-9 * abs(opt.calc_cost(X, U)))
    assert true[-1] < 0  # the full step lowers the cost
    armijo, _ = drawn["Armijo points"]
    assert np.allclose(armijo[:3], [1.0, 0.7, 0.49])


def saved_parts():
    s, t, Q, p, v, u, rho = trep_discopt_scripts.saved_trajectory(trep)
    return s, [t, Q, p, v, u, rho]


def same_parts(got, want):
    assert len(got) == len(want)
    for g, w in zip(got, want):
        if w is None:
            assert g is None
        else:
            assert np.array_equal(np.asarray(g, dtype=float), np.asarray(w, dtype=float))


def test_a_trajectory_file_trep_wrote_loads():
    s, parts = saved_parts()
    same_parts(trep.load_trajectory(str(HERE / "fixtures" / "trep-trajectory.mat"), s), parts)
    # Without a system: each part with its column names, trep's way.
    t, (names, Q), _, (vnames, v), (unames, u), _ = trep.load_trajectory(
        str(HERE / "fixtures" / "trep-trajectory"))
    assert names == ["theta", "x"] and vnames == ["x"] and unames == ["torque"]
    assert v is None and u is None and np.array_equal(Q, parts[1])


def test_trep_read_what_the_layer_writes(tmp_path):
    """trep loaded the committed file the layer wrote (the fixture records what it read);
    the layer's writer still writes a file that loads the same."""
    s, parts = saved_parts()
    read_by_trep = [None if x == "none" else x for x in FIXTURE["loaded_by_trep"]]
    same_parts(read_by_trep, parts)
    trep.save_trajectory(str(tmp_path / "again"), s, *parts)
    committed = HERE / "fixtures" / "tree-mech-trajectory.mat"
    same_parts(trep.load_trajectory(str(tmp_path / "again.mat"), s),
               trep.load_trajectory(str(committed), s))


def test_state_trajectories_round_trip_through_a_file(tmp_path):
    d, X, U = system_and_trajectory()
    d.save_state_trajectory(str(tmp_path / "x.mat"), X, U)
    back = d.load_state_trajectory(str(tmp_path / "x"))
    assert np.array_equal(back.X, X) and np.array_equal(back.U, U)
    with pytest.raises(ValueError, match="times"):
        discopt.DSystem(d.varint, np.arange(5) * 0.1).load_state_trajectory(str(tmp_path / "x"))


def test_a_file_that_is_not_a_trajectory_is_refused(tmp_path):
    (tmp_path / "junk.mat").write_bytes(b"not a MAT-file at all" * 10)
    with pytest.raises(ValueError, match="level-5 MAT-file"):
        trep.load_trajectory(str(tmp_path / "junk.mat"))
    # A file cut short names itself and what is wrong.
    whole = (HERE / "fixtures" / "trep-trajectory.mat").read_bytes()
    (tmp_path / "cut.mat").write_bytes(whole[:-40])
    with pytest.raises(ValueError, match=r"cut\.mat: the file ends inside an element"):
        trep.load_trajectory(str(tmp_path / "cut.mat"))
    s, parts = saved_parts()
    with pytest.raises(ValueError, match="Q has shape"):
        trep.save_trajectory(str(tmp_path / "bad"), s, parts[0], parts[1][:3])


def test_compressed_and_small_elements_read_as_matlab_writes_them(tmp_path):
    """MATLAB (and scipy with compression) may wrap each element in zlib, and write a name of
    up to four bytes in the small-element form: both read as the plain file."""
    import struct
    import zlib

    from tree_mech.trep import _matfile

    plain = tmp_path / "plain.mat"
    _matfile.write(str(plain), {"time": np.array([[0.0, 0.5]]), "Q_index": ["a", "bc"]})
    data = plain.read_bytes()
    packed, at = data[:128], 128
    while at < len(data):
        kind, size = struct.unpack("<II", data[at:at + 8])
        element = data[at:at + 8 + size + (-size % 8)]
        body = zlib.compress(element)
        packed += struct.pack("<II", _matfile.MI_COMPRESSED, len(body)) + body
        at += len(element)
    (tmp_path / "packed.mat").write_bytes(packed)
    # A small element: the name "time" in the tag's upper half and the next four bytes.
    small = data.replace(struct.pack("<II", _matfile.MI_INT8, 4) + b"time" + b"\0" * 4,
                         struct.pack("<I", (4 << 16) | _matfile.MI_INT8) + b"time")
    assert len(small) == len(data) - 8
    # The enclosing matrix (the file's first element) is 8 bytes shorter now.
    outer = struct.unpack("<I", small[132:136])[0]
    small = small[:132] + struct.pack("<I", outer - 8) + small[136:]
    (tmp_path / "small.mat").write_bytes(small)
    want = _matfile.read(str(plain))
    assert want["Q_index"] == ["a", "bc"] and np.array_equal(want["time"], [[0.0, 0.5]])
    for name in ("packed.mat", "small.mat"):
        got = _matfile.read(str(tmp_path / name))
        assert got["Q_index"] == want["Q_index"] and np.array_equal(got["time"], want["time"])


def test_the_default_monitor_gives_the_costs_in_step_order(capsys):
    # trep's monitors hand their histories back as lists (get_costs, get_dcosts), and
    # trep.system is a module scripts reach the trajectory files through.
    d, X, U = system_and_trajectory()
    monitor = discopt.DOptimizerDefaultMonitor()
    opt = discopt.DOptimizer(d, discopt.DCost(X, U, np.eye(d.nX), np.eye(d.nU)),
                             monitor=monitor)
    U1 = U + 0.1  # a trajectory of the system away from the cost's target
    X1 = trep_discopt_scripts.rollout(d, X[0], U1)
    result = opt.optimize(X1, U1, max_steps=4)
    costs, dcosts = monitor.get_costs(), monitor.get_dcosts()
    # Step by step, a descent: each step starts below the last, along a descent direction,
    # and the result is below the last step's start.
    assert len(costs) == len(dcosts) >= 2
    assert all(b < a for a, b in zip(costs, costs[1:])), costs
    assert all(g < 0 for g in dcosts), dcosts
    assert opt.calc_cost(result.X, result.U) <= costs[-1]
    assert trep.system.save_trajectory is trep.save_trajectory
    assert trep.system.System is trep.System


def test_dsystem_keeps_treps_private_time_name():
    # trep's own puppet-optimization example reads dsys._time.
    s = trep.System()
    s.import_frames([trep.rx("theta", name="pivot"), [trep.tz(-1.0, mass=1.0)]])
    trep.potentials.Gravity(s)
    trep.forces.ConfigForce(s, "theta", "torque")
    dsys = discopt.DSystem(trep.MidpointVI(s), np.arange(0.0, 0.1, 0.01))
    assert dsys._time is not None and np.array_equal(dsys._time, dsys.time)
