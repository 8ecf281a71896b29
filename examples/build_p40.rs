//! Compile-time check: the 40-link pendulum (40 variables) compiled by `tree_model!`.
//! `touch examples/build_p40.rs && time cargo build --release --example build_p40` measures
//! its build; running it prints the size of the generated evaluation.

tree_mech::tree_model!(struct Pendulum40 from "benches/models/pendulum-40.toml");

fn main() {
    println!(
        "pendulum-40: {} variables, {} statements per full evaluation",
        Pendulum40::DOF,
        Pendulum40::STATEMENTS
    );
}
