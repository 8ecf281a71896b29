//! The trajectory picture: every variable over time above, total energy below.

use plotters::prelude::*;

use crate::output::{drawing_error, OutputFile, Sentence};
use plotters::style::{register_font, FontStyle};
use tree_mech::Trajectory;

/// DejaVu Sans, bundled so plots need no system fonts (licence in `assets/`).
pub static FONT: &[u8] = include_bytes!("../assets/DejaVuSans.ttf");

fn range(values: impl Iterator<Item = f64>) -> (f64, f64) {
    let (lo, hi) = values.fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), x| {
        (a.min(x), b.max(x))
    });
    if !lo.is_finite() || !hi.is_finite() {
        return (-1.0, 1.0);
    }
    let pad = ((hi - lo) * 0.05).max(1e-9 * hi.abs().max(1.0));
    (lo - pad, hi + pad)
}

/// One named curve.
type Series = (String, Vec<(f64, f64)>);

/// Draws one panel: `series` over `0..t_end` with a caption and a legend (when there is more
/// than one curve and not too many to read).
fn panel(
    area: &DrawingArea<BitMapBackend<'_>, plotters::coord::Shift>,
    caption: &str,
    y_desc: &str,
    t_end: f64,
    series: &[Series],
) -> Result<(), String> {
    let err = drawing_error;
    let (lo, hi) = range(series.iter().flat_map(|s| s.1.iter().map(|p| p.1)));
    let mut chart = ChartBuilder::on(area)
        .caption(caption, ("sans-serif", 24))
        .margin(12)
        .x_label_area_size(36)
        .y_label_area_size(90)
        .build_cartesian_2d(0.0..t_end, lo..hi)
        .map_err(|e| err(&e))?;
    chart
        .configure_mesh()
        .x_desc("t [s]")
        .y_desc(y_desc)
        .draw()
        .map_err(|e| err(&e))?;
    for (i, (name, points)) in series.iter().enumerate() {
        let color = Palette99::pick(i).to_rgba();
        chart
            .draw_series(LineSeries::new(
                points.iter().copied(),
                color.stroke_width(2),
            ))
            .map_err(|e| err(&e))?
            .label(name.clone())
            .legend(move |(x, y)| {
                PathElement::new(vec![(x, y), (x + 18, y)], color.stroke_width(2))
            });
    }
    if (2..=24).contains(&series.len()) {
        chart
            .configure_series_labels()
            .background_style(WHITE.mix(0.8))
            .border_style(BLACK)
            .label_font(("sans-serif", 14))
            .draw()
            .map_err(|e| err(&e))?;
    }
    Ok(())
}

/// Writes a PNG of `traj` to `path`: every variable over time above, total energy below, and
/// with constraints a third panel of the constraint forces λ.
pub fn plot(traj: &Trajectory, title: &str, out: &OutputFile) -> Result<(), String> {
    let err = |e: &dyn Sentence| {
        format!(
            "cannot draw `{}`: {}",
            out.path().display(),
            drawing_error(e)
        )
    };
    let _ = register_font("sans-serif", FontStyle::Normal, FONT);
    let constrained = !traj.constraints.is_empty();
    let height = if constrained { 1220 } else { 900 };
    let root = BitMapBackend::new(out.temp(), (1200, height)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| err(&e))?;
    let (top, rest) = root.split_vertically(560);
    let (bottom, forces) = rest.split_vertically(340);
    let t_end = traj.t.last().copied().unwrap_or(1.0).max(1e-9);
    let variables: Vec<Series> = (0..traj.dof())
        .map(|i| {
            let points = (0..traj.len()).map(|k| (traj.t[k], traj.q(k)[i])).collect();
            (traj.variables[i].clone(), points)
        })
        .collect();
    let energy = vec![(
        "energy".to_string(),
        traj.t
            .iter()
            .copied()
            .zip(traj.energy.iter().copied())
            .collect(),
    )];
    panel(
        &top,
        &format!("{title}: configuration"),
        "q",
        t_end,
        &variables,
    )
    .map_err(|e| err(&e))?;
    panel(&bottom, "total energy", "E [J]", t_end, &energy).map_err(|e| err(&e))?;
    if constrained {
        let lambda: Vec<Series> = (0..traj.constraints.len())
            .map(|r| {
                let points = (0..traj.len())
                    .map(|k| (traj.t[k], traj.lambda(k)[r]))
                    .collect();
                (traj.constraints[r].clone(), points)
            })
            .collect();
        panel(
            &forces,
            "constraint forces (λ; a taut string has λ < 0)",
            "λ",
            t_end,
            &lambda,
        )
        .map_err(|e| err(&e))?;
    }
    root.present().map_err(|e| err(&e))?;
    Ok(())
}
