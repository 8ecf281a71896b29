// After a file's path: `floating_base`, `lean` (or `lean = false`), `contacts from "…"` and
// `enforce_limits = true|false`, nothing else.
tree_mech::tree_model!(struct Fast from "models/pendulum.toml", fast);
tree_mech::tree_model!(struct Number from "models/pendulum.toml", lean = 1);
tree_mech::tree_model!(struct Limits from "models/ur5.urdf", enforce_limits);

fn main() {}
