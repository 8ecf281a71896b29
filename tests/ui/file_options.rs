// After a file's path: `floating_base`, `lean` (or `lean = false`) and `contacts from "…"`,
// nothing else.
tree_mech::tree_model!(struct Fast from "models/pendulum.toml", fast);
tree_mech::tree_model!(struct Number from "models/pendulum.toml", lean = 1);

fn main() {}
