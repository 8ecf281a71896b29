//! `tree-mech check`: a model validated and summarised, its tree drawn as text.

use std::path::{Path, PathBuf};

use tree_mech::model::{self, Given, Rounded};
use tree_mech::runtime::columns_fit;

use super::{counted, Source};

/// What `check` was asked for: its command-line arguments.
#[derive(clap::Args)]
pub struct Args {
    /// Model file (TOML, or URDF by its .urdf extension).
    model: PathBuf,
}

/// Runs `check` with the model read as `source` says.
pub fn run(args: Args, source: &Source) -> Result<(), String> {
    run_check(&args.model, source)
}

fn run_check(path: &Path, source: &Source) -> Result<(), String> {
    let model = source.model(path)?;
    // What the interpreted system would refuse (more Jacobian columns than it allocates);
    // not its evaluation's memory, which a model too large to simulate may still be checked
    // without.
    columns_fit(&model).map_err(|e| e.to_string())?;
    say!("model `{}`: valid", model.name);
    if !source.locks.is_empty() {
        say!("locked (held as constants): {}", source.locks.join(", "));
    }
    say!(
        "gravity: [{}, {}, {}]",
        Given(model.gravity[0]),
        Given(model.gravity[1]),
        Given(model.gravity[2])
    );
    say!(
        "{}, {}:",
        counted(model.frames.len(), "frame"),
        counted(model.variables.len(), "variable")
    );
    print_variables(&model)?;
    print_constraints(&model)?;
    print_contacts(&model)?;
    print_inputs(&model)?;
    print_elements(&model)?;
    print_masses(&model)?;
    say!("tree:\n{}", model.tree_text().trim_end());
    Ok(())
}

/// Each variable: what it drives, its start, dynamic or how it is prescribed, its limits.
fn print_variables(model: &model::Model) -> Result<(), String> {
    // The frames that follow each variable (mimics), found in one pass.
    let mut followers: Vec<Vec<(usize, model::Mimic)>> = vec![Vec::new(); model.variables.len()];
    for (f, frame) in model.frames.iter().enumerate() {
        if let model::Joint::Mimic(m) = frame.joint {
            followers[m.variable].push((f, m));
        }
    }
    for (i, v) in model.variables.iter().enumerate() {
        let mut drives = match v.frame {
            Some(f) => format!(
                "drives `{}` by {}",
                model.frames[f].name, model.frames[f].primitive
            ),
            None => "sets a constraint length".to_string(),
        };
        // Its followers, as the tree writes their parameter.
        for (f, m) in &followers[i] {
            let frame = &model.frames[*f];
            let (name, primitive) = (&frame.name, frame.primitive);
            drives += &format!(" and `{name}` by {primitive}({})", m.describe(&v.name));
        }
        let how = match &v.motion {
            None => format!("dynamic, damping = {}", Given(v.damping)),
            Some(model::Motion::Steady { q0, dq0 }) => {
                format!(
                    "kinematic, held at q0 = {} moving at {}",
                    Given(*q0),
                    Given(*dq0)
                )
            }
            Some(model::Motion::Sine {
                offset,
                amplitude,
                frequency,
                phase,
            }) => format!(
                "kinematic, {} + {}·sin(2π·{}·t + {})",
                Given(*offset),
                Given(*amplitude),
                Given(*frequency),
                Given(*phase)
            ),
            Some(model::Motion::Spline(s)) => {
                let (a, b) = s.span();
                format!(
                    "kinematic, spline through samples on [{}, {}] s",
                    Given(a),
                    Given(b)
                )
            }
        };
        let limits = v
            .limits
            .map(|[lo, hi]| {
                let enforced = match (model.contacts.enforce_limits, v.is_kinematic()) {
                    (true, false) => "enforced",
                    (true, true) => "not enforced: prescribed",
                    (false, _) => "not enforced",
                };
                format!("; limits [{}, {}] ({enforced})", Given(lo), Given(hi))
            })
            .unwrap_or_default();
        say!(
            "  {:<20} {drives}; q0 = {}, dq0 = {}; {how}{limits}",
            v.name,
            Given(v.q0),
            Given(v.dq0)
        );
    }
    Ok(())
}

/// Each constraint: its kind and its frames.
fn print_constraints(model: &model::Model) -> Result<(), String> {
    if !model.constraints.is_empty() {
        say!("{}:", counted(model.constraints.len(), "constraint"));
        for c in &model.constraints {
            let [a, b] = c.frames.map(|f| model.frames[f].name.as_str());
            let what = c.describe(model);
            say!("  {:<20} {what} between `{a}` and `{b}`", c.name);
        }
    }
    Ok(())
}

/// The ground, each contact sphere and slack string, and the unilateral rows they make.
fn print_contacts(model: &model::Model) -> Result<(), String> {
    let c = &model.contacts;
    if let Some(g) = c.ground {
        let n = g.normal.map(Given);
        say!(
            "ground: n·x ≥ {} with n = [{}, {}, {}], friction {}",
            Given(g.height),
            n[0],
            n[1],
            n[2],
            Given(g.friction)
        );
    }
    if !c.spheres.is_empty() {
        say!("{}:", counted(c.spheres.len(), "contact"));
        for s in &c.spheres {
            let friction = s
                .friction
                .map_or(String::new(), |f| format!(", friction {}", Given(f)));
            let collide = if s.collide { "" } else { ", the ground only" };
            say!(
                "  {:<20} sphere of radius {} on `{}`{friction}{collide}",
                s.name,
                Given(s.radius),
                model.frames[s.frame].name
            );
        }
    }
    if !c.strings.is_empty() {
        say!("{}:", counted(c.strings.len(), "slack string"));
    }
    for s in &c.strings {
        let [a, b] = s.frames.map(|f| model.frames[f].name.as_str());
        say!(
            "  {:<20} {} between `{a}` and `{b}`, pulling only",
            s.name,
            s.describe(model)
        );
    }
    let gaps = model.gaps();
    if !gaps.is_empty() {
        let names: Vec<&str> = gaps.iter().map(|g| g.name.as_str()).collect();
        say!(
            "unilateral rows (the VI enforces them; rk4 and rk45 run until one closes, then stop): {}",
            names.join(", ")
        );
    }
    Ok(())
}

/// Each input: the variable it pushes on and its limits.
fn print_inputs(model: &model::Model) -> Result<(), String> {
    if !model.inputs.is_empty() {
        say!(
            "{} (generalized forces u):",
            counted(model.inputs.len(), "input")
        );
        for u in &model.inputs {
            let limits = u
                .limits
                .map(|[lo, hi]| format!("; limits [{}, {}] (not enforced)", Given(lo), Given(hi)))
                .unwrap_or_default();
            say!(
                "  {:<20} on `{}`{limits}",
                u.name,
                model.variables[u.variable].name
            );
        }
    }
    Ok(())
}

/// Springs and dampers.
fn print_elements(model: &model::Model) -> Result<(), String> {
    for s in &model.springs {
        match s.kind {
            model::SpringKind::Frames([a, b]) => say!(
                "spring between `{}` and `{}`: k = {}, rest = {}",
                model.frames[a].name,
                model.frames[b].name,
                Given(s.stiffness),
                Given(s.rest)
            ),
            model::SpringKind::Variable(i) => say!(
                "spring on `{}`: k = {}, rest = {}",
                model.variables[i].name,
                Given(s.stiffness),
                Given(s.rest)
            ),
        }
    }
    for d in &model.dampers {
        say!(
            "damper between `{}` and `{}`: c = {}",
            model.frames[d.frames[0]].name,
            model.frames[d.frames[1]].name,
            Given(d.damping)
        );
    }
    Ok(())
}

/// The masses and their total.
fn print_masses(model: &model::Model) -> Result<(), String> {
    let masses: Vec<_> = model.frames.iter().filter(|f| f.mass.is_some()).collect();
    say!(
        "{}, total mass {} kg:",
        counted(masses.len(), "mass"),
        Rounded(model.total_mass(), 12)
    );
    for f in masses {
        let m = f.mass.unwrap();
        say!("  {:<20} {}", f.name, m.describe());
    }
    Ok(())
}
