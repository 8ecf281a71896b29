"""trep's ``trep.puppets``: the marionette of the paper, built from its dimensions and joints
(``Puppet``, ``make_skeleton``, ``fill_dimensions``, ``fill_joints`` and the defaults) —
a free torso with a neck and head, two arms (3-axis shoulders, elbows, hands) and two legs
(3-axis hips, knees, feet), gravity and joint damping; strings as distance constraints to
control points in a plane above it (``string_constraints=True``), or joint forces
(``joint_forces=True``), or forces pulling on the hooks (``string_forces=True``: a
``HybridWrench`` per string whose three force entries are inputs ``NAME-x``, ``NAME-y``,
``NAME-z``). Written from trep's documented interface: the dimension and joint names and
their default values (Pygmalion's motion-capture figure) are trep's, so a script gets trep's
Puppet.
"""
from __future__ import annotations

from typing import Any, Dict, List, Optional

from . import constraints, forces, potentials
from ._core import System, const_txyz, rx, ry, rz, tx, ty, tz
from .visual import VisualItem3D

#: The figure's dimensions (m), masses ``[m, Ixx, Iyy, Izz]``, joint damping, the height of
#: the string plane and where each string is hooked (frame, offset): trep's defaults.
DEFAULT_DIMENSIONS: Dict[str, Any] = {
    "ltibia_length": 0.4000000081268073, "rtibia_length": 0.40000001048670952,
    "lfemur_length": 0.4000000143639284, "rfemur_length": 0.4000000149386187,
    "lhumerus_length": 0.24999999610023391, "rhumerus_length": 0.2500000129383001,
    "lradius_length": 0.25765900905806788, "rradius_length": 0.25765900577819512,
    "lhand_length": 0.090000006491074078, "rhand_length": 0.089999998759819969,
    "lfoot_length": 0.20298699715253277, "rfoot_length": 0.20000000361419676,
    "lshoulder_width": 0.15811387592769632, "rshoulder_width": 0.15811388178161004,
    "lhip_width": 0.10000000633343277, "rhip_width": 0.10000000072551045,
    "upper_torso_length": 0.49134332092915983, "neck_length": 0.04500002226970809,
    "lower_head_length": 0.044999991144167348, "upper_head_length": 0.090000011865579349,
    "final_head_length": 0.079999981957211988,
    "pelvis_mass": [10, 1, 1, 1], "head_mass": [0.75, 0.08, 0.08, 0.08],
    "femur_mass": [1.5, 0.3, 0.3, 0.1], "tibia_mass": [1.5, 0.3, 0.3, 0.1],
    "humerus_mass": [0.5, 0.05, 0.05, 0.01], "radius_mass": [0.5, 0.05, 0.05, 0.01],
    "damping": 0.2,
    "string_plane_height": 2,
    "strings": {
        "upper_torso_string": ("spine_top", (-0.1, 0, 0)),
        "lower_torso_string": ("spine_top", (0.1, 0, 0)),
        "left_arm_string": ("lradius_end", (0, 0.1, 0)),
        "right_arm_string": ("rradius_end", (0, 0.1, 0)),
        "left_leg_string": ("lfemur_end", (0, 0.1, 0)),
        "right_leg_string": ("rfemur_end", (0, 0.1, 0)),
    },
}

_MOVING = ["torso_tx", "torso_ty", "torso_tz", "torso_rz", "torso_ry", "torso_rx"] + [
    f"{side}{joint}_{axis}" for side in "lr" for joint in ("hip", "shoulder")
    for axis in ("rz", "ry", "rx")] + ["lknee_rx", "rknee_rx", "lelbow_rx", "relbow_rx"]
_HELD = [f"{part}_{axis}" for part in ("lfoot", "rfoot", "neck", "lhand", "rhand")
         for axis in ("rx", "ry", "rz")]

#: Each joint parameter: a config's name (it moves) or a number (held there): trep's defaults.
DEFAULT_JOINTS: Dict[str, Any] = {**{j: j for j in _MOVING}, **{j: 0.0 for j in _HELD}}


def fill_dimensions(dimensions: Optional[Dict[str, Any]] = None) -> Dict[str, Any]:
    """``dimensions`` with every one it does not give at its default."""
    return {**DEFAULT_DIMENSIONS, **(dimensions or {})}


def fill_joints(joints: Optional[Dict[str, Any]] = None) -> Dict[str, Any]:
    """``joints`` with every one it does not give at its default."""
    return {**DEFAULT_JOINTS, **(joints or {})}


def _ball(prefix: str, joints: Dict[str, Any], name: str, rest: list) -> list:
    """A three-axis joint (``rz``, ``ry``, then ``rx`` named ``name``) carrying ``rest``."""
    return [rz(joints[f"{prefix}_rz"]), [ry(joints[f"{prefix}_ry"]), [
        rx(joints[f"{prefix}_rx"], name=name), rest]]]


def _limb(dim: Dict[str, Any], joints: Dict[str, Any], side: str, upper: str, hinge: str,
          lower: str, mass: tuple, end: Any) -> list:
    """An upper bone from a ball joint's ``rx`` frame, a hinge, the lower bone, then what
    ``end`` makes of the lower bone's end: each bone its mass at mid-length."""
    up, low = dim[f"{side}{upper}_length"], dim[f"{side}{lower}_length"]
    return [
        tz(-up / 2, name=f"{side}{upper}_mass", mass=dim[mass[0]]),
        tz(-up, name=f"{side}{upper}_end"), [
            rx(joints[f"{side}{hinge}_rx"], name=f"{side}{lower}"), [
                tz(-low / 2, name=f"{side}{lower}_mass", mass=dim[mass[1]]),
                tz(-low, name=f"{side}{lower}_end"), end]]]


def make_skeleton(dimensions: Optional[Dict[str, Any]] = None,
                  joints: Optional[Dict[str, Any]] = None) -> list:
    """The figure's frames as trep's nested ``import_frames`` list."""
    dim, j = fill_dimensions(dimensions), fill_joints(joints)
    legs, arms = [], []
    for side, sign in (("l", -1.0), ("r", 1.0)):
        foot = _ball(f"{side}foot", j, f"{side}foot",
                     [ty(dim[f"{side}foot_length"], name=f"{side}foot_end")])
        legs += [tx(sign * dim[f"{side}hip_width"], name=f"{side}hip"),
                 _ball(f"{side}hip", j, f"{side}femur",
                       _limb(dim, j, side, "femur", "knee", "tibia",
                             ("femur_mass", "tibia_mass"), foot))]
        hand = _ball(f"{side}hand", j, f"{side}hand",
                     [tz(-dim[f"{side}hand_length"], name=f"{side}hand_end")])
        arms += [tx(sign * dim[f"{side}shoulder_width"], name=f"{side}shoulder"),
                 _ball(f"{side}shoulder", j, f"{side}humerus",
                       _limb(dim, j, side, "humerus", "elbow", "radius",
                             ("humerus_mass", "radius_mass"), hand))]
    # trep's neck turns its last axis by the `neck_rz` parameter (kept, as trep builds it).
    head = [rz(j["neck_rz"]), [ry(j["neck_ry"]), [rx(j["neck_rz"], name="neck_joint"), [
        tz(dim["lower_head_length"], name="head"), [
            tz(dim["upper_head_length"], name="head_center", mass=dim["head_mass"]), [
                tz(dim["final_head_length"], name="head_end")]]]]]]
    spine = [tz(dim["upper_torso_length"], name="spine_top"), [
        tz(dim["neck_length"], name="neck"), head] + arms]
    torso = rx(j["torso_rx"], name="pelvis", mass=dim["pelvis_mass"])
    return [tx(j["torso_tx"]), [ty(j["torso_ty"]), [tz(j["torso_tz"]), [
        rz(j["torso_rz"]), [ry(j["torso_ry"]), [torso, legs + spine]]]]]]


class Puppet(System):
    """trep's marionette: the skeleton of ``make_skeleton``, a string plane with a hook frame
    per string, gravity (−9.8 along z) and damping on every dynamic config; with
    ``joint_forces`` a ``ConfigForce`` on each dynamic config, with ``string_constraints``
    each string a ``Distance`` constraint to a control point moved in the plane by kinematic
    configs ``NAME-x``, ``NAME-y`` and of kinematic length ``NAME-length``."""

    def __init__(self, dimensions: Optional[Dict[str, Any]] = None,
                 joints: Optional[Dict[str, Any]] = None, joint_forces: bool = False,
                 string_forces: bool = False, string_constraints: bool = False) -> None:
        super().__init__()
        self.string_plane: Any = None
        self.string_hooks: Dict[str, str] = {}
        self.joint_forces: Dict[str, Any] = {}
        self.string_forces: Dict[str, Any] = {}
        self.string_constraints: Dict[str, Dict[str, str]] = {}
        self.dimensions = fill_dimensions(dimensions)
        self.joints = fill_joints(joints)
        self.hold_structure_changes()
        self.import_frames(make_skeleton(self.dimensions, self.joints))
        self.make_string_frames()
        if joint_forces:
            self.make_joint_forces()
        if string_forces:
            self.make_string_forces()
        if string_constraints:
            self.make_string_constraints()
        potentials.Gravity(self, (0, 0, -9.8))
        forces.Damping(self, self.dimensions["damping"])
        self.resume_structure_changes()

    def make_string_frames(self) -> None:
        """The string plane above the world and a hook frame (``NAME_hook``) per string."""
        self.world_frame.import_frames(
            [tz(self.dimensions["string_plane_height"], name="string_plane")])
        self.string_plane = self.get_frame("string_plane")
        for name, (frame, offset) in self.dimensions["strings"].items():
            self.string_hooks[name] = f"{name}_hook"
            self.get_frame(frame).import_frames([const_txyz(offset, name=f"{name}_hook")])

    def make_joint_forces(self) -> None:
        """A ``ConfigForce`` on each dynamic config, its input named after it."""
        # The configs as created: while the structure is on hold (the constructor holds it),
        # `dyn_configs` still lists the configs before the skeleton was imported.
        for config in [c for c in self._configs_created if not c.kinematic]:
            self.joint_forces[config.name] = forces.ConfigForce(
                self, config, config.name, config.name)

    def make_string_forces(self) -> None:
        """Each string a force on its hook in world axes (a ``HybridWrench``), its three
        components the inputs ``NAME-x``, ``NAME-y``, ``NAME-z``."""
        for name, hook in self.string_hooks.items():
            info = {"name": name, "x": f"{name}-x", "y": f"{name}-y", "z": f"{name}-z",
                    "hook": hook}
            forces.HybridWrench(self, hook, (info["x"], info["y"], info["z"], 0, 0, 0),
                                name=name)
            self.string_forces[name] = info

    def make_string_constraints(self) -> None:
        """Each string a ``Distance`` constraint from its hook to a control point in the
        string plane (kinematic ``NAME-x``, ``NAME-y``) of kinematic length ``NAME-length``."""
        for name, hook in self.string_hooks.items():
            info = {"name": name, "x": f"{name}-x", "y": f"{name}-y",
                    "length": f"{name}-length", "control_hook": f"{name}_control",
                    "hook": hook}
            self.string_plane.import_frames([tx(info["x"], kinematic=True), [
                ty(info["y"], kinematic=True, name=info["control_hook"])]])
            constraints.Distance(self, hook, info["control_hook"], info["length"], name=name)
            self.string_constraints[name] = info

    def _strings(self, strings: Optional[List[str]]) -> List[Dict[str, str]]:
        if strings is None:
            return list(self.string_constraints.values())
        return [self.string_constraints[name] for name in strings]

    def project_string_controls(self, strings: Optional[List[str]] = None) -> None:
        """Puts each string's control point (all, or those named) straight above its hook
        at the current configuration, then corrects the strings' lengths."""
        for info in self._strings(strings):
            p = self.get_frame(info["hook"]).p()
            self.get_config(info["x"]).q = p[0]
            self.get_config(info["y"]).q = p[1]
        self.correct_string_lengths(strings)

    def correct_string_lengths(self, strings: Optional[List[str]] = None) -> None:
        """Sets each string's length (all, or those named) to its hook's distance from its
        control point."""
        for info in self._strings(strings):
            length = self.get_constraint(info["name"]).get_actual_distance()
            self.get_config(info["length"]).q = length


class PuppetVisual(VisualItem3D):
    """trep's view of a Puppet's trajectory (``visualize_3d([PuppetVisual(puppet, t, q)])``):
    seen from the front (its forward the world's −y, up +z), drawn as its frames (trep draws
    shaped limbs with OpenGL)."""

    def __init__(self, *args: Any, **kwds: Any):
        super().__init__(*args, **kwds)
        self.setOrientation(forward=[0, -1, 0], up=[0, 0, 1])
        self.puppet = self.system
