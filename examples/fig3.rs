//! The paper's Fig. 3 experiment: simulate the N-link pendulum (N = 1…19) for 10 s at
//! Δt = 0.01 (1000 steps of the midpoint VI) in each evaluation mode, print the wall times
//! as a Markdown table and draw them to `docs/fig3.png`.
//! Run: `cargo run --release --example fig3`.

use std::time::Instant;

use plotters::prelude::*;
use tree_mech::integrate::{JacobianUpdate, MidpointVi, StepContext, ViSettings};
use tree_mech::model;
use tree_mech::nalgebra::{allocator::Allocator, DefaultAllocator};
use tree_mech::{tree_model, NoForce, PaperEvaluation, PaperSystem, System, TreeSystem};

tree_model!(struct P1 from "benches/models/pendulum-1.toml");
tree_model!(struct P2 from "benches/models/pendulum-2.toml");
tree_model!(struct P3 from "benches/models/pendulum-3.toml");
tree_model!(struct P4 from "benches/models/pendulum-4.toml");
tree_model!(struct P5 from "benches/models/pendulum-5.toml");
tree_model!(struct P6 from "benches/models/pendulum-6.toml");
tree_model!(struct P7 from "benches/models/pendulum-7.toml");
tree_model!(struct P8 from "benches/models/pendulum-8.toml");
tree_model!(struct P9 from "benches/models/pendulum-9.toml");
tree_model!(struct P10 from "benches/models/pendulum-10.toml");
tree_model!(struct P11 from "benches/models/pendulum-11.toml");
tree_model!(struct P12 from "benches/models/pendulum-12.toml");
tree_model!(struct P13 from "benches/models/pendulum-13.toml");
tree_model!(struct P14 from "benches/models/pendulum-14.toml");
tree_model!(struct P15 from "benches/models/pendulum-15.toml");
tree_model!(struct P16 from "benches/models/pendulum-16.toml");
tree_model!(struct P17 from "benches/models/pendulum-17.toml");
tree_model!(struct P18 from "benches/models/pendulum-18.toml");
tree_model!(struct P19 from "benches/models/pendulum-19.toml");

/// The generated system for N links, timed.
fn time_generated(n: usize, jacobian: JacobianUpdate) -> f64 {
    match n {
        1 => time_vi_with(&mut P1, jacobian),
        2 => time_vi_with(&mut P2, jacobian),
        3 => time_vi_with(&mut P3, jacobian),
        4 => time_vi_with(&mut P4, jacobian),
        5 => time_vi_with(&mut P5, jacobian),
        6 => time_vi_with(&mut P6, jacobian),
        7 => time_vi_with(&mut P7, jacobian),
        8 => time_vi_with(&mut P8, jacobian),
        9 => time_vi_with(&mut P9, jacobian),
        10 => time_vi_with(&mut P10, jacobian),
        11 => time_vi_with(&mut P11, jacobian),
        12 => time_vi_with(&mut P12, jacobian),
        13 => time_vi_with(&mut P13, jacobian),
        14 => time_vi_with(&mut P14, jacobian),
        15 => time_vi_with(&mut P15, jacobian),
        16 => time_vi_with(&mut P16, jacobian),
        17 => time_vi_with(&mut P17, jacobian),
        18 => time_vi_with(&mut P18, jacobian),
        _ => time_vi_with(&mut P19, jacobian),
    }
}

/// Best wall time of a few 1000-step VI runs from the model's initial state, in ms.
fn time_vi<S: System>(sys: &mut S) -> f64
where
    DefaultAllocator: Allocator<S::N> + Allocator<S::N, S::N>,
{
    time_vi_with(sys, JacobianUpdate::EveryIteration)
}

/// As [`time_vi`], choosing when Newton re-evaluates its Jacobian.
fn time_vi_with<S: System>(sys: &mut S, jacobian: JacobianUpdate) -> f64
where
    DefaultAllocator: Allocator<S::N> + Allocator<S::N, S::N>,
{
    let (q0, dq0) = sys.initial_state();
    let mut best = f64::INFINITY;
    for _ in 0..3 {
        let start = Instant::now();
        let settings = ViSettings {
            jacobian,
            ..ViSettings::default()
        };
        let mut vi = MidpointVi::new(sys, settings);
        let mut motion = tree_mech::runtime::ModelMotions::of(sys);
        let mut q = q0.clone();
        let mut p = vi.initial_momentum(sys, &q0, &dq0);
        let mut next = q0.clone();
        let mut no_force = NoForce;
        let mut cx = StepContext::new(sys, &mut no_force, &mut motion, 0.01);
        for k in 0..1000 {
            vi.step(cx.at(k, k as f64 * 0.01), &mut q, &mut p, &mut next)
                .unwrap();
        }
        best = best.min(start.elapsed().as_secs_f64() * 1e3);
    }
    best
}

fn main() -> std::process::ExitCode {
    tree_mech::run_main(example)
}

fn example() -> Result<(), Box<dyn std::error::Error>> {
    let modes = [
        ("generated, Jacobian reused", None),
        ("generated (tree_model!)", None),
        ("interpreted, sweeps", None),
        ("interpreted, cached (paper)", Some(PaperEvaluation::Cached)),
        (
            "interpreted, uncached (paper)",
            Some(PaperEvaluation::Uncached),
        ),
    ];
    let mut rows: Vec<(usize, Vec<f64>)> = Vec::new();
    println!("| N | generated, reuse [ms] | generated [ms] | interpreted sweeps [ms] | interpreted cached [ms] | interpreted uncached [ms] | sweeps / generated | cached / generated | uncached / cached |");
    println!("|---:|---:|---:|---:|---:|---:|---:|---:|---:|");
    for n in 1..=19 {
        let model = model::n_link_pendulum(n);
        let times: Vec<f64> = modes
            .iter()
            .enumerate()
            .map(|(k, &(_, mode))| match mode {
                None if k == 0 => time_generated(n, JacobianUpdate::OncePerStep),
                None if k == 1 => time_generated(n, JacobianUpdate::EveryIteration),
                None => time_vi(&mut TreeSystem::new(&model).unwrap()),
                Some(mode) => time_vi(&mut PaperSystem::new(&model, mode).unwrap()),
            })
            .collect();
        println!(
            "| {n} | {:.3} | {:.3} | {:.2} | {:.2} | {:.1} | {:.1} | {:.1} | {:.0} |",
            times[0],
            times[1],
            times[2],
            times[3],
            times[4],
            times[2] / times[1],
            times[3] / times[1],
            times[4] / times[3]
        );
        rows.push((n, times));
    }
    let labels: Vec<&str> = modes.iter().map(|m| m.0).collect();
    plot(&rows, &labels, "docs/fig3.png")?;
    println!("\nplot: docs/fig3.png");
    Ok(())
}

fn plot(
    rows: &[(usize, Vec<f64>)],
    labels: &[&str],
    path: &str,
) -> Result<(), Box<dyn std::error::Error>> {
    std::fs::create_dir_all("docs")?;
    let _ = plotters::style::register_font(
        "sans-serif",
        plotters::style::FontStyle::Normal,
        include_bytes!("../assets/DejaVuSans.ttf"),
    );
    let root = BitMapBackend::new(path, (900, 600)).into_drawing_area();
    root.fill(&WHITE)?;
    let lo = rows
        .iter()
        .flat_map(|r| r.1.iter().copied())
        .fold(f64::INFINITY, f64::min);
    let hi = rows
        .iter()
        .flat_map(|r| r.1.iter().copied())
        .fold(0.0, f64::max);
    let mut chart = ChartBuilder::on(&root)
        .caption(
            "N-link pendulum, 10 s at dt = 0.01 (midpoint VI)",
            ("sans-serif", 24),
        )
        .margin(14)
        .x_label_area_size(40)
        .y_label_area_size(70)
        .build_cartesian_2d(1usize..19usize, (lo * 0.7..hi * 1.5).log_scale())?;
    chart
        .configure_mesh()
        .x_desc("links N")
        .y_desc("wall time [ms]")
        .draw()?;
    for (s, label) in labels.iter().enumerate() {
        let color = Palette99::pick(s).to_rgba();
        chart
            .draw_series(LineSeries::new(
                rows.iter().map(|r| (r.0, r.1[s])),
                color.stroke_width(2),
            ))?
            .label(*label)
            .legend(move |(x, y)| {
                PathElement::new(vec![(x, y), (x + 18, y)], color.stroke_width(2))
            });
    }
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::UpperLeft)
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .label_font(("sans-serif", 16))
        .draw()?;
    root.present()?;
    Ok(())
}
