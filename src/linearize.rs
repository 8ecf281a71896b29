//! `tree-mech linearize`: the exact linearisation of the dynamics at a state, and of one
//! midpoint-VI step, as JSON.

use std::path::Path;

use serde_json::{json, Value};
use tree_mech::integrate::{
    Forcing, MidpointVi, StepContext, StepInput, StepOutput, StepSecondDerivatives, ViSettings,
};
use tree_mech::nalgebra::{DMatrix, Dyn};
use tree_mech::runtime::linearize::{
    continuous_derivatives, explicit_step_derivatives, DORMAND_PRINCE, RK4,
};
use tree_mech::runtime::{ModelMotions, Prescription, Vector};
use tree_mech::{NoForce, System};

use crate::{parse_list, parse_vector, Source};

/// An explicit method whose step `linearize --dt` can take instead of the VI's.
#[derive(Clone, Copy)]
pub enum Explicit {
    Rk4,
    Rk45,
}

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
    /// Linearise an explicit step instead of the VI's.
    pub explicit: Option<Explicit>,
    /// Add the VI step's second derivatives.
    pub second_order: bool,
}

fn matrix(m: &DMatrix<f64>) -> Value {
    json!((0..m.nrows())
        .map(|r| (0..m.ncols()).map(|c| m[(r, c)]).collect::<Vec<_>>())
        .collect::<Vec<_>>())
}

/// trep's 30 second derivatives of the step under `vi`: `q2_dq1dp1` … as
/// [output][input₁][input₂], each unordered pair of input blocks once (`dq1dp1`, not also
/// `dp1dq1`), in x's order; `lambda1_…` in trep's scaling `−Δt λ`.
fn second_order(vi: &mut Value, second: &StepSecondDerivatives, dt: f64) {
    for of in StepOutput::ALL {
        let (name, scale) = match of {
            StepOutput::Q2 => ("q2", 1.0),
            StepOutput::P2 => ("p2", 1.0),
            StepOutput::Lambda => ("lambda1", -dt),
        };
        for (k, &a) in StepInput::ALL.iter().enumerate() {
            for &b in &StepInput::ALL[k..] {
                let rows: Vec<Value> = second
                    .block(of, a, b)
                    .iter()
                    .map(|h| matrix(&(h * scale)))
                    .collect();
                vi[format!("{name}_d{}d{}", a.name(), b.name())] = Value::Array(rows);
            }
        }
    }
}

pub fn run(path: &Path, source: &Source, request: Request) -> Result<(), String> {
    if request.second_order && (request.explicit.is_some() || request.dt.is_none()) {
        return Err(
            "--second-order is for the VI step: give --dt (and not --integrator rk4 or rk45)"
                .into(),
        );
    }
    let mut sys = source.system(path)?;
    let n = sys.dof();
    let names: Vec<String> = (0..n).map(|i| sys.variable_name(i).to_string()).collect();
    let inputs: Vec<String> = (0..sys.input_count())
        .map(|k| sys.input_name(k).to_string())
        .collect();
    let constraints: Vec<String> = (0..sys.constraint_count())
        .map(|r| sys.constraint_name(r).to_string())
        .collect();
    let dynamic: Vec<usize> = (0..n).filter(|&i| !sys.is_kinematic(i)).collect();
    let kinematic: Vec<usize> = (0..n).filter(|&i| sys.is_kinematic(i)).collect();
    let (q0, dq0) = sys.initial_state();
    let mut q = request
        .q
        .map_or(Ok(q0), |s| parse_vector(s, n, "q", &names))?;
    let mut dq = request
        .dq
        .map_or(Ok(dq0), |s| parse_vector(s, n, "dq", &names))?;
    let u = match request.u {
        Some(text) => parse_list(text, inputs.len(), "u", &inputs, "inputs")?,
        None => vec![0.0; inputs.len()],
    };
    let t = request.t;
    if !t.is_finite() {
        return Err(format!("--t: `{t}` is not a finite time"));
    }
    // The kinematic variables follow their prescription at t.
    let mut motion = ModelMotions::of(&sys);
    for &k in &kinematic {
        [q[k], dq[k], _] = motion.kinematic(k, t);
    }
    let mut force = NoForce;
    let mut cx = StepContext::new(&mut sys, &mut force, &mut motion, 0.0);
    cx.u = &u;
    let d =
        continuous_derivatives(cx.at(0, t), &q, &dq).map_err(|e| format!("at this state, {e}"))?;
    let pick = |list: &[usize]| -> Vec<String> { list.iter().map(|&i| names[i].clone()).collect() };
    let mut out = json!({
        "variables": names,
        "dynamic": pick(&dynamic),
        "kinematic": pick(&kinematic),
        "inputs": inputs,
        "constraints": constraints,
        "q": q.as_slice(),
        "dq": dq.as_slice(),
        "u": u,
        "qdd": d.qdd.as_slice(),
        "qdd_dq": matrix(&d.qdd_dq),
        "qdd_ddq": matrix(&d.qdd_ddq),
        "qdd_du": matrix(&d.qdd_du),
        "lambda": d.lambda.as_slice(),
        "lambda_dq": matrix(&d.lambda_dq),
        "lambda_ddq": matrix(&d.lambda_ddq),
        "lambda_du": matrix(&d.lambda_du),
    });
    if let Some(dt) = request.dt {
        if !(dt > 0.0 && dt.is_finite()) {
            return Err(format!("--dt must be a positive number, got {dt}"));
        }
    }
    if let (Some(dt), Some(method)) = (request.dt, request.explicit) {
        cx.dt = dt;
        let (key, tableau, what) = match method {
            Explicit::Rk4 => ("rk4", &RK4, "the RK4 step"),
            Explicit::Rk45 => ("rk45", &DORMAND_PRINCE, "the Dormand–Prince step"),
        };
        let d = explicit_step_derivatives(cx.at(0, t), &q, &dq, tableau)
            .map_err(|e| format!("{what}: {e}"))?;
        out[key] = json!({
            "t2": t + dt,
            "state": "the dynamic variables' q, then their q̇",
            "x2": d.x2.as_slice(),
            "x2_dx1": matrix(&d.x2_dx1),
            "x2_du1": matrix(&d.x2_du1),
        });
    } else if let Some(dt) = request.dt {
        if !(0.0..=1.0).contains(&request.alpha) {
            return Err(format!("--alpha must lie in [0, 1], got {}", request.alpha));
        }
        let settings = ViSettings {
            alpha: request.alpha,
            forcing: request.forcing,
            max_subdivisions: 0,
            ..ViSettings::default()
        };
        let mut vi = MidpointVi::new(&*cx.sys, settings);
        let mut p1 = vi.initial_momentum(cx.sys, &q, &dq);
        if let Some(text) = request.p {
            let dyn_names = pick(&dynamic);
            let values = parse_list(text, dynamic.len(), "p", &dyn_names, "dynamic variables")?;
            for (c, &i) in dynamic.iter().enumerate() {
                p1[i] = values[c];
            }
        }
        // A guess for λ: the continuous equations' at the state.
        for (s, l) in d.lambda.iter().enumerate() {
            vi.lambda[s] = *l;
        }
        let (mut q2, mut p2, mut next) = (q.clone(), p1.clone(), q.clone());
        cx.dt = dt;
        vi.step(cx.at(0, t), &mut q2, &mut p2, &mut next)
            .map_err(|e| format!("the VI step: {e}"))?;
        let (s, second) = if request.second_order {
            let (s, second) = vi
                .second_derivatives(cx.at(0, t), &q, &p1, &q2)
                .map_err(|e| format!("the VI step: {e}"))?;
            (s, Some(second))
        } else {
            let s = vi
                .derivatives(cx.at(0, t), &q, &p1, &q2)
                .map_err(|e| format!("the VI step: {e}"))?;
            (s, None)
        };
        // trep's λ₁ is −Δt times this integrator's force-scaled λ.
        let trep = |m: &DMatrix<f64>| matrix(&(m * -dt));
        let lambda1: Vec<f64> = vi.lambda.iter().map(|l| -dt * l).collect();
        let rows = |v: &Vector<Dyn>| dynamic.iter().map(|&i| v[i]).collect::<Vec<_>>();
        out["vi"] = json!({
            "t2": t + dt,
            "q2": q2.as_slice(),
            "p2": rows(&p2),
            "lambda": vi.lambda.as_slice(),
            "lambda1": lambda1,
            "q2_dq1": matrix(&s.q2_dq1), "q2_dp1": matrix(&s.q2_dp1),
            "q2_du1": matrix(&s.q2_du1), "q2_dk2": matrix(&s.q2_dk2),
            "p2_dq1": matrix(&s.p2_dq1), "p2_dp1": matrix(&s.p2_dp1),
            "p2_du1": matrix(&s.p2_du1), "p2_dk2": matrix(&s.p2_dk2),
            "lambda1_dq1": trep(&s.lambda_dq1), "lambda1_dp1": trep(&s.lambda_dp1),
            "lambda1_du1": trep(&s.lambda_du1), "lambda1_dk2": trep(&s.lambda_dk2),
        });
        if let Some(second) = second {
            second_order(&mut out["vi"], &second, dt);
        }
    }
    println!(
        "{}",
        serde_json::to_string_pretty(&out).map_err(|e| e.to_string())?
    );
    Ok(())
}
