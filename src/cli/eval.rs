//! `tree-mech eval`: `L`, its derivatives, `q̈`, `λ`, every pose and the asked frames'
//! kinematics at one state, as JSON.

use std::path::PathBuf;

use serde_json::json;
use tree_mech::nalgebra::Dyn;
use tree_mech::runtime::evaluation::evaluate_state;
use tree_mech::runtime::kinematics::{Kinematics, Reference};
use tree_mech::runtime::{ModelMotions, Prescription};
use tree_mech::System;

use super::{parse_list, parse_vector, Source};

/// What `eval` was asked for: its command-line arguments.
#[derive(clap::Args)]
pub struct Args {
    /// Model file (TOML, or URDF by its .urdf extension).
    model: PathBuf,
    /// Configuration, comma-separated, in variable order (default: the model's q0).
    #[arg(long, allow_hyphen_values = true)]
    q: Option<String>,
    /// Velocity, comma-separated (default: the model's dq0).
    #[arg(long, allow_hyphen_values = true)]
    dq: Option<String>,
    /// Time at which the kinematic variables' accelerations are taken.
    #[arg(long, default_value_t = 0.0, allow_hyphen_values = true)]
    t: f64,
    /// Inputs `u`, comma-separated in the model's input order (default: zero).
    #[arg(long, allow_hyphen_values = true)]
    u: Option<String>,
    /// A frame whose kinematics to add under `frames` (repeatable): its pose, Jacobian,
    /// twist and accelerations at this state, q̈ from the dynamics.
    #[arg(long = "frame", value_name = "NAME")]
    frames: Vec<String>,
}

/// Runs `eval` with the model read as `source` says.
pub fn run(args: Args, source: &Source) -> Result<(), String> {
    let Args {
        model,
        q,
        dq,
        t,
        u,
        frames,
    } = args;
    run_eval(
        &model,
        source,
        EvalState {
            q: q.as_deref(),
            dq: dq.as_deref(),
            u: u.as_deref(),
            t,
        },
        &frames,
    )
}

/// The state `eval` is asked about, as given on the command line.
struct EvalState<'a> {
    q: Option<&'a str>,
    dq: Option<&'a str>,
    u: Option<&'a str>,
    t: f64,
}

fn run_eval(
    path: &std::path::Path,
    source: &Source,
    state: EvalState<'_>,
    frames: &[String],
) -> Result<(), String> {
    let EvalState { q, dq, u, t: time } = state;
    let mut sys = source.system(path)?;
    let n = sys.dof();
    let names: Vec<String> = (0..n).map(|i| sys.variable_name(i).to_string()).collect();
    let (q0, dq0) = sys.initial_state();
    let q = q.map_or(Ok(q0), |s| parse_vector(s, n, "q", &names))?;
    let dq = dq.map_or(Ok(dq0), |s| parse_vector(s, n, "dq", &names))?;
    if !time.is_finite() {
        return Err(format!("--t: `{time}` is not a finite time"));
    }
    let input_names: Vec<String> = sys.input_names();
    let u = match u {
        Some(text) => parse_list(text, input_names.len(), "u", &input_names, "input")?,
        None => vec![0.0; sys.input_count()],
    };
    let e = evaluate_state(&mut sys, time, &q, &dq, &u).map_err(|e| e.to_string())?;
    let (t, c) = (&e.terms, &e.constraints);
    let dynamic: Vec<usize> = (0..n).filter(|&i| !sys.is_kinematic(i)).collect();
    let kinematic: Vec<usize> = (0..n).filter(|&i| sys.is_kinematic(i)).collect();
    let rows = sys.constraint_count();
    let mut motion = ModelMotions::of(&sys);
    let name_list =
        |list: &[usize]| -> Vec<String> { list.iter().map(|&i| names[i].clone()).collect() };
    let constraint_names: Vec<String> = (0..rows)
        .map(|r| sys.constraint_name(r).to_string())
        .collect();
    let dh: Vec<Vec<f64>> = (0..rows)
        .map(|r| (0..n).map(|i| c.dh[(r, i)]).collect())
        .collect();
    let kinematic_motion: serde_json::Map<String, serde_json::Value> = kinematic
        .iter()
        .map(|&i| (names[i].clone(), json!(motion.kinematic(i, time))))
        .collect();
    let matrix = |m: &tree_mech::runtime::Matrix<Dyn>| -> Vec<Vec<f64>> {
        (0..n)
            .map(|i| (0..n).map(|j| m[(i, j)]).collect())
            .collect()
    };
    let poses: serde_json::Map<String, serde_json::Value> = e
        .poses
        .iter()
        .enumerate()
        .map(|(k, p)| (sys.frame_name(k).to_string(), json!(p.matrix())))
        .collect();
    // The frames' kinematics at the state, q̈ from the dynamics (kinematic variables'
    // from their prescription), in world axes at each frame's origin.
    let mut kinematics = Kinematics::new(sys.model()).map_err(|e| e.to_string())?;
    kinematics
        .update(q.as_slice(), Some(dq.as_slice()), Some(e.qdd.as_slice()))
        .map_err(|e| e.to_string())?;
    let mut frame_entries = serde_json::Map::new();
    for name in frames {
        let f = kinematics
            .frame(name)
            .map_err(|e| format!("--frame: {e}"))?;
        let jacobian = kinematics.jacobian(f, Reference::LocalWorldAligned);
        frame_entries.insert(
            name.clone(),
            json!({
                "pose": kinematics.pose(f).matrix(),
                "jacobian": (0..6)
                    .map(|r| (0..n).map(|c| jacobian[(r, c)]).collect::<Vec<_>>())
                    .collect::<Vec<_>>(),
                "velocity": kinematics.velocity(f, Reference::LocalWorldAligned),
                "acceleration": kinematics.acceleration(f, Reference::LocalWorldAligned),
                "classical_acceleration": kinematics.classical_acceleration(f),
            }),
        );
    }
    let com = kinematics.center_of_mass();
    let out = json!({
        "variables": names,
        "q": q.as_slice(),
        "dq": dq.as_slice(),
        "L": t.l,
        "energy": e.energy,
        "dL_dq": t.dl_dq.as_slice(),
        "dL_ddq": t.dl_ddq.as_slice(),
        "M": matrix(&t.mass),
        "d2L_ddqdq": matrix(&t.d2l_ddq_dq),
        "d2L_dqdq": matrix(&t.d2l_dq_dq),
        "dynamic": name_list(&dynamic),
        "kinematic": name_list(&kinematic),
        "kinematic_motion": kinematic_motion,
        "qdd": dynamic.iter().map(|&i| e.qdd[i]).collect::<Vec<_>>(),
        "constraints": constraint_names,
        "h": c.h.as_slice(),
        "dh_dq": dh,
        "lambda": e.lambda.as_slice(),
        "inputs": input_names,
        "u": u,
        "poses": poses,
        "center_of_mass": {
            "mass": com.mass,
            "com": com.position,
            "vcom": com.velocity,
            "acom": com.acceleration,
        },
        "frames": frame_entries,
    });
    say!(
        "{}",
        serde_json::to_string_pretty(&out).map_err(|e| e.to_string())?
    );
    Ok(())
}
