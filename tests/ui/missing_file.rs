tree_mech::tree_model!(struct Bad from "tests/ui/models/does-not-exist.toml");

fn main() {}
