//! The animation (`simulate --animate out.gif`): the figure in perspective — bones along the
//! rigid links, masses as dots sized by mass, strings and other elements as lines between
//! their frames, control points as small squares, a floor grid below — one GIF frame per
//! 1/25 s of simulated time.

use plotters::coord::Shift;
use plotters::prelude::*;

use super::output::{drawing_error, OutputFile, Sentence};
use plotters::style::{register_font, FontStyle};
use tree_mech::model::{ConstraintKind, Joint, Model, SpringKind};
use tree_mech::runtime::{Pose, Seconds};

use super::plot::FONT;

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

/// Where the camera looks.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum CameraMode {
    /// Fixed on the start's workspace: everything at the start, and the ball around the root
    /// its masses can swing through (a swinging arm stays in view; a falling body leaves it).
    #[default]
    Fixed,
    /// The same scale, following the root (the first rotating frame: a free body's torso).
    Track,
}

/// The frame the camera centres on: the first rotating frame (past a floating base's
/// translations), or the first frame.
fn root_frame(model: &Model) -> usize {
    model
        .frames
        .iter()
        .position(|f| f.primitive.is_rotation())
        .unwrap_or(0)
}

/// Writes the animation of the frame poses `frames` (one `Vec<Pose>` per picture, taken at
/// the times `times`) of `model` to `out`, played in real time: each picture shows for the
/// mean spacing of `times` (the samples a run records need not fall on a 1/FPS grid).
/// Pictures are drawn and compressed on every core, a fixed palette (the figure's colours,
/// a colour cube and greys) instead of a per-picture quantisation; `progress` hears of each
/// picture written.
pub fn write_gif(
    model: &Model,
    times: &[f64],
    frames: &[Vec<Pose>],
    out: &OutputFile,
    mode: CameraMode,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<(), String> {
    let spacing = match times {
        [first, .., last] => (last - first) / (times.len() - 1) as f64,
        _ => 1.0 / FPS,
    };
    let delay = ((100.0 * spacing).round() as u16).max(1);
    let err =
        |e: &dyn Sentence| format!("cannot write `{}`: {}", out.path().display(), e.sentence());
    let _ = register_font("sans-serif", FontStyle::Normal, FONT);
    let figure = Figure::of(model);
    let Some(start) = frames.first() else {
        return Ok(());
    };
    // The start's workspace: every frame at the start, and the ball around the root with
    // its farthest mass on the rim.
    let root = root_frame(model);
    let centre = start[root].p;
    let finite = |p: &&Pose| p.p.iter().all(|x| x.is_finite());
    let reach = figure
        .masses
        .iter()
        .map(|&(k, _)| &start[k])
        .filter(finite)
        .map(|p| dot(sub(p.p, centre), sub(p.p, centre)).sqrt())
        .fold(1e-3, f64::max);
    let (mut lo0, mut hi0) = (centre.map(|x| x - reach), centre.map(|x| x + reach));
    for p in start.iter().filter(finite) {
        for i in 0..3 {
            lo0[i] = lo0[i].min(p.p[i]);
            hi0[i] = hi0[i].max(p.p[i]);
        }
    }
    let floor = lo0[2];
    let file = std::fs::File::create(out.temp()).map_err(|e| err(&e.to_string()))?;
    let mut encoder = gif::Encoder::new(
        std::io::BufWriter::new(file),
        SIZE.0 as u16,
        SIZE.1 as u16,
        &palette(),
    )
    .map_err(|e| err(&e.to_string()))?;
    encoder
        .set_repeat(gif::Repeat::Infinite)
        .map_err(|e| err(&e.to_string()))?;
    let threads = std::thread::available_parallelism()
        .map_or(1, |n| n.get())
        .clamp(1, 8);
    let picture = |k: usize| -> Result<gif::Frame<'static>, String> {
        let shift = match mode {
            CameraMode::Fixed => [0.0; 3],
            CameraMode::Track => sub(frames[k][root].p, centre),
        };
        let (lo, hi) = (
            [0, 1, 2].map(|i| lo0[i] + shift[i]),
            [0, 1, 2].map(|i| hi0[i] + shift[i]),
        );
        let camera = Camera::framing(lo, hi);
        let mut rgb = vec![255u8; 3 * (SIZE.0 * SIZE.1) as usize];
        {
            let area = BitMapBackend::with_buffer(&mut rgb, SIZE).into_drawing_area();
            let scene = Scene {
                figure: &figure,
                camera: &camera,
                lo,
                hi,
                floor,
                model,
            };
            draw_frame(&area, &scene, times[k], &frames[k])?;
            area.present().map_err(|e| drawing_error(&e))?;
        }
        let indices: Vec<u8> = rgb
            .chunks_exact(3)
            .map(|p| palette_index([p[0], p[1], p[2]]))
            .collect();
        let mut frame =
            gif::Frame::from_indexed_pixels(SIZE.0 as u16, SIZE.1 as u16, &indices, None);
        frame.delay = delay;
        frame.make_lzw_pre_encoded();
        Ok(frame)
    };
    // A batch of pictures at a time, split over the threads, written in order.
    let batch = 4 * threads;
    for first in (0..frames.len()).step_by(batch) {
        let last = (first + batch).min(frames.len());
        let mut done: Vec<Option<Result<gif::Frame<'static>, String>>> =
            (first..last).map(|_| None).collect();
        std::thread::scope(|s| {
            for (t, slots) in done.chunks_mut(batch.div_ceil(threads)).enumerate() {
                let picture = &picture;
                let begin = first + t * batch.div_ceil(threads);
                s.spawn(move || {
                    for (j, slot) in slots.iter_mut().enumerate() {
                        *slot = Some(picture(begin + j));
                    }
                });
            }
        });
        for (j, frame) in done.into_iter().enumerate() {
            let frame = frame.unwrap_or_else(|| Err("a picture was not drawn".into()))?;
            encoder
                .write_lzw_pre_encoded_frame(&frame)
                .map_err(|e| err(&e.to_string()))?;
            progress(first + j + 1, frames.len());
        }
    }
    encoder
        .into_inner()
        .and_then(|mut w| std::io::Write::flush(&mut w))
        .map_err(|e| err(&e.to_string()))?;
    Ok(())
}

/// The GIF's one palette: the figure's own colours exactly, then a 6×6×6 colour cube and a
/// ramp of greys for everything between (anti-aliased text).
const NAMED: [RGBColor; 9] = [
    WHITE, BLACK, STRING, SPRING, DAMPER, BONE, WOOD, ANCHOR, GRID,
];
const GREYS: usize = 256 - NAMED.len() - 216;

fn palette() -> Vec<u8> {
    let mut p = Vec::with_capacity(768);
    for c in NAMED {
        p.extend([c.0, c.1, c.2]);
    }
    for r in 0..6u8 {
        for g in 0..6u8 {
            for b in 0..6u8 {
                p.extend([r * 51, g * 51, b * 51]);
            }
        }
    }
    for k in 0..GREYS {
        let v = (255 * k / (GREYS - 1)) as u8;
        p.extend([v, v, v]);
    }
    p
}

/// A pixel's palette entry: a figure colour exactly, a grey to the nearest grey, anything
/// else to the nearest corner of the colour cube.
fn palette_index(c: [u8; 3]) -> u8 {
    if let Some(k) = NAMED.iter().position(|n| [n.0, n.1, n.2] == c) {
        return k as u8;
    }
    if c[0] == c[1] && c[1] == c[2] {
        let k = (c[0] as usize * (GREYS - 1) + 127) / 255;
        return (NAMED.len() + 216 + k) as u8;
    }
    let q = |x: u8| (x as usize + 25) / 51;
    (NAMED.len() + 36 * q(c[0]) + 6 * q(c[1]) + q(c[2])) as u8
}

/// What every picture of one animation shares.
struct Scene<'a> {
    figure: &'a Figure,
    camera: &'a Camera,
    lo: [f64; 3],
    hi: [f64; 3],
    /// The floor's height (world-fixed: the start's lowest point).
    floor: f64,
    model: &'a Model,
}

type Area<'a> = DrawingArea<BitMapBackend<'a>, Shift>;

fn draw_frame(root: &Area, scene: &Scene, t: f64, poses: &[Pose]) -> Result<(), String> {
    let Scene {
        figure,
        camera,
        lo,
        hi,
        floor,
        model,
    } = *scene;
    let e = drawing_error;
    root.fill(&WHITE).map_err(|x| e(&x))?;
    let line = |a: [f64; 3], b: [f64; 3], style: ShapeStyle| -> Result<(), String> {
        if let (Some((pa, _)), Some((pb, _))) = (camera.project(a), camera.project(b)) {
            root.draw(&PathElement::new(vec![pa, pb], style))
                .map_err(|x| e(&x))?;
        }
        Ok(())
    };
    // A floor grid fixed in the world under the start's lowest point, its lines on
    // multiples of a tenth of the view (so a tracking camera sees it slide by).
    let extent = (0..3).map(|i| hi[i] - lo[i]).fold(1e-3, f64::max);
    let cell = extent / 10.0;
    let z = floor - 0.02 * extent;
    let (x0, x1) = (lo[0] - 0.25 * extent, hi[0] + 0.25 * extent);
    let (y0, y1) = (lo[1] - 0.25 * extent, hi[1] + 0.25 * extent);
    for i in (x0 / cell).ceil() as i64..=(x1 / cell).floor() as i64 {
        let x = i as f64 * cell;
        line([x, y0, z], [x, y1, z], GRID.stroke_width(1))?;
    }
    for i in (y0 / cell).ceil() as i64..=(y1 / cell).floor() as i64 {
        let y = i as f64 * cell;
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
        format!("{}   t = {} s", model.name, caption_time(t)),
        (12, 12),
        ("sans-serif", 18).into_font(),
    ))
    .map_err(|x| e(&x))?;
    Ok(())
}

/// The caption's time: two decimals, steady from frame to frame; past a million seconds as
/// the messages print times (never hundreds of digits across the picture).
fn caption_time(t: f64) -> String {
    if t.abs() < 1e6 {
        format!("{t:.2}")
    } else {
        Seconds(t).to_string()
    }
}

#[cfg(test)]
mod tests {
    use super::caption_time;

    #[test]
    fn the_caption_time_is_short_at_any_size() {
        assert_eq!(caption_time(0.125), "0.12");
        assert_eq!(caption_time(12.0), "12.00");
        assert_eq!(caption_time(1e300), "1e300");
        assert_eq!(caption_time(2.5e9), "2.5e9");
    }
}
