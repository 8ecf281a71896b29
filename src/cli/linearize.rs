//! `tree-mech linearize`: the exact linearisation of the dynamics at a state, and of one
//! step as a map, as JSON (the numbers from `runtime::report`).

use std::path::{Path, PathBuf};

use serde_json::{json, Value};
use tree_mech::integrate::{project_initial_state, Forcing};
use tree_mech::model::Integrator;
use tree_mech::nalgebra::DMatrix;
use tree_mech::runtime::dynamics::{prescribe, Split};
use tree_mech::runtime::report::{self, Entry, Explicit};
use tree_mech::runtime::ModelMotions;
use tree_mech::System;

use super::{integrator_arg, parse_list, parse_vector, ForcingArg, Source};

/// What to linearise, as the options gave it.
pub struct Request<'a> {
    pub q: Option<&'a str>,
    pub dq: Option<&'a str>,
    pub u: Option<&'a str>,
    pub p: Option<&'a str>,
    pub t: f64,
    pub dt: Option<f64>,
    pub forcing: Forcing,
    pub alpha: f64,
    /// The VI's contact relaxation κ.
    pub kappa: f64,
    /// Linearise an explicit step instead of the VI's.
    pub explicit: Option<Explicit>,
    /// Add the VI step's second derivatives.
    pub second_order: bool,
}

/// What `linearize` was asked for: its command-line arguments.
#[derive(clap::Args)]
pub struct Args {
    /// Model file (TOML, or URDF by its .urdf extension).
    model: PathBuf,
    /// Configuration, comma-separated, in variable order (default: the model's q0; with
    /// neither --q nor --dq, the start projected onto the constraints as simulate takes
    /// it).
    #[arg(long, allow_hyphen_values = true)]
    q: Option<String>,
    /// Velocity, comma-separated (default: the model's dq0, projected with q0).
    #[arg(long, allow_hyphen_values = true)]
    dq: Option<String>,
    /// Inputs, comma-separated in input order (default: zero).
    #[arg(long, allow_hyphen_values = true)]
    u: Option<String>,
    /// Time (the kinematic variables' prescription is taken at it).
    #[arg(long, default_value_t = 0.0, allow_hyphen_values = true)]
    t: f64,
    /// Also one VI step of this length from (t, q, p), and its derivatives.
    #[arg(long)]
    dt: Option<f64>,
    /// The VI step's starting momenta of the dynamic variables (default ∂L/∂q̇ at q, q̇).
    #[arg(long, allow_hyphen_values = true)]
    p: Option<String>,
    /// VI forcing: split (second order) or left (trep's).
    #[arg(long, value_enum, default_value = "split")]
    forcing: ForcingArg,
    /// VI quadrature point α.
    #[arg(long, default_value_t = 0.5)]
    alpha: f64,
    /// VI contact relaxation κ (gap × impulse, m·N·s): the step's derivatives through contact
    /// are those of the relaxed, smooth step; 0 is hard contact.
    #[arg(long, default_value_t = 0.0)]
    kappa: f64,
    /// The step to linearise with --dt: the VI (state (q, p)), or RK4 or rk45's
    /// Dormand–Prince step (state (q, q̇)).
    #[arg(long, default_value = "vi", value_parser = integrator_arg())]
    integrator: Integrator,
    /// With --dt (VI): also the step's 30 second derivatives, `q2_dq1dp1` … as
    /// [output][input1][input2].
    #[arg(long)]
    second_order: bool,
}

/// Runs `linearize` with the model read as `source` says.
pub fn run(args: Args, source: &Source) -> Result<(), String> {
    let Args {
        model,
        q,
        dq,
        u,
        t,
        dt,
        p,
        forcing,
        alpha,
        kappa,
        integrator,
        second_order,
    } = args;
    linearize(
        &model,
        source,
        Request {
            q: q.as_deref(),
            dq: dq.as_deref(),
            u: u.as_deref(),
            p: p.as_deref(),
            t,
            dt,
            forcing: forcing.into(),
            alpha,
            kappa,
            explicit: Explicit::of(integrator),
            second_order,
        },
    )
}

fn matrix(m: &DMatrix<f64>) -> Value {
    json!((0..m.nrows())
        .map(|r| (0..m.ncols()).map(|c| m[(r, c)]).collect::<Vec<_>>())
        .collect::<Vec<_>>())
}

/// An entry as JSON: matrices as rows, second derivatives as `[output][input₁][input₂]`.
fn value(e: &Entry) -> Value {
    match e {
        Entry::Scalar(x) => json!(x),
        Entry::Vector(v) => json!(v),
        Entry::Matrix(m) => matrix(m),
        Entry::Stack(rows) => Value::Array(rows.iter().map(matrix).collect()),
    }
}

fn linearize(path: &Path, source: &Source, request: Request) -> Result<(), String> {
    if request.second_order && (request.explicit.is_some() || request.dt.is_none()) {
        return Err(
            "--second-order is for the VI step: give --dt (and not --integrator rk4 or rk45)"
                .into(),
        );
    }
    if request.p.is_some() && (request.explicit.is_some() || request.dt.is_none()) {
        return Err(
            "--p is the VI step's momentum at its start: give --dt (and not --integrator rk4 \
             or rk45); the continuous linearisation takes --dq"
                .into(),
        );
    }
    if let Some(dt) = request.dt {
        if !(dt > 0.0 && dt.is_finite()) {
            return Err(format!(
                "--dt must be a positive number, got {}",
                tree_mech::model::Given(dt)
            ));
        }
    }
    if !request.t.is_finite() {
        return Err(format!("--t: `{}` is not a finite time", request.t));
    }
    let mut sys = source.system(path)?;
    let n = sys.dof();
    let names: Vec<String> = (0..n).map(|i| sys.variable_name(i).to_string()).collect();
    let inputs: Vec<String> = sys.input_names();
    let constraints: Vec<String> = (0..sys.constraint_count())
        .map(|r| sys.constraint_name(r).to_string())
        .collect();
    let pick = |kinematic: bool| -> Vec<String> {
        (0..n)
            .filter(|&i| sys.is_kinematic(i) == kinematic)
            .map(|i| names[i].clone())
            .collect()
    };
    let (dynamic, kinematic) = (pick(false), pick(true));
    // The model's own start is taken as `simulate` takes it: its kinematic variables at their
    // prescription (here at --t), then projected onto the constraints.
    let (mut q0, mut dq0) = sys.initial_state();
    if request.q.is_none() && request.dq.is_none() {
        let split = Split::of(&sys);
        let mut motion = ModelMotions::of(&sys);
        prescribe(
            &split.kinematic,
            &mut motion,
            request.t,
            &mut q0,
            &mut dq0,
            None,
        );
        project_initial_state(&mut sys, &split, &mut q0, &mut dq0)
            .map_err(|e| format!("the model's start: {e}"))?;
    }
    let q = request
        .q
        .map_or(Ok(q0), |s| parse_vector(s, n, "q", &names))?;
    let dq = request
        .dq
        .map_or(Ok(dq0), |s| parse_vector(s, n, "dq", &names))?;
    let u = match request.u {
        Some(text) => parse_list(text, inputs.len(), "u", &inputs, "input")?,
        None => vec![0.0; inputs.len()],
    };
    let p = match request.p {
        Some(text) => Some(parse_list(
            text,
            dynamic.len(),
            "p",
            &dynamic,
            "dynamic variable",
        )?),
        None => None,
    };
    let r = report::linearize(
        &mut sys,
        &q,
        &dq,
        &report::Request {
            t: request.t,
            u,
            dt: request.dt,
            p,
            forcing: request.forcing,
            alpha: request.alpha,
            explicit: request.explicit,
            second_order: request.second_order,
            kappa: request.kappa,
        },
    )
    .map_err(|e| e.to_string())?;
    let mut out = json!({
        "variables": names,
        "dynamic": dynamic,
        "kinematic": kinematic,
        "inputs": inputs,
        "constraints": constraints,
    });
    for (key, e) in &r.continuous {
        out[key] = value(e);
    }
    if let Some((key, entries)) = &r.step {
        let mut step = json!({});
        for (name, e) in entries {
            step[name] = value(e);
        }
        if *key != "vi" {
            step["state"] = json!("the dynamic variables' q, then their q̇");
        }
        out[*key] = step;
    }
    say!(
        "{}",
        serde_json::to_string_pretty(&out).map_err(|e| e.to_string())?
    );
    Ok(())
}
