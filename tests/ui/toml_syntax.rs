tree_mech::tree_model!(struct Bad from "tests/ui/models/syntax-error.toml");

fn main() {}
