//! The command line, a module a command: each reads its own arguments (a `clap::Args`
//! struct) and the model as [`Source`] says, and returns an error as a sentence.

/// `println!` for a command's output: a write that fails (a full disk, a device that takes
/// nothing) returns an error sentence from the enclosing function instead of a panic.
macro_rules! say {
    ($($arg:tt)*) => {
        $crate::cli::write_line(format_args!($($arg)*))?
    };
}

mod animate;
mod bodies;
mod check;
mod eval;
mod forces;
pub mod interrupt;
mod linearize;
mod optimize;
mod output;
mod plot;
mod simulate;

use std::path::Path;

use clap::{Parser, Subcommand, ValueEnum};
use tree_mech::integrate::Forcing;
use tree_mech::model;
use tree_mech::nalgebra::Dyn;
use tree_mech::runtime::Vector;
use tree_mech::TreeSystem;

#[derive(Parser)]
#[command(
    name = "tree-mech",
    version,
    about = "Simulate mechanical systems described as trees of frames"
)]
pub struct Cli {
    #[command(subcommand)]
    command: Command,
    /// URDF models: add a floating base (root_x root_y root_z root_yaw root_pitch root_roll:
    /// tx ty tz rz ry rx) between the world and the root link.
    #[arg(long, global = true)]
    floating_base: bool,
    /// URDF models: load each mimic joint as a joint of its own, its `<mimic>` ignored
    /// (Pinocchio's default; by default a mimic joint follows the joint it names).
    #[arg(long, global = true)]
    independent_mimics: bool,
    /// URDF models: each `<collision><sphere>` becomes a contact sphere on its link (they
    /// touch the ground, not each other).
    #[arg(long, global = true)]
    contacts: bool,
    /// Hold a variable still as a constant, at its q0 or at VALUE: `--lock NAME[=VALUE]`,
    /// repeated or comma-separated (as Pinocchio's reduced model locks joints).
    #[arg(
        long,
        global = true,
        value_name = "NAME[=VALUE]",
        value_delimiter = ','
    )]
    lock: Vec<String>,
    /// Add the ground: the plane z = HEIGHT (default 0) under the world, replacing the
    /// model's own (docs/model-format.md, "Contact"); a negative height as `--ground=-0.1`.
    #[arg(
        long,
        global = true,
        value_name = "HEIGHT",
        num_args = 0..=1,
        default_missing_value = "0"
    )]
    ground: Option<f64>,
    /// The ground's Coulomb friction μ (with --ground; default 0, frictionless).
    #[arg(long, global = true, value_name = "MU")]
    friction: Option<f64>,
    /// Add a contact sphere on a frame: `--contact FRAME[:RADIUS]` (radius 0: a point),
    /// repeated or comma-separated; named after its frame.
    #[arg(
        long,
        global = true,
        value_name = "FRAME[:RADIUS]",
        value_delimiter = ','
    )]
    contact: Vec<String>,
    /// Enforce the variables' limits even where the model says `enforce_limits = false` (they
    /// are enforced by default).
    #[arg(long, global = true, conflicts_with = "no_limits")]
    limits: bool,
    /// Do not enforce the variables' limits, whatever the model says (they stay numbers that
    /// `check` shows; rk4 and rk45 then run through them).
    #[arg(long, global = true)]
    no_limits: bool,
}

#[derive(Subcommand)]
enum Command {
    /// Simulate a model and write its trajectory (CSV) and a picture (PNG).
    #[command(allow_negative_numbers = true)]
    Simulate(simulate::Args),
    /// Evaluate L, its derivatives, q̈ and every pose at a state; prints JSON.
    Eval(eval::Args),
    /// Linearise the dynamics at a state (exact derivatives of q̈ and λ), and with --dt one
    /// midpoint-VI step as a map; prints JSON.
    #[command(allow_negative_numbers = true)]
    Linearize(linearize::Args),
    /// Solve an optimal-control task file (iLQR or DDP) and write the optimal trajectory.
    Optimize(optimize::Request),
    /// Validate a model and print a summary with the tree drawn as text.
    Check(check::Args),
}

impl Cli {
    /// Runs the command it names.
    pub fn run(self) -> Result<(), String> {
        let source = Source {
            urdf: model::UrdfOptions {
                floating_base: self.floating_base,
                independent_mimics: self.independent_mimics,
                collision_spheres: self.contacts,
            },
            locks: self.lock,
            contacts: contacts_of(
                self.ground,
                self.friction,
                &self.contact,
                self.limits,
                self.no_limits,
            )?,
        };
        match self.command {
            Command::Simulate(args) => simulate::run(args, &source),
            Command::Eval(args) => eval::run(args, &source),
            Command::Linearize(args) => linearize::run(args, &source),
            Command::Check(args) => check::run(args, &source),
            Command::Optimize(request) => {
                if source.urdf.floating_base
                    || source.urdf.independent_mimics
                    || source.urdf.collision_spheres
                    || !source.locks.is_empty()
                    || source.contacts != model::ContactsSpec::default()
                {
                    Err("--floating-base, --independent-mimics, --contacts, --lock, --ground, --contact and --limits do not apply to optimize: say `floating_base = true` in the task file, and put locks and contacts in the model".into())
                } else {
                    optimize::run(request)
                }
            }
        }
    }
}

/// How every command reads its model: the URDF options, the variables to lock and the
/// contact added.
pub struct Source {
    urdf: model::UrdfOptions,
    locks: Vec<String>,
    contacts: model::ContactsSpec,
}

/// The contact the command line adds: `--ground [HEIGHT]` with `--friction`, each
/// `--contact FRAME[:RADIUS]` ([`model::ContactSpec::parse`]), `--limits` / `--no-limits`.
fn contacts_of(
    ground: Option<f64>,
    friction: Option<f64>,
    contacts: &[String],
    limits: bool,
    no_limits: bool,
) -> Result<model::ContactsSpec, String> {
    let ground = match (ground, friction) {
        (None, None) => None,
        (height, friction) => Some(model::GroundSpec {
            height,
            friction,
            normal: None,
        }),
    };
    let contacts = (contacts.iter())
        .map(|c| model::ContactSpec::parse(c).map_err(|e| format!("--contact: {e}")))
        .collect::<Result<_, _>>()?;
    Ok(model::ContactsSpec {
        enforce_limits: (limits || no_limits).then_some(limits),
        ground,
        contacts,
    })
}

impl Source {
    /// The model at `path`, with the locked variables held.
    pub fn model(&self, path: &Path) -> Result<model::Model, String> {
        let mut model = model::from_file(path, self.urdf).map_err(|e| e.to_string())?;
        if self.contacts != model::ContactsSpec::default() {
            model = model
                .with_contacts(&self.contacts)
                .map_err(|e| format!("--ground/--contact: {e}"))?;
        }
        if self.locks.is_empty() {
            return Ok(model);
        }
        let locks = self
            .locks
            .iter()
            .map(|l| model::Lock::parse(l))
            .collect::<Result<Vec<_>, _>>()?;
        model.locked(&locks).map_err(|e| e.to_string())
    }

    pub fn system(&self, path: &Path) -> Result<TreeSystem, String> {
        TreeSystem::new(&self.model(path)?).map_err(|e| e.to_string())
    }
}

#[derive(Clone, Copy, ValueEnum)]
enum ForcingArg {
    /// f⁻ = f⁺ = ½Δt F at the midpoint (second order).
    Split,
    /// f⁻ = Δt F, f⁺ = 0 (trep's; first order in the force).
    Left,
}

/// `--integrator`'s parser: the names of [`model::Integrator`], each with its summary in
/// `--help`; clap refuses any other with the list.
fn integrator_arg() -> impl clap::builder::TypedValueParser<Value = model::Integrator> {
    use clap::builder::TypedValueParser;
    let names = model::Integrator::ALL
        .map(|i| clap::builder::PossibleValue::new(i.name()).help(i.summary()));
    clap::builder::PossibleValuesParser::new(names).map(|name| name.parse().unwrap_or_default())
}

impl From<ForcingArg> for Forcing {
    fn from(forcing: ForcingArg) -> Self {
        match forcing {
            ForcingArg::Split => Forcing::Split,
            ForcingArg::Left => Forcing::Left,
        }
    }
}

/// `1 frame`, `2 frames`, `1 mass`, `3 masses`.
fn counted(n: usize, noun: &str) -> String {
    match (n, noun.ends_with('s')) {
        (1, _) => format!("1 {noun}"),
        (_, true) => format!("{n} {noun}es"),
        (_, false) => format!("{n} {noun}s"),
    }
}

/// Parses a comma-separated vector of exactly `n` numbers.
fn parse_vector(text: &str, n: usize, what: &str, names: &[String]) -> Result<Vector<Dyn>, String> {
    parse_list(text, n, what, names, "variable").map(Vector::<Dyn>::from_vec)
}

/// Parses a comma-separated list of exactly `n` finite numbers for option `--{what}`, one per
/// entry of `names` (the model's `kind`s).
fn parse_list(
    text: &str,
    n: usize,
    what: &str,
    names: &[String],
    kind: &str,
) -> Result<Vec<f64>, String> {
    let values: Vec<f64> = text
        .split(',')
        .map(|s| {
            let s = s.trim();
            s.parse::<f64>()
                .ok()
                .filter(|x| x.is_finite())
                .ok_or_else(|| format!("--{what}: `{s}` is not a finite number"))
        })
        .collect::<Result<_, _>>()?;
    if values.len() != n {
        return Err(format!(
            "--{what} has {} values; the model has {} ({})",
            values.len(),
            tree_mech::model::Counted(n, kind),
            names.join(", ")
        ));
    }
    Ok(values)
}

/// Writes one line to standard output and flushes it; a failure is a sentence.
pub fn write_line(line: std::fmt::Arguments<'_>) -> Result<(), String> {
    use std::io::Write;
    let mut out = std::io::stdout().lock();
    writeln!(out, "{line}")
        .and_then(|()| out.flush())
        .map_err(|e| format!("cannot write to standard output: {e}"))
}
