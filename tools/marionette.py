#!/usr/bin/env python3
"""Writes models/marionette.toml: a wooden marionette of 42 variables, and
models/marionette-floor.toml: the same puppet over a floor, its strings slack.

The model is generated rather than typed because its string lengths and the raised right
leg's starting angles follow from the geometry; run `python3 tools/marionette.py` after
changing a dimension. Units: m, kg, s; z up, the puppet faces +y, its left is +x.

* a free torso (tx ty tz rz ry rx), a head on a two-axis neck held upright by springs,
  3-axis shoulders and hips, elbows and knees (one axis each);
* six strings (distance constraints) from hooks at the shoulders, hands and knees to
  control points, each with kinematic x, y and length: 18 prescribed variables, moved as a
  puppeteer marching the puppet on the spot (knees lifted in turn, arms swinging, the body
  rocking and bobbing);
* viscous damping on every joint and a damper between the hands.

The floor model (docs/model-format.md, "Contact") keeps the bodies, joints and hooks, and
changes what the strings do: each is slack (it pulls, never pushes), its control point held
still above its hook, and its length held for a second, then paid out by LOWER over LOWER_TIME
(a smoothstep, sampled): the puppet hangs with its feet just above a floor (μ = 0.8), then
settles onto it — feet, knees, hands and torso are contact spheres — and collapses as the
strings go slack.
"""
import math
import pathlib

TORSO_Z = 0.50          # torso centre above the floor
BAR_Z = 1.20            # height of the control points
SHOULDER = (0.10, 0.11)  # shoulder hook: x offset, z offset from the torso centre
HIP = (0.05, -0.125)
UPPER_ARM, FOREARM = 0.12, 0.11
THIGH, SHIN = 0.16, 0.15
# The starting pose: arms held forward (shoulder pitch, elbow flexed), thighs lifted (hip
# pitch) with the shins hanging, every string vertical above its hook. A limb hanging straight
# below a vertical string would pull along the shoulder strings' line (Dh loses rank), and a
# string is taut only when it holds a limb up.
ARM_PITCH, ELBOW = 0.5, 0.7
HIP_PITCH = 0.8
HAND_STROKE, KNEE_STROKE = 0.05, 0.03   # amplitudes of the strings' lengths
# The floor model: the floor a little below the feet, the strings paid out from t = 1 s.
FOOT_CLEARANCE = 0.002
LOWER, LOWER_START, LOWER_TIME = 0.5, 1.0, 1.5
FLOOR_SPHERES = (("foot", 0.015), ("knee", 0.02), ("hand", 0.02))

frames = []
variables = {}


def frame(name, parent, prim, value, mass=None, inertia=None):
    frames.append((name, parent, prim, value, mass, inertia))


def rod(m, length, r):
    """Inertia of a solid cylinder along z about its centre: (Ixx, Iyy, Izz)."""
    a = m * (3 * r * r + length * length) / 12
    return [a, a, m * r * r / 2]


def box(m, x, y, z):
    return [m * (y * y + z * z) / 12, m * (x * x + z * z) / 12, m * (x * x + y * y) / 12]


def dynamic(name, damping, q0=0.0):
    variables[name] = {"q0": q0, "damping": damping}


def kinematic(name, q0, motion):
    variables[name] = {"q0": q0, "kinematic": True, "motion": motion}


def sine(offset, amplitude, frequency, phase=0.0):
    return {"offset": offset, "amplitude": amplitude, "frequency": frequency, "phase": phase}


# Torso: free-floating.
for axis, prim, c in (("x", "tx", 0.05), ("y", "ty", 0.05), ("z", "tz", 0.05)):
    frame(f"torso_{axis}", None if axis == "x" else prev, prim, f"torso_{axis}")
    prev = f"torso_{axis}"
    dynamic(f"torso_{axis}", c, TORSO_Z if axis == "z" else 0.0)
frame("torso_yaw_frame", "torso_z", "rz", "torso_yaw")
frame("torso_pitch_frame", "torso_yaw_frame", "ry", "torso_pitch")
frame("torso", "torso_pitch_frame", "rx", "torso_roll", 0.20, box(0.20, 0.16, 0.08, 0.25))
for v in ("torso_yaw", "torso_pitch", "torso_roll"):
    dynamic(v, 0.005)

# Head on a neck: pitch then yaw; springs keep it upright (it sits above its pivot).
frame("neck", "torso", "tz", 0.125)
frame("neck_pitch_frame", "neck", "rx", "neck_pitch")
frame("neck_yaw_frame", "neck_pitch_frame", "rz", "neck_yaw")
frame("head", "neck_yaw_frame", "tz", 0.06, 0.06, [6e-5, 6e-5, 6e-5])
dynamic("neck_pitch", 0.0005)
dynamic("neck_yaw", 0.0005)

# Arms and legs; side +1 is the left.
right_hip_pitch = None
for side, s in (("left", 1.0), ("right", -1.0)):
    # Arm: shoulder hook, 3-axis shoulder, upper arm, elbow, forearm, hand hook.
    frame(f"{side}_shoulder_x", "torso", "tx", s * SHOULDER[0])
    frame(f"{side}_shoulder", f"{side}_shoulder_x", "tz", SHOULDER[1])
    frame(f"{side}_shoulder_yaw_frame", f"{side}_shoulder", "rz", f"{side}_shoulder_yaw")
    frame(f"{side}_shoulder_roll_frame", f"{side}_shoulder_yaw_frame", "ry", f"{side}_shoulder_roll")
    frame(f"{side}_shoulder_pitch_frame", f"{side}_shoulder_roll_frame", "rx", f"{side}_shoulder_pitch")
    frame(f"{side}_upper_arm", f"{side}_shoulder_pitch_frame", "tz", -UPPER_ARM / 2,
          0.02, rod(0.02, UPPER_ARM, 0.015))
    frame(f"{side}_elbow_z", f"{side}_upper_arm", "tz", -UPPER_ARM / 2)
    frame(f"{side}_elbow", f"{side}_elbow_z", "rx", f"{side}_elbow")
    frame(f"{side}_forearm", f"{side}_elbow", "tz", -FOREARM / 2, 0.015, rod(0.015, FOREARM, 0.013))
    frame(f"{side}_hand", f"{side}_forearm", "tz", -FOREARM / 2, 0.008, [1e-6, 1e-6, 1e-6])
    for v in ("shoulder_yaw", "shoulder_roll", "shoulder_pitch"):
        dynamic(f"{side}_{v}", 0.001)
    dynamic(f"{side}_elbow", 0.0005)

    # Leg: 3-axis hip, thigh, knee hook, shin, ankle, foot.
    frame(f"{side}_hip_x", "torso", "tx", s * HIP[0])
    frame(f"{side}_hip", f"{side}_hip_x", "tz", HIP[1])
    frame(f"{side}_hip_yaw_frame", f"{side}_hip", "rz", f"{side}_hip_yaw")
    frame(f"{side}_hip_roll_frame", f"{side}_hip_yaw_frame", "ry", f"{side}_hip_roll")
    frame(f"{side}_hip_pitch_frame", f"{side}_hip_roll_frame", "rx", f"{side}_hip_pitch")
    frame(f"{side}_thigh", f"{side}_hip_pitch_frame", "tz", -THIGH / 2, 0.04, rod(0.04, THIGH, 0.02))
    frame(f"{side}_knee_z", f"{side}_thigh", "tz", -THIGH / 2)
    frame(f"{side}_knee", f"{side}_knee_z", "rx", f"{side}_knee")
    frame(f"{side}_shin", f"{side}_knee", "tz", -SHIN / 2, 0.03, rod(0.03, SHIN, 0.018))
    frame(f"{side}_ankle", f"{side}_shin", "tz", -SHIN / 2)
    frame(f"{side}_foot", f"{side}_ankle", "ty", 0.03, 0.015, [2e-6, 2e-6, 2e-6])
    for v in ("hip_yaw", "hip_roll"):
        dynamic(f"{side}_{v}", 0.002)
    dynamic(f"{side}_hip_pitch", 0.002)
    dynamic(f"{side}_knee", 0.001)

# The starting pose.
for side in ("left", "right"):
    variables[f"{side}_shoulder_pitch"]["q0"] = ARM_PITCH
    variables[f"{side}_elbow"]["q0"] = ELBOW
    variables[f"{side}_hip_pitch"]["q0"] = HIP_PITCH
    variables[f"{side}_knee"]["q0"] = -HIP_PITCH

# Strings: hook, the control point above it at the start, and how the puppeteer moves the
# control's x, y and the string's length: the bar rocks sideways at 0.25 Hz and bobs at 1 Hz;
# the hands and knees are lifted in turn at 0.5 Hz (left knee with right hand).
shoulder_z = TORSO_Z + SHOULDER[1]
hand_y = UPPER_ARM * math.sin(ARM_PITCH) + FOREARM * math.sin(ARM_PITCH + ELBOW)
hand_z = shoulder_z - UPPER_ARM * math.cos(ARM_PITCH) - FOREARM * math.cos(ARM_PITCH + ELBOW)
hip_z = TORSO_Z + HIP[1]
knee_y = THIGH * math.sin(HIP_PITCH)
knee_z = hip_z - THIGH * math.cos(HIP_PITCH)
strings = []
for side, s in (("left", 1.0), ("right", -1.0)):
    first = 0.0 if s > 0 else math.pi
    rest = BAR_Z - shoulder_z
    strings.append((f"{side}_shoulder", sine(s * SHOULDER[0], 0.02, 0.25), sine(0.0, 0.0, 0.0),
                    sine(rest, 0.01, 1.0)))
    rest = BAR_Z - hand_z
    strings.append((f"{side}_hand", sine(s * SHOULDER[0], 0.0, 0.0), sine(hand_y, 0.0, 0.0),
                    sine(rest, HAND_STROKE, 0.5, math.pi - first)))
    rest = BAR_Z - knee_z
    strings.append((f"{side}_knee", sine(s * HIP[0], 0.0, 0.0), sine(knee_y, 0.0, 0.0),
                    sine(rest, KNEE_STROKE, 0.5, first)))


def fmt(x):
    if isinstance(x, bool):
        return "true" if x else "false"
    if isinstance(x, float):
        return repr(round(x, 15))
    if isinstance(x, dict):
        return "{ " + ", ".join(f"{k} = {fmt(v)}" for k, v in x.items()) + " }"
    if isinstance(x, list):
        return "[" + ", ".join(fmt(v) for v in x) + "]"
    if isinstance(x, str):
        return f'"{x}"'
    return str(x)


for name, mx, my, length in strings:
    frame(f"{name}_control_x", None, "tx", f"{name}_x")
    frame(f"{name}_control_y", f"{name}_control_x", "ty", f"{name}_y")
    frame(f"{name}_control", f"{name}_control_y", "tz", BAR_Z)
    kinematic(f"{name}_x", mx["offset"], mx)
    kinematic(f"{name}_y", my["offset"], my)
    kinematic(f"{name}_len", length["offset"], length)

def frame_tables():
    """The frames as TOML tables."""
    lines = []
    for name, parent, prim, value, mass, inertia in frames:
        lines += ["[[frame]]", f'name = "{name}"']
        if parent:
            lines.append(f'parent = "{parent}"')
        lines.append(f"{prim} = {fmt(value)}")
        if mass is not None:
            lines.append(f"mass = {fmt(mass)}")
            lines.append(f"inertia = {fmt([float(x) for x in inertia])}")
        lines.append("")
    return lines


out = [
    "# A wooden marionette: 24 dynamic and 18 kinematic variables, six strings.",
    "# Generated by tools/marionette.py — edit that and run it, not this file.",
    'name = "marionette"',
    "",
]
out += frame_tables()
for name, settings in variables.items():
    out.append(f"[variables.{name}]")
    for k, v in settings.items():
        if k == "damping" and v == 0.0:
            continue
        if k == "motion" and v["amplitude"] == 0.0:
            continue
        out.append(f"{k} = {fmt(v)}")
    out.append("")
for name, *_ in strings:
    out += ["[[constraint]]", f'name = "{name.replace("_", "-")}-string"', 'kind = "distance"',
            f'frames = ["{name}", "{name}_control"]', f'length = "{name}_len"', ""]
for v, k in (("neck_pitch", 0.2), ("neck_yaw", 0.05), ("left_knee", 0.005), ("right_knee", 0.005)):
    out += ["[[spring]]", f'variable = "{v}"', f"stiffness = {k}", "rest = 0.0", ""]
out += ["[[damper]]", 'frames = ["left_hand", "right_hand"]', "damping = 0.01", ""]

models = pathlib.Path(__file__).resolve().parent.parent / "models"
path = models / "marionette.toml"
path.write_text("\n".join(out))
print(f"wrote {path}: {len(frames)} frames, {len(variables)} variables")


def lowered(rest):
    """A string's length held at `rest`, then paid out by LOWER (smoothstep), as samples."""
    samples = []
    for k in range(0, 41):
        t = 0.1 * k
        x = min(max((t - LOWER_START) / LOWER_TIME, 0.0), 1.0)
        samples.append([round(t, 10), rest + LOWER * x * x * (3 - 2 * x)])
    return samples


# The floor model: the same bodies; strings slack, controls still, lengths lowered.
foot_z = knee_z - SHIN  # the shins hang straight below the knees at the start
floor = foot_z - 0.015 - FOOT_CLEARANCE
out = [
    "# The marionette over a floor: its strings slack and paid out from t = 1 s, so it settles",
    "# onto the floor on its feet and collapses; feet, knees, hands and torso touch the floor.",
    "# Generated by tools/marionette.py — edit that and run it, not this file.",
    'name = "marionette-floor"',
    "enforce_limits = false",
    "",
]
out += frame_tables()
lengths = {f"{name}_len": length["offset"] for name, _, _, length in strings}
for name, settings in variables.items():
    out.append(f"[variables.{name}]")
    if name in lengths:
        out += [f"q0 = {fmt(lengths[name])}", "kinematic = true",
                f"samples = {fmt(lowered(lengths[name]))}", ""]
        continue
    for k, v in settings.items():
        if k == "damping" and v == 0.0:
            continue
        if k == "motion":
            continue
        out.append(f"{k} = {fmt(v)}")
    out.append("")
for name, *_ in strings:
    out += ["[[constraint]]", f'name = "{name.replace("_", "-")}-string"', 'kind = "distance"',
            f'frames = ["{name}", "{name}_control"]', f'length = "{name}_len"', "slack = true", ""]
for v, k in (("neck_pitch", 0.2), ("neck_yaw", 0.05), ("left_knee", 0.005), ("right_knee", 0.005)):
    out += ["[[spring]]", f'variable = "{v}"', f"stiffness = {k}", "rest = 0.0", ""]
out += ["[[damper]]", 'frames = ["left_hand", "right_hand"]', "damping = 0.01", ""]
out += ["[ground]", f"height = {fmt(floor)}", "friction = 0.8", ""]
for side in ("left", "right"):
    for part, radius in FLOOR_SPHERES:
        out += ["[[contact]]", f'frame = "{side}_{part}"', f"radius = {radius}",
                f'name = "{side}_{part}"', "collide = false", ""]
out += ["[[contact]]", 'frame = "torso"', "radius = 0.05", 'name = "torso"', "collide = false", ""]
path = models / "marionette-floor.toml"
path.write_text("\n".join(out))
print(f"wrote {path}: the floor at z = {floor:.4f} m")
