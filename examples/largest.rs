//! The largest models compiled by `tree_model!`: the 40-link pendulum (40 variables) and the
//! humanoid (22 variables, 44 frames). Measure their build with
//! `touch examples/largest.rs && time cargo build --release --example largest`; running it
//! prints the size of each generated evaluation.

tree_mech::tree_model!(struct Pendulum40 from "benches/models/pendulum-40.toml");
tree_mech::tree_model!(struct Humanoid from "models/humanoid.toml");

fn main() -> std::process::ExitCode {
    tree_mech::run_main(example)
}

fn example() -> Result<(), Box<dyn std::error::Error>> {
    println!(
        "pendulum-40: {} variables, {} statements per full evaluation",
        Pendulum40::DOF,
        Pendulum40::STATEMENTS
    );
    println!(
        "humanoid: {} variables, {} statements per full evaluation",
        Humanoid::DOF,
        Humanoid::STATEMENTS
    );
    Ok(())
}
