tree_mech::tree_model!(struct Bad from "tests/ui/models/unknown-parent.toml");

fn main() {}
