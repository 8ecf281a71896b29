// `contacts from` a TOML file after a model's path: a file that cannot be read, and one whose
// contact names a frame the model lacks (the error gives its line in that file).
tree_mech::tree_model!(struct Missing from "models/pendulum.toml", contacts from "tests/ui/models/no-such.toml");
tree_mech::tree_model!(struct Unknown from "models/pendulum.toml", contacts from "tests/ui/models/bad-contact.toml");

fn main() {}
