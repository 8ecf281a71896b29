# -*- coding: utf-8 -*-
"""trep-style scripts, run unchanged by trep 1.0.2 itself (Python 2.7, through
tools/reference/trep_api.py, which saves what they record as tests/fixtures/trep-api.json)
and by tree_mech.trep (python/tests/test_trep.py, which compares). Each takes the `trep`
module as its argument: that is the only difference between the two runs. Written for this
project (no trep code or examples); Python 2.7 and 3 alike.
"""
from __future__ import division, print_function

import math

import numpy as np


def cart_pendulum_string(trep):
    """A cart (x) carrying a double pendulum (theta, phi) whose tip hangs on a string of
    kinematic length from a kinematically driven hand; a spring on phi, damping, a push on
    the cart, gravity."""
    s = trep.System()
    cart = trep.Frame(s.world_frame, trep.TX, "x", name="cart")
    cart.set_mass(2.0, 0.1, 0.2, 0.3)
    pivot = trep.Frame(cart, trep.RY, "theta", name="pivot")
    bob = trep.Frame(pivot, trep.TZ, -0.8, name="bob", mass=(0.5, 0.01, 0.02, 0.015))
    elbow = trep.Frame(bob, trep.RY, "phi", name="elbow")
    trep.Frame(elbow, trep.TZ, -0.5, name="tip", mass=0.3)
    hand_x = trep.Frame(s.world_frame, trep.TX, "hand_x", kinematic=True, name="hand_x")
    trep.Frame(hand_x, trep.TZ, 1.0, name="hand")
    trep.potentials.Gravity(s, [0.0, 0.0, -9.8])
    trep.potentials.ConfigSpring(s, "phi", 3.0, q0=0.1)
    trep.forces.Damping(s, 0.05, {"theta": 0.2})
    trep.forces.ConfigForce(s, "x", "push")
    trep.constraints.Distance(s, "tip", "hand", "string")
    # A state on the string: its length is the tip-hand distance there.
    s.get_config("x").q = 0.1
    s.get_config("theta").q = 0.3
    s.get_config("phi").q = -0.4
    s.get_config("hand_x").q = 0.25
    s.get_config("string").q = 1.0
    tip, hand = s.get_frame("tip"), s.get_frame("hand")
    s.get_config("string").q = float(np.linalg.norm(tip.p()[:3] - hand.p()[:3]))
    return s


def ball_on_incline(trep):
    """A point mass free in space (bx, by, bz) held on an inclined plane, with gravity."""
    s = trep.System()
    trep.Frame(s.world_frame, trep.RX, 0.3, name="incline")
    fx = trep.Frame(s.world_frame, trep.TX, "bx")
    fy = trep.Frame(fx, trep.TY, "by")
    ball = trep.Frame(fy, trep.TZ, "bz", name="ball")
    ball.set_mass(1.5, 0.1, 0.1, 0.1)
    trep.potentials.Gravity(s)
    trep.constraints.PointOnPlane(s, "incline", [0.0, 0.0, 1.0], "ball")
    # On the plane: n = (0, -sin 0.3, cos 0.3), so z = tan(0.3) y.
    s.get_config("bx").q = 0.2
    s.get_config("by").q = 0.5
    s.get_config("bz").q = math.tan(0.3) * 0.5
    return s


def imported_tree(trep):
    """Two pendulums hanging from a carriage on a driven rail, declared as trep's nested
    definition lists (trep.tx … trep.rz through import_frames), masses given as a number and
    as (m, Ixx, Iyy, Izz); gravity, a config spring, damping."""
    s = trep.System()
    frames = [
        trep.tx("rail", kinematic=True, name="carriage"), [
            trep.ry("a1", name="A1"), [
                trep.tz(-0.6, name="A1_mass", mass=(0.8, 0.01, 0.02, 0.01)),
                trep.tz(-1.2), [
                    trep.ry("a2", name="A2"), [
                        trep.tz(-0.5, name="A2_mass", mass=0.4)]]],
            trep.ty(0.3), [
                trep.rx("b1", name="B1"), [
                    trep.tz(-0.9, name="B1_mass", mass=0.6)]]]]
    s.import_frames(frames)
    trep.potentials.Gravity(s)
    trep.potentials.ConfigSpring(s, "a2", 2.0, q0=0.2)
    trep.forces.Damping(s, 0.02)
    s.q = {"a1": 0.4, "a2": -0.3, "b1": 0.2, "rail": 0.1}
    return s


def coupled_pendulums(trep):
    """Two pendulums, one swinging in y-z and one in x-z, their bobs joined by a spring and a
    damper, the first also sprung to a point of the world and the second to the world's
    origin; gravity."""
    s = trep.System()
    a = trep.Frame(s.world_frame, trep.RX, "a", name="a")
    trep.Frame(a, trep.TZ, -1.0, name="bob_a", mass=1.0)
    offset = trep.Frame(s.world_frame, trep.TX, 0.8, name="offset")
    b = trep.Frame(offset, trep.RY, "b", name="b")
    trep.Frame(b, trep.TZ, -1.2, name="bob_b", mass=(0.7, 0.01, 0.01, 0.02))
    anchor = trep.Frame(s.world_frame, trep.TY, 0.5, name="anchor")
    trep.potentials.Gravity(s)
    trep.potentials.LinearSpring(s, "bob_a", "bob_b", 4.0, x0=0.6)
    trep.potentials.LinearSpring(s, "bob_a", anchor, 1.5, x0=0.9)
    trep.potentials.LinearSpring(s, s.world_frame, "bob_b", 0.8, x0=1.0)
    trep.forces.LinearDamper(s, "bob_a", "bob_b", 0.3)
    s.q = {"a": 0.3, "b": -0.2}
    return s


def pinned_masses(trep):
    """A spherical pendulum whose tip carries, by point constraints, a free ball (3-D:
    PointToPoint3D), a cup sliding in x-z (PointToPoint2D) and a slider on a rail along y
    (PointToPoint1D); damping on the pendulum, a push on the ball, gravity."""
    s = trep.System()
    th1 = trep.Frame(s.world_frame, trep.RX, "th1", name="th1")
    th2 = trep.Frame(th1, trep.RY, "th2", name="th2")
    trep.Frame(th2, trep.TZ, -1.0, name="tip", mass=1.0)
    bx = trep.Frame(s.world_frame, trep.TX, "bx")
    by = trep.Frame(bx, trep.TY, "by")
    trep.Frame(by, trep.TZ, "bz", name="ball", mass=0.5)
    cx = trep.Frame(s.world_frame, trep.TX, "cx")
    trep.Frame(cx, trep.TZ, "cz", name="cup", mass=0.2)
    trep.Frame(s.world_frame, trep.TY, "sy", name="slider", mass=0.3)
    trep.potentials.Gravity(s)
    trep.forces.Damping(s, 0.0, {"th1": 0.1, "th2": 0.05})
    trep.forces.ConfigForce(s, "bx", "push")
    trep.constraints.PointToPoint3D(s, "tip", "ball", name="pin")
    trep.constraints.PointToPoint2D(s, "xz", "cup", "ball", name="cup_pin")
    trep.constraints.PointToPoint1D(s, "y", "slider", "tip", name="rail")
    # Everything on its constraints: the ball, cup and slider where the tip is.
    s.q = {"th1": 0.3, "th2": -0.2}
    tip = s.get_frame("tip").p()
    s.q = {"th1": 0.3, "th2": -0.2, "bx": tip[0], "by": tip[1], "bz": tip[2],
           "cx": tip[0], "cz": tip[2], "sy": tip[1]}
    return s


def python_elements(trep, parts=("potential", "force", "constraint")):
    """A pendulum (theta) beside a point (x, z) held on a circle, with a potential, a force and
    the constraint all written in Python, as trep lets a script subclass its bases: a
    twisting spring on theta coupled to x, a drag on both that depends on the configuration,
    and ``x² + z² = R²``; gravity. (``parts`` leaves some out, for timing one alone.)"""

    class TwistSpring(trep.Potential):
        """V = k(1 − cos(θ − a)) + c·x·sin θ."""

        def __init__(self, system, k, a, c):
            trep.Potential.__init__(self, system, name="twist")
            self.th, self.x = system.get_config("theta"), system.get_config("x")
            self.k, self.a, self.c = k, a, c

        def V(self):
            th, x = self.th.q, self.x.q
            return self.k * (1.0 - math.cos(th - self.a)) + self.c * x * math.sin(th)

        def V_dq(self, q1):
            th, x = self.th.q, self.x.q
            if q1 == self.th:
                return self.k * math.sin(th - self.a) + self.c * x * math.cos(th)
            if q1 == self.x:
                return self.c * math.sin(th)
            return 0.0

        def V_dqdq(self, q1, q2):
            th, x = self.th.q, self.x.q
            pair = set([q1.name, q2.name])
            if pair == set(["theta"]):
                return self.k * math.cos(th - self.a) - self.c * x * math.sin(th)
            if pair == set(["theta", "x"]):
                return self.c * math.cos(th)
            return 0.0

        def V_dqdqdq(self, q1, q2, q3):
            th, x = self.th.q, self.x.q
            names = sorted([q1.name, q2.name, q3.name])
            if names == ["theta"] * 3:
                return -self.k * math.sin(th - self.a) - self.c * x * math.cos(th)
            if names == ["theta", "theta", "x"]:
                return -self.c * math.sin(th)
            return 0.0

    class Drag(trep.Force):
        """F_θ = −b·θ̇·(1 + ½cos θ), F_x = −d·ẋ − e·θ̇·x."""

        def __init__(self, system, b, d, e):
            trep.Force.__init__(self, system, name="drag")
            self.th, self.x = system.get_config("theta"), system.get_config("x")
            self.b, self.d, self.e = b, d, e

        def f(self, q):
            th, x = self.th, self.x
            if q == th:
                return -self.b * th.dq * (1.0 + 0.5 * math.cos(th.q))
            if q == x:
                return -self.d * x.dq - self.e * th.dq * x.q
            return 0.0

        def f_dq(self, q, q1):
            th, x = self.th, self.x
            if q == th and q1 == th:
                return 0.5 * self.b * th.dq * math.sin(th.q)
            if q == x and q1 == x:
                return -self.e * th.dq
            return 0.0

        def f_ddq(self, q, dq1):
            th, x = self.th, self.x
            if q == th and dq1 == th:
                return -self.b * (1.0 + 0.5 * math.cos(th.q))
            if q == x and dq1 == x:
                return -self.d
            if q == x and dq1 == th:
                return -self.e * x.q
            return 0.0

        def f_dqdq(self, q, q1, q2):
            th = self.th
            if q == th and q1 == th and q2 == th:
                return 0.5 * self.b * th.dq * math.cos(th.q)
            return 0.0

        def f_ddqdq(self, q, dq1, q2):
            th, x = self.th, self.x
            if q == th and dq1 == th and q2 == th:
                return 0.5 * self.b * math.sin(th.q)
            if q == x and dq1 == th and q2 == x:
                return -self.e
            return 0.0

        def f_ddqddq(self, q, dq1, dq2):
            return 0.0

        def f_du(self, q, u1):
            return 0.0

        def f_dudq(self, q, u1, q2):
            return 0.0

        def f_duddq(self, q, u1, dq2):
            return 0.0

        def f_dudu(self, q, u1, u2):
            return 0.0

    class OnCircle(trep.Constraint):
        """h = x² + z² − R²."""

        def __init__(self, system, radius):
            trep.Constraint.__init__(self, system, name="circle")
            self.x, self.z = system.get_config("x"), system.get_config("z")
            self.r = radius

        def h(self):
            return self.x.q ** 2 + self.z.q ** 2 - self.r ** 2

        def h_dq(self, q1):
            return 2.0 * q1.q if q1 in (self.x, self.z) else 0.0

        def h_dqdq(self, q1, q2):
            return 2.0 if q1 == q2 and q1 in (self.x, self.z) else 0.0

        def h_dqdqdq(self, q1, q2, q3):
            return 0.0

        def h_dqdqdqdq(self, q1, q2, q3, q4):
            return 0.0

    s = trep.System()
    theta = trep.Frame(s.world_frame, trep.RX, "theta", name="theta")
    trep.Frame(theta, trep.TZ, -1.0, name="bob", mass=1.0)
    x = trep.Frame(s.world_frame, trep.TX, "x", name="x")
    trep.Frame(x, trep.TZ, "z", name="point", mass=0.5)
    trep.potentials.Gravity(s)
    if "potential" in parts:
        TwistSpring(s, 3.0, 0.2, 0.8)
    if "force" in parts:
        Drag(s, 0.3, 0.2, 0.1)
    if "constraint" in parts:
        OnCircle(s, 1.2)
    s.q = {"theta": 0.4, "x": 1.2 * math.sin(0.3), "z": -1.2 * math.cos(0.3)}
    return s


def _arm_beside_slider(trep):
    """A two-joint arm (a about x, b about y, its tip a body with inertia) beside a slider x,
    under gravity."""
    s = trep.System()
    s.import_frames([
        trep.rx("a", name="A"), [
            trep.tz(-1.0, name="elbow"), [
                trep.ry("b", name="B"), [
                    trep.tz(-0.5, mass=(1.0, 0.1, 0.2, 0.3), name="tip")]]],
        trep.tx("x", name="X", mass=2.0)])
    trep.potentials.Gravity(s)
    return s


def wrenches_and_curves(trep):
    """A two-joint arm (a about x, b about y) beside a slider x on a nonlinear spring: a
    spline force curve through four points (m = 1.5, b = 0.2), a constant wrench on the tip
    in its own axes, one on the elbow in world axes and one on the tip in world axes at its
    origin; gravity."""
    s = _arm_beside_slider(trep)
    curve = trep.Spline([[-1.0, -2.0], [0.0, 0.0], [0.5, 1.5], [2.0, 2.0]])
    trep.potentials.NonlinearConfigSpring(s, "x", curve, m=1.5, b=0.2)
    trep.forces.BodyWrench(s, "tip", (1.0, -0.5, 0.3, 0.2, 0.1, -0.4))
    trep.forces.SpatialWrench(s, "B", (0.3, 0.2, -0.1, 0.05, -0.2, 0.1))
    trep.forces.HybridWrench(s, "tip", (0.5, 0.0, 1.0, 0.1, 0.3, 0.0))
    s.q = [0.3, -0.4, 0.2]
    return s


def input_wrenches(trep):
    """A two-joint arm (a about x, b about y) beside a slider x, pushed by wrenches whose
    entries name inputs — on the tip in world axes at its origin, on the tip in its own axes,
    on the elbow joint's frame in world axes — between a ConfigForce on the slider and one
    after them; gravity."""
    s = _arm_beside_slider(trep)
    trep.forces.ConfigForce(s, "x", "push")
    trep.forces.HybridWrench(s, "tip", ("fx", 0.0, "fz", 0.1, 0.0, 0.0))
    trep.forces.BodyWrench(s, "tip", (0.2, "by", 0.0, 0.0, 0.0, "bt"))
    trep.forces.SpatialWrench(s, "B", (0.0, 0.0, "sz", "st", 0.0, 0.0))
    trep.forces.ConfigForce(s, "b", "elbow_torque")
    s.q = [0.3, -0.4, 0.2]
    return s


def python_force_inputs(trep):
    """``python_elements`` (a potential, a force and a constraint written in Python) pushed
    as well by a force written in Python that creates two inputs — nonlinear in them and
    depending on the state: ``F_θ = a u₁ cos θ + b u₁ u₂``, ``F_x = u₂ (1 + c x θ̇)`` — then a
    ConfigForce on z after it."""

    class Thruster(trep.Force):
        def __init__(self, system, a, b, c):
            trep.Force.__init__(self, system, name="thruster")
            self.th, self.x = system.get_config("theta"), system.get_config("x")
            self.a, self.b, self.c = a, b, c
            self.u1 = self._create_input("thrust")
            self.u2 = self._create_input("gimbal")

        def f(self, q):
            u1, u2 = self.u1.u, self.u2.u
            if q == self.th:
                return self.a * u1 * math.cos(self.th.q) + self.b * u1 * u2
            if q == self.x:
                return u2 * (1.0 + self.c * self.x.q * self.th.dq)
            return 0.0

        def f_dq(self, q, q1):
            u1, u2 = self.u1.u, self.u2.u
            if q == self.th and q1 == self.th:
                return -self.a * u1 * math.sin(self.th.q)
            if q == self.x and q1 == self.x:
                return u2 * self.c * self.th.dq
            return 0.0

        def f_ddq(self, q, dq1):
            if q == self.x and dq1 == self.th:
                return self.u2.u * self.c * self.x.q
            return 0.0

        def f_du(self, q, u):
            u1, u2 = self.u1.u, self.u2.u
            if q == self.th:
                if u == self.u1:
                    return self.a * math.cos(self.th.q) + self.b * u2
                if u == self.u2:
                    return self.b * u1
            if q == self.x and u == self.u2:
                return 1.0 + self.c * self.x.q * self.th.dq
            return 0.0

        def f_dqdq(self, q, q1, q2):
            if q == self.th and q1 == self.th and q2 == self.th:
                return -self.a * self.u1.u * math.cos(self.th.q)
            return 0.0

        def f_ddqdq(self, q, dq1, q2):
            if q == self.x and dq1 == self.th and q2 == self.x:
                return self.u2.u * self.c
            return 0.0

        def f_ddqddq(self, q, dq1, dq2):
            return 0.0

        def f_dudq(self, q, u, q1):
            if q == self.th and u == self.u1 and q1 == self.th:
                return -self.a * math.sin(self.th.q)
            if q == self.x and u == self.u2 and q1 == self.x:
                return self.c * self.th.dq
            return 0.0

        def f_duddq(self, q, u, dq1):
            if q == self.x and u == self.u2 and dq1 == self.th:
                return self.c * self.x.q
            return 0.0

        def f_dudu(self, q, u1, u2):
            if q == self.th and set([u1.name, u2.name]) == set(["thrust", "gimbal"]):
                return self.b
            return 0.0

    s = python_elements(trep)
    Thruster(s, 0.8, 0.5, 0.7)
    trep.forces.ConfigForce(s, "z", "lift")
    return s


def _posed_puppet(trep, **strings):
    """trep's marionette (`trep.puppets.Puppet`, its strings as `strings` says) in a pose."""
    import importlib
    puppets = importlib.import_module(trep.__name__ + ".puppets")
    p = puppets.Puppet(joint_forces=False, **strings)
    pose = {"torso_tz": 1.1, "torso_rz": 0.2, "lhip_rx": -0.4, "rhip_rx": 0.3,
            "lknee_rx": 0.5, "rknee_rx": 0.2, "lshoulder_rx": 0.6, "relbow_rx": 0.4}
    for name, value in pose.items():
        p.get_config(name).q = value
    return p


def puppet_string_forces(trep, steps=20, dt=0.01):
    """trep's marionette pulled by its strings as forces (``Puppet(string_forces=True)``: a
    HybridWrench per string, its three components inputs): the inputs, then ``steps`` VI
    steps with each string pulling up by its own amount, and the last step's derivatives by
    the strings' inputs — all by name (trep lists the strings in its dict's order)."""
    p = _posed_puppet(trep, string_forces=True)
    names = [i.name for i in p.inputs]
    pull = dict((n, (0.5 + 0.05 * len(n) if n.endswith("-z") else 0.1 * (-1) ** len(n)))
                for n in names)
    u = [pull[n] for n in names]
    mvi = trep.MidpointVI(p, tolerance=1e-10)  # trep's Newton stalls on the Puppet at 1e-13
    mvi.initialize_from_configs(0.0, p.q, dt, p.q)
    for _ in range(steps):
        mvi.step(mvi.t2 + dt, u)
    dyn = [c.name for c in p.dyn_configs]
    q2_du1, p2_du1 = mvi.q2_du1(), mvi.p2_du1()
    return {"inputs": sorted(names),
            "q": dict((c.name, float(mvi.q2[i])) for i, c in enumerate(p.configs)),
            "q2_du1": dict((d, dict((n, float(q2_du1[r, k])) for k, n in enumerate(names)))
                           for r, d in enumerate(dyn)),
            "p2_du1": dict((d, dict((n, float(p2_du1[r, k])) for k, n in enumerate(names)))
                           for r, d in enumerate(dyn))}


SYSTEMS = [("cart_pendulum_string", cart_pendulum_string), ("ball_on_incline", ball_on_incline),
           ("imported_tree", imported_tree), ("coupled_pendulums", coupled_pendulums),
           ("pinned_masses", pinned_masses), ("python_elements", python_elements),
           ("wrenches_and_curves", wrenches_and_curves), ("input_wrenches", input_wrenches),
           ("python_force_inputs", python_force_inputs)]

#: The systems whose frames' third derivatives are recorded too.
THIRD_ORDER = (wrenches_and_curves,)

#: Splines through points given every way trep takes them: values alone, slopes or
#: curvatures at the ends, at interior points, both, unevenly spaced.
SPLINES = {
    "two": [[0, 0], [1, 2]],
    "natural": [[-1, 2], [0, 0], [1, 1], [3, -1]],
    "clamped": [[0, 0, 1], [1, 1], [2, 0, 0]],
    "end_curvatures": [[0, 0, 1, 0], [1, 1], [2, 0, None, 2]],
    "first_slope": [[0, 0, 1], [1, 1], [2, 0]],
    "first_curvature": [[0, 0, None, 1], [1, 1], [2, 0]],
    "interior_slope": [[0, 0], [1, 1, 0], [2, 0], [3, 1]],
    "interior_curvature": [[0, 0], [1, 1, None, 1], [2, 0], [3, 1]],
    "interior_both": [[0, 0], [1, 1, 0, 1], [2, 0], [3, 1]],
    "every_derivative": [[0, 0, 1, 0], [1, 1, 0, 1], [2, 0, 1, 0]],
    "both_ends_full": [[0, 0, 1, 0], [1, 1], [2, 0], [3, 1, 1, 0]],
    "mixed": [[0, 0], [1, 1, 0, 0], [2, 0], [3, 1], [4, 0, 1, 1], [5, 1]],
    "slopes_and_a_full_end": [[0, 0, 1, 0], [1, 1, 0], [2, 0, 1], [3, 1]],
    "slope_inside_full_ends": [[0, 0, 1, 0], [1, 1, 0], [2, 0], [3, 1, 1, 0]],
    "uneven": [[-0.3, 0.2], [0.1, -0.5], [0.25, 0.4], [0.9, 1.3], [1.7, -0.2]],
}


def splines(trep):
    """Each spline's value, slope and curvature on a grid reaching beyond its points."""
    out = {}
    for name, points in sorted(SPLINES.items()):
        curve = trep.Spline(points)
        lo, hi = points[0][0], points[-1][0]
        xs = [lo - 0.7 + (hi - lo + 1.4) * i / 40.0 for i in range(41)]
        out[name] = {"x": xs, "y": [curve.y(x) for x in xs], "dy": [curve.dy(x) for x in xs],
                     "ddy": [curve.ddy(x) for x in xs],
                     "coefficients": _list(curve.coefficients)}
    return out


def tape_measure(trep):
    """A tape from the arm's pivot through its tip to the slider, at a moving state: its
    length, rate and every derivative trep gives."""
    s = wrenches_and_curves(trep)
    s.dq = [0.5, -0.2, 0.1]
    tape = trep.TapeMeasure(s, ["A", "tip", "X"])
    cs = s.configs
    return {"length": tape.length(), "velocity": tape.velocity(),
            "length_dq": [tape.length_dq(a) for a in cs],
            "length_dqdq": [[tape.length_dqdq(a, b) for b in cs] for a in cs],
            "length_dqdqdq": [[[tape.length_dqdqdq(a, b, c) for c in cs] for b in cs]
                              for a in cs],
            "velocity_dq": [tape.velocity_dq(a) for a in cs],
            "velocity_ddq": [tape.velocity_ddq(a) for a in cs],
            "velocity_dqdq": [[tape.velocity_dqdq(a, b) for b in cs] for a in cs],
            "velocity_ddqdq": [[tape.velocity_ddqdq(a, b) for b in cs] for a in cs]}


def _list(x):
    return np.asarray(x, dtype=float).tolist()


def frame_derivatives(f, cs, third_order):
    """A frame's pose, body velocity and their derivatives by the configs ``cs`` (the third
    order only where asked: those tensors are the fixture's bulk)."""
    out = {"g_dq": [_list(f.g_dq(a)) for a in cs],
           "g_dqdq": [[_list(f.g_dqdq(a, b)) for b in cs] for a in cs],
           "p_dq": [_list(f.p_dq(a)) for a in cs],
           "p_dqdq": [[_list(f.p_dqdq(a, b)) for b in cs] for a in cs],
           "vb_dq": [_list(f.vb_dq(a)) for a in cs],
           "vb_ddq": [_list(f.vb_ddq(a)) for a in cs],
           "g_inv": _list(f.g_inv()), "g_inv_dq": [_list(f.g_inv_dq(a)) for a in cs],
           "lg": _list(f.lg()), "lg_dq": _list(f.lg_dq()),
           "twist_hat": _list(f.twist_hat()),
           "g_inv_dqdq": [[_list(f.g_inv_dqdq(a, b)) for b in cs] for a in cs],
           "vb_dqdq": [[_list(f.vb_dqdq(a, b)) for b in cs] for a in cs],
           "vb_ddqdq": [[_list(f.vb_ddqdq(a, b)) for b in cs] for a in cs],
           "lg_dqdq": _list(f.lg_dqdq()), "lg_inv": _list(f.lg_inv()),
           "lg_inv_dq": _list(f.lg_inv_dq()), "lg_inv_dqdq": _list(f.lg_inv_dqdq())}
    if third_order:
        out["p_dqdqdq"] = [[[_list(f.p_dqdqdq(a, b, c)) for c in cs] for b in cs] for a in cs]
        out["vb_ddqdqdq"] = [[[_list(f.vb_ddqdqdq(a, b, c)) for c in cs] for b in cs]
                             for a in cs]
    return out


def record(trep, build):
    """Everything the layer covers, at one state and over a VI run: the Lagrangian and its
    derivatives, the dynamics and theirs, frames, constraints, MidpointVI steps and the last
    step's derivatives, and the configurations satisfy_constraints finds."""
    s = build(trep)
    out = {"configs": [c.name for c in s.configs],
           "dyn": [c.name for c in s.dyn_configs], "kin": [c.name for c in s.kin_configs]}
    n = s.nQ
    s.dq = [0.3 * (-1) ** i + 0.1 * i for i in range(n)]
    if s.nQk:
        s.ddqk = [0.7 + 0.1 * i for i in range(s.nQk)]
    if s.nu:
        s.u = [0.4 + 0.2 * i for i in range(s.nu)]
    out["q"], out["dq"] = _list(s.q), _list(s.dq)
    out["L"], out["E"] = s.L(), s.total_energy()
    out["V_parts"] = [p.V() for p in s.potentials]
    cs = s.configs
    out["L_dq"] = [s.L_dq(a) for a in cs]
    out["L_ddq"] = [s.L_ddq(a) for a in cs]
    out["L_dqdq"] = [[s.L_dqdq(a, b) for b in cs] for a in cs]
    out["L_ddqdq"] = [[s.L_ddqdq(a, b) for b in cs] for a in cs]
    out["L_ddqddq"] = [[s.L_ddqddq(a, b) for b in cs] for a in cs]
    out["f"] = _list(s.f())
    out["ddq_after_f"] = _list(s.ddq)  # f() leaves the accelerations in ddq
    out["f_dq"], out["f_ddq"] = _list(s.f_dq()), _list(s.f_ddq())
    if s.nu:
        out["f_du"] = _list(s.f_du())
        out["lambda_du"] = _list(s.lambda_du())
    if s.nQk:
        out["f_dddk"] = _list(s.f_dddk())
        out["lambda_dddk"] = _list(s.lambda_dddk())
    out["lambda"] = _list(s.lambda_())
    out["lambda_dq"], out["lambda_ddq"] = _list(s.lambda_dq()), _list(s.lambda_ddq())
    out["tree"] = s.world_frame.tree_view()
    out["frames"] = dict((f.name, {"g": _list(f.g()), "p": _list(f.p()), "vb": _list(f.vb())})
                         for f in s.frames if f.name is not None)
    out["frame_derivatives"] = dict((f.name, frame_derivatives(f, cs, build in THIRD_ORDER))
                                    for f in s.frames
                                    if f.name is not None and f.name != "World")
    out["h"] = [c.h() for c in s.constraints]
    out["h_dq"] = [[c.h_dq(a) for a in cs] for c in s.constraints]
    # The midpoint VI from rest at this configuration, 20 steps of dt = 0.01 with the
    # kinematic configs moving and a constant input.
    dt = 0.01
    mvi = trep.MidpointVI(s, tolerance=1e-13)  # both solvers to rounding
    q0 = s.q
    mvi.initialize_from_configs(0.0, q0, dt, q0)
    # The System as the integrator leaves it: scripts read system.q or the energy in loops.
    out["vi_start_system"] = {"q": _list(s.q), "dq": _list(s.dq), "t": s.t, "u": _list(s.u)}
    steps = []
    u1 = [0.4 + 0.2 * i for i in range(s.nu)]
    for k in range(20):
        t2 = mvi.t2 + dt
        k2 = [q0[s.nQd + j] + 0.05 * math.sin(3.0 * t2) for j in range(s.nQk)]
        mvi.step(t2, u1, k2)
        steps.append({"t2": mvi.t2, "q2": _list(mvi.q2), "p2": _list(mvi.p2),
                      "lambda1": _list(mvi.lambda1),
                      "system": {"q": _list(s.q), "dq": _list(s.dq), "t": s.t, "u": _list(s.u),
                                 "E": s.total_energy(),
                                 "V_parts": [p.V() for p in s.potentials]}})
    out["vi"] = steps
    d = {}
    inputs = ["q1", "p1", "u1", "k2"]
    for of in ["q2", "p2", "lambda1"]:
        for k, a in enumerate(inputs):
            d["%s_d%s" % (of, a)] = _list(getattr(mvi, "%s_d%s" % (of, a))())
            for b in inputs[k:]:
                name = "%s_d%sd%s" % (of, a, b)
                try:
                    d[name] = _list(getattr(mvi, name)())
                except NotImplementedError:
                    pass  # trep 1.0.2's LinearSpring has no third derivative: nothing to hold
    out["vi_derivatives"] = d
    # The DEL residual at a q2 moved off the step (trep's calc_f: what inverse dynamics
    # reads), and the end momentum there (calc_p2).
    kept = mvi.q2
    mvi.q2 = [x + 0.01 * (i + 1) for i, x in enumerate(kept)]
    out["calc_f"] = _list(mvi.calc_f())
    mvi.calc_p2()
    out["calc_p2"] = _list(mvi.p2)
    # satisfy_constraints from a configuration moved off the constraints and a moving state,
    # each way trep's documentation gives of holding configs still (both at once differ:
    # trep 1.0.2 then holds only the list).
    satisfied = {}
    for label, options in [("all", {}), ("keep_kinematic", {"keep_kinematic": True}),
                           ("constant", {"constant_q_list": [cs[0].name]})]:
        start = [x + 0.05 * (i + 1) / n for i, x in enumerate(q0)]
        s.q = start
        s.dq = 0.3
        q = s.satisfy_constraints(tolerance=1e-12, **options)
        satisfied[label] = {"q": _list(q), "dq": _list(s.dq), "h": [c.h() for c in s.constraints],
                            "start": _list(start)}
    out["satisfy_constraints"] = satisfied
    # minimize_potential_energy from the same moved configuration: the equilibrium found, its
    # potential, or that none was (a ball on an endless incline has none).
    minimized = {}
    for label, options in [("all", {}), ("keep_kinematic", {"keep_kinematic": True})]:
        s.q = [x + 0.05 * (i + 1) / n for i, x in enumerate(q0)]
        s.dq = 0.3
        try:
            q = s.minimize_potential_energy(**options)
        except Exception:  # trep raises a StandardError, tree_mech.trep a RuntimeError
            minimized[label] = {"failed": True}
            continue
        minimized[label] = {"failed": False, "q": _list(q), "V": -s.L(), "dq": _list(s.dq),
                            "h": [c.h() for c in s.constraints]}
    out["minimize_potential_energy"] = minimized
    return out


def _plain(x):
    """JSON's strings as `str` (Python 2.7 reads them as `unicode`, which trep refuses)."""
    if isinstance(x, dict):
        return dict((_plain(k), _plain(v)) for k, v in x.items())
    if isinstance(x, list):
        return [_plain(v) for v in x]
    if isinstance(x, (bool, int, float)) or x is None:
        return x
    return str(x)


def puppet_from_frames(trep, spec):
    """A marionette built through the trep API from `spec` (tools/reference/trep-puppet.json:
    the frames, masses, damping and strings of trep's own Puppet), ready to step."""
    spec = _plain(spec)
    kinds = {"tx": trep.TX, "ty": trep.TY, "tz": trep.TZ,
             "rx": trep.RX, "ry": trep.RY, "rz": trep.RZ}
    s = trep.System()
    s.hold_structure_changes()
    frames = {}
    for f in spec["frames"]:
        parent = frames[f["parent"]] if f["parent"] else s.world_frame
        frames[f["name"]] = trep.Frame(parent, kinds[f["kind"]], f["value"], name=f["name"],
                                       kinematic=f.get("kinematic", False))
        if f.get("mass"):
            frames[f["name"]].set_mass(f["mass"], *f["inertia"])
    s.resume_structure_changes()
    trep.potentials.Gravity(s, spec["gravity"])
    trep.forces.Damping(s, 0.0, spec["damping"])
    for c in spec["strings"]:
        trep.constraints.Distance(s, c["frames"][0], c["frames"][1], c["length"], name=c["name"])
    q = dict((c.name, spec["q0"].get(c.name, 0.0)) for c in s.configs)
    s.q = q
    return s


def step_puppet(trep, s, steps, dt):
    """`steps` midpoint-VI steps of the puppet from rest, the strings' kinematic configs held;
    returns the final configuration."""
    mvi = trep.MidpointVI(s)
    mvi.initialize_from_configs(0.0, s.q, dt, s.q)
    k2 = s.qk
    for _ in range(steps):
        mvi.step(mvi.t2 + dt, [], k2)
    return mvi.q2


def time_puppet(trep, spec, runs=3, steps=1000, dt=0.01):
    """The best of `runs` wall times (s) of `steps` VI steps of the Puppet built from `spec`
    (building it is not timed)."""
    import time
    best = float("inf")
    for _ in range(runs):
        s = puppet_from_frames(trep, spec)
        start = time.time()
        step_puppet(trep, s, steps, dt)
        best = min(best, time.time() - start)
    return best


def puppet_module(trep, steps=30, dt=0.01):
    """trep's own marionette from `trep.puppets` (strings as constraints): its configs, its
    frames' positions in a pose, the control points projected above their hooks, then
    `steps` VI steps with the string controls held — all by name (trep lists the strings in
    its dict's order)."""
    p = _posed_puppet(trep, string_constraints=True)
    p.project_string_controls()
    out = {"configs": sorted(c.name for c in p.configs),
           "dyn": sorted(c.name for c in p.dyn_configs),
           "frames": dict((f.name, _list(f.p())) for f in p.frames if f.name is not None),
           "q0": dict((c.name, c.q) for c in p.configs)}
    mvi = trep.MidpointVI(p)
    mvi.initialize_from_configs(0.0, p.q, dt, p.q)
    k2 = [c.q for c in p.kin_configs]
    for _ in range(steps):
        mvi.step(mvi.t2 + dt, (), k2)
    out["q"] = dict((c.name, float(mvi.q2[i])) for i, c in enumerate(p.configs))
    out["lambda1"] = dict((c.name, float(mvi.lambda1[i])) for i, c in enumerate(p.constraints))
    return out


def time_python_elements(trep, runs=3, steps=1000, dt=0.01,
                         parts=("potential", "force", "constraint")):
    """The best of `runs` wall times (s) of `steps` VI steps of `python_elements` (its
    potential, force and constraint written in Python, called back on every evaluation;
    `parts` for some of them alone)."""
    import time
    best = float("inf")
    for _ in range(runs):
        s = python_elements(trep, parts)
        mvi = trep.MidpointVI(s)
        mvi.initialize_from_configs(0.0, s.q, dt, s.q)
        start = time.time()
        for _ in range(steps):
            mvi.step(mvi.t2 + dt)
        best = min(best, time.time() - start)
    return best


def energy_pump(trep, steps=400, dt=0.01):
    """A closed loop as trep scripts write them: a damped-free pendulum with a torque input,
    pumped towards the upright energy by ``u = k (E* − E) dq`` where ``E`` and ``dq`` are
    read from the System inside the loop (the state the integrator leaves there). Returns
    the angle after each step."""
    s = trep.System()
    s.import_frames([trep.rx("theta", name="pivot"), [trep.tz(-1.0, mass=1.0, name="bob")]])
    trep.potentials.Gravity(s, (0.0, 0.0, -9.8))
    trep.forces.ConfigForce(s, "theta", "torque")
    s.q = [0.1]
    mvi = trep.MidpointVI(s)
    mvi.initialize_from_configs(0.0, s.q, dt, s.q)
    target, gain = 9.8, 0.4
    angles = []
    for _ in range(steps):
        u = gain * (target - s.total_energy()) * s.dq[0]
        mvi.step(mvi.t2 + dt, [u])
        angles.append(float(mvi.q2[0]))
    return angles
