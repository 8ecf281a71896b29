//! The UR5 compiled with `tree_model!` reaches a point (tasks/ur5-reach.toml): iLQR plans
//! the motion, then the plan is tracked from a pushed start with the solver's feedback gains
//! `u = u_k + K_k (x − x_k)`, and the tracking error is printed as it decays (beside the
//! plan's controls played open loop from the same push, which do not correct it).
//!
//! Run: `cargo run --release --example reach`.

use tree_mech::control::{solve_task, task_system, TaskOptions};
use tree_mech::model;
use tree_mech::nalgebra::DVector;
use tree_mech::{tree_model, System};

tree_model!(pub struct Ur5 from "models/ur5.urdf", enforce_limits = false);

fn main() -> std::process::ExitCode {
    tree_mech::run_main(example)
}

fn example() -> Result<(), Box<dyn std::error::Error>> {
    let (task, model) =
        model::read_task(concat!(env!("CARGO_MANIFEST_DIR"), "/tasks/ur5-reach.toml"))?;
    // Five solves from the same guess, the best time kept (tools/reference/crocoddyl_reach.py
    // times Crocoddyl the same way).
    let solve = || {
        solve_task(
            Ur5::new(),
            &task,
            &model,
            &TaskOptions::default(),
            &mut |_| {},
        )
    };
    let mut res = solve()?;
    for _ in 1..5 {
        res.solve_seconds = res.solve_seconds.min(solve()?.solve_seconds);
    }
    let sol = &res.solution;
    let tool = model.frame_index("ee_link").ok_or("no ee_link")?;
    let end = model.origins(res.q[task.knots].as_slice())[tool];
    println!(
        "planned in {} iterations ({:.1} ms, best of 5 solves, compiled): cost {:.4e}, tool ends at ({:.4}, {:.4}, {:.4}) m",
        sol.history.len(),
        res.solve_seconds * 1e3,
        sol.cost,
        end[0],
        end[1],
        end[2]
    );
    // A push: every joint's momentum disturbed at the start.
    let mut dynamics = task_system(Ur5::new(), &task)?;
    let mut x0 = sol.x[0].clone();
    let nd = Ur5::new().dof();
    assert_eq!(nd, 6, "the UR5's six joints are its state's first entries");
    for r in 0..nd {
        x0[nd + r] += 0.05 * if r % 2 == 0 { 1.0 } else { -1.0 };
    }
    let (mut closed, mut open) = (x0.clone(), x0);
    let mut next = vec![0.0; closed.len()];
    // The tool's distance from where the plan puts it at the same knot.
    let tool_error = |x: &DVector<f64>, plan: &DVector<f64>| {
        let (a, b) = (
            model.origins(x.as_slice())[tool],
            model.origins(plan.as_slice())[tool],
        );
        (0..3).map(|i| (a[i] - b[i]).powi(2)).sum::<f64>().sqrt()
    };
    println!("   t [s]   tool off the plan, tracked [m]   open loop [m]");
    for k in 0..task.knots {
        let error = |x: &DVector<f64>| tool_error(x, &sol.x[k]);
        if k % 10 == 0 {
            println!(
                "  {:5.2}        {:.3e}         {:.3e}",
                k as f64 * task.dt,
                error(&closed),
                error(&open)
            );
        }
        let u = &sol.u[k] + &sol.gains[k] * (&closed - &sol.x[k]);
        dynamics.step(k, closed.as_slice(), u.as_slice(), &mut next, None)?;
        closed.copy_from_slice(&next);
        dynamics.step(k, open.as_slice(), sol.u[k].as_slice(), &mut next, None)?;
        open.copy_from_slice(&next);
    }
    let n = task.knots;
    let error = |x: &DVector<f64>| tool_error(x, &sol.x[n]);
    println!(
        "  {:5.2}        {:.3e}         {:.3e}",
        n as f64 * task.dt,
        error(&closed),
        error(&open)
    );
    Ok(())
}
