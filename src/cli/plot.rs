//! The trajectory picture: one panel per kind of variable — angles (rad), lengths (m), the
//! prescribed (kinematic) ones — then the total energy and, with constraints, their forces λ.
//! Every curve has a legend entry in a column beside its panel. Drawn at twice the size and
//! averaged down, so lines and text are anti-aliased.

use plotters::prelude::*;
use plotters::style::{register_font, FontStyle};
use tree_mech::model::{ConstraintKind, Model};
use tree_mech::Trajectory;

use super::output::{drawing_error, OutputFile, Sentence};

/// DejaVu Sans, bundled so plots need no system fonts (licence in `assets/`).
pub static FONT: &[u8] = include_bytes!("../../assets/DejaVuSans.ttf");

/// Drawing scale: pictures are drawn this many times larger, then averaged down.
const SCALE: u32 = 2;
/// The picture's width in pixels (after averaging).
const WIDTH: u32 = 1200;
/// The legend column's width.
const LEGEND: u32 = 230;
/// One legend row's height.
const ROW: u32 = 17;

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
pub type Series = (String, Vec<(f64, f64)>);

/// One panel: a caption, the y axis's label, its curves over time (or over `x` when it
/// is given: its label and its end).
pub struct Panel {
    pub caption: String,
    pub y_desc: &'static str,
    pub series: Vec<Series>,
    pub x: Option<(&'static str, f64)>,
}

impl Panel {
    /// Its height before scaling: room for the chart, and for every legend row (in two
    /// columns past 30 curves).
    fn height(&self) -> u32 {
        let rows = self
            .series
            .len()
            .div_ceil(if self.series.len() > 30 { 2 } else { 1 });
        (ROW * rows as u32 + 70).max(280)
    }
}

type Area<'a> = DrawingArea<BitMapBackend<'a>, plotters::coord::Shift>;

/// Draws `panel` over `0..t_end`, its legend in a column at the right.
fn draw_panel(area: &Area, panel: &Panel, t_end: f64) -> Result<(), String> {
    let (x_desc, t_end) = panel.x.unwrap_or(("t [s]", t_end));
    let err = drawing_error;
    let s = SCALE as i32;
    let (chart_area, legend) = area.split_horizontally((WIDTH - LEGEND) * SCALE);
    let (lo, hi) = range(panel.series.iter().flat_map(|s| s.1.iter().map(|p| p.1)));
    let mut chart = ChartBuilder::on(&chart_area)
        .caption(&panel.caption, ("sans-serif", 22 * s))
        .margin(10 * s)
        .x_label_area_size(36 * s)
        .y_label_area_size(80 * s)
        .build_cartesian_2d(0.0..t_end, lo..hi)
        .map_err(|e| err(&e))?;
    chart
        .configure_mesh()
        .x_desc(x_desc)
        .y_desc(panel.y_desc)
        .label_style(("sans-serif", 13 * s))
        .axis_desc_style(("sans-serif", 15 * s))
        .light_line_style(RGBColor(235, 235, 235).stroke_width(SCALE))
        .bold_line_style(RGBColor(215, 215, 215).stroke_width(SCALE))
        .draw()
        .map_err(|e| err(&e))?;
    let columns = if panel.series.len() > 30 { 2 } else { 1 };
    let per_column = panel.series.len().div_ceil(columns).max(1);
    let column_width = (LEGEND / columns as u32) as i32 * s;
    for (i, (name, points)) in panel.series.iter().enumerate() {
        let color = Palette99::pick(i).to_rgba();
        chart
            .draw_series(LineSeries::new(
                points.iter().copied(),
                color.stroke_width(2 * SCALE),
            ))
            .map_err(|e| err(&e))?;
        let (c, r) = ((i / per_column) as i32, (i % per_column) as i32);
        let (x, y) = (c * column_width + 4 * s, (44 + r * ROW as i32) * s);
        legend
            .draw(&PathElement::new(
                vec![(x, y), (x + 16 * s, y)],
                color.stroke_width(3 * SCALE),
            ))
            .map_err(|e| err(&e))?;
        legend
            .draw(&Text::new(
                name.clone(),
                (x + 22 * s, y - 7 * s),
                ("sans-serif", 13 * s).into_font(),
            ))
            .map_err(|e| err(&e))?;
    }
    Ok(())
}

/// The most curves a panel of the variables shows: past it, curves of different size
/// flatten each other against one scale, and the legend's colours repeat.
const CROWDED: usize = 8;

/// `panel` as panels of at most [`CROWDED`] curves each, in order (a model's variables come
/// limb by limb), each on its own scale: "angles (1 of 3)" ….
fn split_crowded(panel: Panel) -> Vec<Panel> {
    if panel.series.len() <= CROWDED || panel.x.is_some() {
        return vec![panel];
    }
    let parts = panel.series.len().div_ceil(CROWDED);
    let size = panel.series.len().div_ceil(parts);
    let mut series = panel.series.into_iter().peekable();
    (1..=parts)
        .map(|k| Panel {
            caption: format!("{} ({k} of {parts})", panel.caption),
            y_desc: panel.y_desc,
            series: series.by_ref().take(size).collect(),
            x: None,
        })
        .collect()
}

/// The constraints' multipliers λ in their units: a distance constraint `‖d‖² − ℓ² = 0`
/// has λ in N/m (its tension is `−2ℓλ` N: a taut string has λ < 0); a plane or point
/// constraint, a length, has λ in N.
fn constraint_panel(traj: &Trajectory, model: &Model) -> Panel {
    let mut units = Vec::new();
    for c in &model.constraints {
        let unit = match c.kind {
            ConstraintKind::Distance { .. } => "N/m",
            _ => "N",
        };
        units.extend(std::iter::repeat_n(unit, c.rows()));
    }
    let same = units.windows(2).all(|w| w[0] == w[1]);
    Panel {
        caption: "constraint multipliers λ (a string's tension is −2ℓλ: taut, λ < 0)".into(),
        y_desc: match (same, units.first()) {
            (true, Some(&"N/m")) => "λ [N/m]",
            (true, _) => "λ [N]",
            (false, _) => "λ [N/m or N]",
        },
        series: (0..traj.constraints.len())
            .map(|r| {
                let points = (0..traj.len())
                    .map(|k| (traj.t[k], traj.lambda(k)[r]))
                    .collect();
                let unit = units.get(r).copied().unwrap_or("");
                (format!("{} [{unit}]", traj.constraints[r]), points)
            })
            .collect(),
        x: None,
    }
}

/// Writes a PNG of `traj` (a run of `model`) to `out`.
pub fn plot(traj: &Trajectory, model: &Model, out: &OutputFile) -> Result<(), String> {
    plot_with(traj, model, out, Vec::new())
}

/// [`plot`] with `extra` panels after the run's own.
pub fn plot_with(
    traj: &Trajectory,
    model: &Model,
    out: &OutputFile,
    extra: Vec<Panel>,
) -> Result<(), String> {
    let err =
        |e: &dyn Sentence| format!("cannot draw `{}`: {}", out.path().display(), e.sentence());
    let _ = register_font("sans-serif", FontStyle::Normal, FONT);
    let title = &model.name;
    let curve = |i: usize| {
        let points = (0..traj.len()).map(|k| (traj.t[k], traj.q(k)[i])).collect();
        (traj.variables[i].clone(), points)
    };
    let of_kind = |keep: &dyn Fn(usize) -> bool| -> Vec<Series> {
        (0..traj.dof()).filter(|&i| keep(i)).map(curve).collect()
    };
    let kinematic = |i: usize| model.variables[i].is_kinematic();
    let mut panels = vec![
        Panel {
            caption: format!("{title}: angles"),
            y_desc: "q [rad]",
            series: of_kind(&|i| !kinematic(i) && model.is_angle(i)),
            x: None,
        },
        Panel {
            caption: format!("{title}: lengths"),
            y_desc: "q [m]",
            series: of_kind(&|i| !kinematic(i) && !model.is_angle(i)),
            x: None,
        },
        Panel {
            caption: format!("{title}: prescribed (kinematic) variables"),
            y_desc: "q [rad or m]",
            series: of_kind(&kinematic),
            x: None,
        },
        Panel {
            caption: "total energy".into(),
            y_desc: "E [J]",
            series: vec![(
                "energy".into(),
                traj.t
                    .iter()
                    .copied()
                    .zip(traj.energy.iter().copied())
                    .collect(),
            )],
            x: None,
        },
    ];
    if !traj.constraints.is_empty() {
        panels.push(constraint_panel(traj, model));
    }
    panels.extend(extra);
    panels.retain(|p| !p.series.is_empty());
    let panels: Vec<Panel> = panels.into_iter().flat_map(split_crowded).collect();
    let height: u32 = panels.iter().map(Panel::height).sum();
    let t_end = traj.t.last().copied().unwrap_or(1.0).max(1e-9);
    let (w, h) = (WIDTH * SCALE, height * SCALE);
    let mut big = vec![255u8; (3 * w * h) as usize];
    {
        let root = BitMapBackend::with_buffer(&mut big, (w, h)).into_drawing_area();
        let mut rest = root.clone();
        for panel in &panels {
            let (area, below) = rest.split_vertically(panel.height() * SCALE);
            draw_panel(&area, panel, t_end).map_err(|e| err(&e))?;
            rest = below;
        }
        root.present().map_err(|e| err(&e))?;
    }
    // Each output pixel the mean of its SCALE × SCALE block: anti-aliased lines and text.
    let (w, h) = (WIDTH as usize, height as usize);
    let n = SCALE as usize;
    let mut small = vec![0u8; 3 * w * h];
    for y in 0..h {
        for x in 0..w {
            for c in 0..3 {
                let mut sum = 0u32;
                for dy in 0..n {
                    for dx in 0..n {
                        sum += big[3 * ((y * n + dy) * w * n + x * n + dx) + c] as u32;
                    }
                }
                small[3 * (y * w + x) + c] = (sum / (n * n) as u32) as u8;
            }
        }
    }
    let file = std::fs::File::create(out.temp()).map_err(|e| err(&e.to_string()))?;
    let mut encoder = png::Encoder::new(std::io::BufWriter::new(file), w as u32, h as u32);
    encoder.set_color(png::ColorType::Rgb);
    encoder.set_depth(png::BitDepth::Eight);
    encoder
        .write_header()
        .and_then(|mut writer| writer.write_image_data(&small))
        .map_err(|e| err(&e.to_string()))?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_crowded_panel_is_split_in_order_and_a_short_one_kept() {
        let series = |n: usize| -> Vec<Series> {
            (0..n)
                .map(|i| (format!("q{i}"), vec![(0.0, i as f64)]))
                .collect()
        };
        let panel = |n: usize| Panel {
            caption: "angles".into(),
            y_desc: "q [rad]",
            series: series(n),
            x: None,
        };
        let parts = split_crowded(panel(21));
        let sizes: Vec<usize> = parts.iter().map(|p| p.series.len()).collect();
        assert_eq!(sizes, [7, 7, 7]);
        assert_eq!(parts[2].caption, "angles (3 of 3)");
        assert_eq!(parts[1].series[0].0, "q7");
        assert_eq!(split_crowded(panel(CROWDED)).len(), 1);
    }

    #[test]
    fn constraint_multipliers_carry_their_units() {
        let path = concat!(env!("CARGO_MANIFEST_DIR"), "/models/marionette.toml");
        let model = tree_mech::model::from_toml_file(path).unwrap();
        let rows = model.constraint_row_names();
        let traj = Trajectory::new(Vec::new(), rows, 1);
        let panel = constraint_panel(&traj, &model);
        assert_eq!(panel.y_desc, "λ [N/m]");
        assert!(
            panel.series[0].0.ends_with(" [N/m]"),
            "{}",
            panel.series[0].0
        );
    }
}
