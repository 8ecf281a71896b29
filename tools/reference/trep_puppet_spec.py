"""Writes tools/reference/trep-puppet.json — trep's Puppet (tools/reference/trep-puppet.toml,
itself written from trep) as the plain frame list python/tests/trep_scripts.py builds
through the trep API, so the same script runs on trep (Python 2.7, no TOML reader) and on
tree_mech.trep. Python 3.11: python3 tools/reference/trep_puppet_spec.py"""
import json
import pathlib
import tomllib

here = pathlib.Path(__file__).parent
model = tomllib.loads((here / "trep-puppet.toml").read_text())
variables = model.get("variables", {})
frames = []
for f in model["frame"]:
    (kind, value), = [(k, f[k]) for k in ("tx", "ty", "tz", "rx", "ry", "rz") if k in f]
    entry = {"name": f["name"], "parent": f.get("parent"), "kind": kind, "value": value}
    if isinstance(value, str) and variables.get(value, {}).get("kinematic"):
        entry["kinematic"] = True
    if f.get("mass"):
        entry["mass"] = f["mass"]
        entry["inertia"] = f.get("inertia", [0.0, 0.0, 0.0])
    frames.append(entry)
spec = {
    "gravity": model.get("gravity", [0.0, 0.0, -9.8]),
    "frames": frames,
    "damping": {k: v["damping"] for k, v in variables.items() if v.get("damping")},
    "strings": [{"name": c["name"], "frames": c["frames"], "length": c["length"]}
                for c in model.get("constraint", [])],
    "q0": {k: v["q0"] for k, v in variables.items() if "q0" in v},
}
(here / "trep-puppet.json").write_text(json.dumps(spec, indent=1) + "\n")
