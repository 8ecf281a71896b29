//! The animation (`simulate --animate out.gif`): the figure in perspective — bones along the
//! rigid links, masses as dots sized by mass, strings and other elements as lines between
//! their frames, control points as small squares, a floor grid below — one GIF frame per
//! 1/25 s of simulated time.

use plotters::coord::Shift;
use plotters::prelude::*;

use crate::output::{drawing_error, OutputFile, Sentence};
use plotters::style::{register_font, FontStyle};
use tree_mech::model::{ConstraintKind, Joint, Model, SpringKind};
use tree_mech::runtime::Pose;

use crate::plot::FONT;

/// Picture size in pixels.
const SIZE: (u32, u32) = (640, 480);
/// Frames per second of simulated time, at most (the GIF plays in real time).
pub const FPS: f64 = 25.0;
/// The most frames a GIF gets: longer runs get fewer frames per simulated second.
pub const MAX_FRAMES: usize = 500;

/// What is drawn, read once from the model.
struct Figure {
    /// `(parent, child)`: a rigid link between two frame origins (`None` is the world
    /// origin). Only constant translations that lead to mass are bones: a variable
    /// translation is a slider, not a link, and a massless branch (a control point's
    /// chain) is scaffolding.
    bones: Vec<(Option<usize>, usize)>,
    /// `(frame, mass)` of every mass.
    masses: Vec<(usize, f64)>,
    /// Lines between two frames with their colour: constraints, springs, dampers.
    links: Vec<([usize; 2], RGBColor)>,
    /// Frames that an element attaches to and that carry no mass below them: control points.
    anchors: Vec<usize>,
}

const STRING: RGBColor = RGBColor(30, 30, 30);
const SPRING: RGBColor = RGBColor(20, 140, 60);
const DAMPER: RGBColor = RGBColor(40, 80, 200);
const BONE: RGBColor = RGBColor(90, 90, 100);
const WOOD: RGBColor = RGBColor(170, 110, 50);
const ANCHOR: RGBColor = RGBColor(200, 40, 40);
const GRID: RGBColor = RGBColor(215, 215, 220);

impl Figure {
    fn of(model: &Model) -> Figure {
        let n = model.frames.len();
        let mut carries_mass: Vec<bool> = model
            .frames
            .iter()
            .map(|f| f.mass.is_some_and(|m| m.mass > 0.0))
            .collect();
        for k in (0..n).rev() {
            if let Some(p) = model.frames[k].parent {
                carries_mass[p] |= carries_mass[k];
            }
        }
        let bones = (0..n)
            .filter(|&k| {
                let f = &model.frames[k];
                !f.primitive.is_rotation()
                    && matches!(f.joint, Joint::Constant(x) if x != 0.0)
                    && carries_mass[k]
            })
            .map(|k| (model.frames[k].parent, k))
            .collect();
        let masses = (0..n)
            .filter_map(|k| {
                let m = model.frames[k].mass?.mass;
                (m > 0.0).then_some((k, m))
            })
            .collect();
        let mut links = Vec::new();
        for c in &model.constraints {
            let color = match c.kind {
                ConstraintKind::Distance { .. } => STRING,
                _ => ANCHOR,
            };
            links.push((c.frames, color));
        }
        for s in &model.springs {
            if let SpringKind::Frames(f) = s.kind {
                links.push((f, SPRING));
            }
        }
        for d in &model.dampers {
            links.push((d.frames, DAMPER));
        }
        let mut anchors: Vec<usize> = links
            .iter()
            .flat_map(|(f, _)| *f)
            .filter(|&k| !carries_mass[k])
            .collect();
        anchors.sort_unstable();
        anchors.dedup();
        Figure {
            bones,
            masses,
            links,
            anchors,
        }
    }
}

/// A pinhole camera looking at the scene's centre from the front left, a little above.
struct Camera {
    eye: [f64; 3],
    right: [f64; 3],
    up: [f64; 3],
    forward: [f64; 3],
    focal: f64,
}

fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}
fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}
fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}
fn unit(a: [f64; 3]) -> [f64; 3] {
    let n = dot(a, a).sqrt();
    [a[0] / n, a[1] / n, a[2] / n]
}

impl Camera {
    /// Frames the box `lo..hi` so that it fills about two thirds of the picture.
    fn framing(lo: [f64; 3], hi: [f64; 3]) -> Camera {
        let centre = [0, 1, 2].map(|i| 0.5 * (lo[i] + hi[i]));
        let extent = (0..3).map(|i| hi[i] - lo[i]).fold(1e-3, f64::max);
        let (azimuth, elevation) = (50f64.to_radians(), 20f64.to_radians());
        let distance = 2.5 * extent;
        let eye = [
            centre[0] + distance * elevation.cos() * azimuth.cos(),
            centre[1] + distance * elevation.cos() * azimuth.sin(),
            centre[2] + distance * elevation.sin(),
        ];
        let forward = unit(sub(centre, eye));
        let right = unit(cross(forward, [0.0, 0.0, 1.0]));
        let up = cross(right, forward);
        Camera {
            eye,
            right,
            up,
            forward,
            focal: 0.65 * SIZE.1 as f64 * distance / extent,
        }
    }

    /// Pixel coordinates and depth of a world point; `None` behind the camera.
    fn project(&self, p: [f64; 3]) -> Option<((i32, i32), f64)> {
        let d = sub(p, self.eye);
        let depth = dot(d, self.forward);
        if depth <= 1e-9 {
            return None;
        }
        let x = 0.5 * SIZE.0 as f64 + self.focal * dot(d, self.right) / depth;
        let y = 0.5 * SIZE.1 as f64 - self.focal * dot(d, self.up) / depth;
        let clamp = |v: f64| v.clamp(-1e5, 1e5) as i32;
        Some(((clamp(x), clamp(y)), depth))
    }
}

/// Writes the animation of the frame poses `frames` (one `Vec<Pose>` per picture, taken at
/// the times `times`) of `model` to `path`, played in real time: each picture shows for the
/// mean spacing of `times` (the samples a run records need not fall on a 1/FPS grid).
pub fn write_gif(
    model: &Model,
    times: &[f64],
    frames: &[Vec<Pose>],
    out: &OutputFile,
) -> Result<(), String> {
    let spacing = match times {
        [first, .., last] => (last - first) / (times.len() - 1) as f64,
        _ => 1.0 / FPS,
    };
    let delay_ms = (1000.0 * spacing).round() as u32;
    let err = |e: &dyn Sentence| {
        format!(
            "cannot write `{}`: {}",
            out.path().display(),
            drawing_error(e)
        )
    };
    let _ = register_font("sans-serif", FontStyle::Normal, FONT);
    let figure = Figure::of(model);
    let (mut lo, mut hi) = ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]);
    for pose in frames.iter().flatten() {
        for i in 0..3 {
            if pose.p[i].is_finite() {
                lo[i] = lo[i].min(pose.p[i]);
                hi[i] = hi[i].max(pose.p[i]);
            }
        }
    }
    if !lo[0].is_finite() {
        (lo, hi) = ([-1.0; 3], [1.0; 3]);
    }
    // The world origin (a pendulum's pivot) belongs in the picture too.
    for i in 0..3 {
        lo[i] = lo[i].min(0.0);
        hi[i] = hi[i].max(0.0);
    }
    let camera = Camera::framing(lo, hi);
    let root = BitMapBackend::gif(out.temp(), SIZE, delay_ms.max(10))
        .map_err(|e| err(&e))?
        .into_drawing_area();
    for (t, poses) in times.iter().zip(frames) {
        draw_frame(&root, &figure, &camera, lo, hi, model, *t, poses).map_err(|e| err(&e))?;
        root.present().map_err(|e| err(&e))?;
    }
    Ok(())
}

type Area<'a> = DrawingArea<BitMapBackend<'a>, Shift>;

#[allow(clippy::too_many_arguments)]
fn draw_frame(
    root: &Area,
    figure: &Figure,
    camera: &Camera,
    lo: [f64; 3],
    hi: [f64; 3],
    model: &Model,
    t: f64,
    poses: &[Pose],
) -> Result<(), String> {
    let e = drawing_error;
    root.fill(&WHITE).map_err(|x| e(&x))?;
    let line = |a: [f64; 3], b: [f64; 3], style: ShapeStyle| -> Result<(), String> {
        if let (Some((pa, _)), Some((pb, _))) = (camera.project(a), camera.project(b)) {
            root.draw(&PathElement::new(vec![pa, pb], style))
                .map_err(|x| e(&x))?;
        }
        Ok(())
    };
    // Floor grid just below the lowest point, a quarter of the extent wider than the scene.
    let extent = (0..3).map(|i| hi[i] - lo[i]).fold(1e-3, f64::max);
    let z = lo[2] - 0.02 * extent;
    let (x0, x1) = (lo[0] - 0.25 * extent, hi[0] + 0.25 * extent);
    let (y0, y1) = (lo[1] - 0.25 * extent, hi[1] + 0.25 * extent);
    for i in 0..=10 {
        let s = i as f64 / 10.0;
        let (x, y) = (x0 + s * (x1 - x0), y0 + s * (y1 - y0));
        line([x, y0, z], [x, y1, z], GRID.stroke_width(1))?;
        line([x0, y, z], [x1, y, z], GRID.stroke_width(1))?;
    }
    let origin = |k: Option<usize>| k.map_or([0.0; 3], |k| poses[k].p);
    for &(parent, child) in &figure.bones {
        line(origin(parent), origin(Some(child)), BONE.stroke_width(3))?;
    }
    for &(frames, color) in &figure.links {
        line(
            poses[frames[0]].p,
            poses[frames[1]].p,
            color.stroke_width(1),
        )?;
    }
    for &k in &figure.anchors {
        if let Some(((x, y), _)) = camera.project(poses[k].p) {
            root.draw(&Rectangle::new(
                [(x - 3, y - 3), (x + 3, y + 3)],
                ANCHOR.filled(),
            ))
            .map_err(|x| e(&x))?;
        }
    }
    // Masses far to near, so nearer dots cover farther ones.
    let heaviest = figure.masses.iter().map(|m| m.1).fold(0.0, f64::max);
    let mut dots: Vec<((i32, i32), f64, i32)> = figure
        .masses
        .iter()
        .filter_map(|&(k, m)| {
            let (at, depth) = camera.project(poses[k].p)?;
            let radius = 2.0 + 6.0 * (m / heaviest).cbrt();
            Some((at, depth, radius.round() as i32))
        })
        .collect();
    dots.sort_by(|a, b| b.1.total_cmp(&a.1));
    for (at, _, r) in dots {
        root.draw(&Circle::new(at, r, WOOD.filled()))
            .map_err(|x| e(&x))?;
        root.draw(&Circle::new(at, r, BLACK.stroke_width(1)))
            .map_err(|x| e(&x))?;
    }
    root.draw(&Text::new(
        format!("{}   t = {t:.2} s", model.name),
        (12, 12),
        ("sans-serif", 18).into_font(),
    ))
    .map_err(|x| e(&x))?;
    Ok(())
}
