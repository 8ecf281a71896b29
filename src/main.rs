//! The `tree-mech` command line: simulate a model, evaluate it at a state, linearise it,
//! solve an optimal-control task, check a model. Each command is a module of `cli`.

mod cli;

use clap::Parser;

fn main() -> std::process::ExitCode {
    cli::interrupt::install();
    let status = tree_mech::run_main(|| Ok(cli::Cli::parse().run()?));
    if cli::interrupt::requested() {
        return std::process::ExitCode::from(cli::interrupt::STATUS);
    }
    status
}
