//! The animation (`simulate --animate out.gif`): the figure in perspective — bones along the
//! rigid links, masses as dots sized by mass, strings and other elements as lines between
//! their frames, control points as small squares, a floor grid below — one GIF frame per
//! 1/25 s of simulated time.

use plotters::coord::Shift;
use plotters::prelude::*;

use plotters::style::{register_font, FontStyle};
use tree_mech::model::{tangents, ConstraintKind, Joint, Model, Rounded, SpringKind};
use tree_mech::runtime::{Pose, Seconds};

use super::bodies::{BodyBox, Rail};
use super::forces::Arrow;
use super::output::{drawing_error, OutputFile, Sentence};
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
    /// The bodies with a size, drawn as their equivalent boxes (the others as dots).
    boxes: Vec<BodyBox>,
}

const STRING: RGBColor = RGBColor(30, 30, 30);
const SPRING: RGBColor = RGBColor(20, 140, 60);
const DAMPER: RGBColor = RGBColor(40, 80, 200);
const BONE: RGBColor = RGBColor(90, 90, 100);
const WOOD: RGBColor = RGBColor(170, 110, 50);
const ANCHOR: RGBColor = RGBColor(200, 40, 40);
const GRID: RGBColor = RGBColor(215, 215, 220);
const RAIL: RGBColor = RGBColor(150, 150, 160);
const TARGET: RGBColor = RGBColor(220, 0, 120);
const GROUND: RGBColor = RGBColor(150, 120, 90);
const CONTACT: RGBColor = RGBColor(0, 150, 170);
/// Contact forces: a corner of the palette's colour cube, so drawn exactly.
const FORCE: RGBColor = RGBColor(255, 102, 0);

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
        for c in &model.contacts.strings {
            links.push((c.frames, STRING));
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
        let boxes = (0..n)
            .filter_map(|k| BodyBox::of(k, model.frames[k].mass.as_ref()?))
            .collect();
        Figure {
            bones,
            masses,
            links,
            anchors,
            boxes,
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
    /// Frames the box `lo..hi` so that it fills most of the picture: its width (the box's
    /// diagonal across) against the picture's width, its height (with the depth seen from
    /// above) against the picture's height, whichever is tighter.
    fn framing(lo: [f64; 3], hi: [f64; 3]) -> Camera {
        let centre = [0, 1, 2].map(|i| 0.5 * (lo[i] + hi[i]));
        let extent = (0..3).map(|i| hi[i] - lo[i]).fold(1e-3, f64::max);
        let (azimuth, elevation) = (50f64.to_radians(), 20f64.to_radians());
        let distance = 2.5 * extent;
        let across = (hi[0] - lo[0]).hypot(hi[1] - lo[1]).max(1e-3);
        let tall = (hi[2] - lo[2] + elevation.sin() * across).max(1e-3);
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
            focal: distance * f64::min(0.85 * SIZE.0 as f64 / across, 0.8 * SIZE.1 as f64 / tall),
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
    /// Fixed on the whole run: every body, control point and target at every picture is in
    /// view, on a floor under the lowest point the run reaches.
    #[default]
    Fixed,
    /// Following the root (the first rotating frame: a free body's torso), at the scale that
    /// keeps the bodies around it in view; the floor grid slides by under the view and the
    /// caption gives the root's height.
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

/// What the camera frames over a run: a box fixed in the world around everything the run
/// shows, or, tracking, a box around the root holding everything the run shows about it.
struct View {
    lo: [f64; 3],
    hi: [f64; 3],
    mode: CameraMode,
    root: usize,
}

impl View {
    /// The box around what is drawn — the bodies (their boxes), the bones, the control points —
    /// and the targets (fixed) over all of `frames`, or around the root (tracking); non-finite
    /// positions are left out (a floating base's massless translation frames are not drawn,
    /// and stay at the ground while the body falls).
    fn of(
        figure: &Figure,
        model: &Model,
        frames: &[Vec<Pose>],
        targets: &[[f64; 3]],
        mode: CameraMode,
    ) -> View {
        let root = root_frame(model);
        let (mut lo, mut hi) = ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]);
        let mut take = |p: [f64; 3], shift: [f64; 3]| {
            if p.iter().chain(&shift).all(|x| x.is_finite()) {
                for i in 0..3 {
                    lo[i] = lo[i].min(p[i] - shift[i]);
                    hi[i] = hi[i].max(p[i] - shift[i]);
                }
            }
        };
        for poses in frames {
            let shift = match mode {
                CameraMode::Fixed => [0.0; 3],
                CameraMode::Track => poses[root].p,
            };
            let bones = figure
                .bones
                .iter()
                .flat_map(|&(a, b)| a.into_iter().chain([b]));
            let masses = figure.masses.iter().map(|m| m.0);
            for k in bones.chain(masses).chain(figure.anchors.iter().copied()) {
                take(poses[k].p, shift);
            }
            for body in &figure.boxes {
                body.corners(&poses[body.frame])
                    .into_iter()
                    .for_each(|p| take(p, shift));
            }
        }
        if mode == CameraMode::Fixed {
            targets.iter().for_each(|&p| take(p, [0.0; 3]));
        }
        if lo[0] > hi[0] {
            (lo, hi) = ([0.0; 3], [0.0; 3]);
        }
        View { lo, hi, mode, root }
    }

    /// The box the picture of `poses` frames.
    fn at(&self, poses: &[Pose]) -> ([f64; 3], [f64; 3]) {
        let shift = match self.mode {
            CameraMode::Track if poses[self.root].p.iter().all(|x| x.is_finite()) => {
                poses[self.root].p
            }
            _ => [0.0; 3],
        };
        (
            [0, 1, 2].map(|i| self.lo[i] + shift[i]),
            [0, 1, 2].map(|i| self.hi[i] + shift[i]),
        )
    }
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
    overlay: &Overlay,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<(), String> {
    let targets = overlay.targets;
    let spacing = match times {
        [first, .., last] => (last - first) / (times.len() - 1) as f64,
        _ => 1.0 / FPS,
    };
    let delay = ((100.0 * spacing).round() as u16).max(1);
    let err =
        |e: &dyn Sentence| format!("cannot write `{}`: {}", out.path().display(), e.sentence());
    let _ = register_font("sans-serif", FontStyle::Normal, FONT);
    let figure = Figure::of(model);
    if frames.is_empty() {
        return Ok(());
    }
    let view = View::of(&figure, model, frames, targets, mode);
    let rails = Rail::of(model, frames);
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
    let largest_force = overlay.largest_force();
    let picture = |k: usize| -> Result<gif::Frame<'static>, String> {
        let (lo, hi) = view.at(&frames[k]);
        let camera = Camera::framing(lo, hi);
        let scene = Scene {
            figure: &figure,
            camera: &camera,
            lo,
            hi,
            rails: &rails,
            targets,
            root: (mode == CameraMode::Track).then_some(view.root),
            model,
            arrows: overlay.arrows.get(k).map_or(&[], |a| a.as_slice()),
            largest_force,
        };
        let rgb = render(&scene, times[k], &frames[k])?;
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

/// One picture of `scene` at `t` with the frames at `poses`, as RGB bytes.
fn render(scene: &Scene, t: f64, poses: &[Pose]) -> Result<Vec<u8>, String> {
    let mut rgb = vec![255u8; 3 * (SIZE.0 * SIZE.1) as usize];
    {
        let area = BitMapBackend::with_buffer(&mut rgb, SIZE).into_drawing_area();
        draw_frame(&area, scene, t, poses)?;
        area.present().map_err(|e| drawing_error(&e))?;
    }
    Ok(rgb)
}

/// The GIF's one palette: the figure's own colours exactly, then a 6×6×6 colour cube and a
/// ramp of greys for everything between (anti-aliased text).
const NAMED: [RGBColor; 13] = [
    WHITE, BLACK, STRING, SPRING, DAMPER, BONE, WOOD, ANCHOR, GRID, RAIL, TARGET, GROUND, CONTACT,
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

/// What an animation draws beyond the model: the points a task aims for, and each picture's
/// contact forces (`--forces`; none when empty).
#[derive(Default)]
pub struct Overlay<'a> {
    pub targets: &'a [[f64; 3]],
    pub arrows: &'a [Vec<Arrow>],
}

impl Overlay<'_> {
    /// The largest force over the run: the arrows' common scale.
    fn largest_force(&self) -> f64 {
        (self.arrows.iter().flatten())
            .map(|a| dot(a.force, a.force).sqrt())
            .fold(0.0, f64::max)
    }
}

/// What every picture of one animation shares.
struct Scene<'a> {
    figure: &'a Figure,
    camera: &'a Camera,
    /// The box in view (its bottom is the floor's height).
    lo: [f64; 3],
    hi: [f64; 3],
    rails: &'a [Rail],
    /// Points the run aims for (a task's frame targets), marked.
    targets: &'a [[f64; 3]],
    /// The frame a tracking camera follows (its height is captioned).
    root: Option<usize>,
    model: &'a Model,
    /// This picture's contact forces, and the run's largest (drawn a quarter of the view).
    arrows: &'a [Arrow],
    largest_force: f64,
}

type Area<'a> = DrawingArea<BitMapBackend<'a>, Shift>;

/// One picture: the floor, the rails, the bones and the elements' lines, the control points,
/// the bodies (boxes where they have a size, dots where not), the targets and the caption.
fn draw_frame(root: &Area, scene: &Scene, t: f64, poses: &[Pose]) -> Result<(), String> {
    let e = drawing_error;
    root.fill(&WHITE).map_err(|x| e(&x))?;
    let line = |a: [f64; 3], b: [f64; 3], style: ShapeStyle| -> Result<(), String> {
        if let (Some((pa, _)), Some((pb, _))) = (scene.camera.project(a), scene.camera.project(b)) {
            root.draw(&PathElement::new(vec![pa, pb], style))
                .map_err(|x| e(&x))?;
        }
        Ok(())
    };
    draw_floor(scene, &line)?;
    let figure = scene.figure;
    for rail in scene.rails {
        let [a, b] = rail.ends(poses);
        line(a, b, RAIL.stroke_width(4))?;
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
        if let Some(((x, y), _)) = scene.camera.project(poses[k].p) {
            root.draw(&Rectangle::new(
                [(x - 3, y - 3), (x + 3, y + 3)],
                ANCHOR.filled(),
            ))
            .map_err(|x| e(&x))?;
        }
    }
    for body in &figure.boxes {
        let corners = body.corners(&poses[body.frame]);
        for (a, b) in BodyBox::EDGES {
            line(corners[a], corners[b], WOOD.stroke_width(2))?;
        }
    }
    draw_dots(root, scene, poses)?;
    draw_spheres(root, scene, poses)?;
    let extent = (0..3)
        .map(|i| scene.hi[i] - scene.lo[i])
        .fold(1e-3, f64::max);
    draw_arrows(scene, extent, &line)?;
    for &p in scene.targets {
        let arm = 0.04 * extent;
        for i in 0..3 {
            let (mut a, mut b) = (p, p);
            a[i] -= arm;
            b[i] += arm;
            line(a, b, TARGET.stroke_width(2))?;
        }
    }
    let mut caption = format!("{}   t = {} s", scene.model.name, caption_time(t));
    if let Some(k) = scene.root {
        let z = poses[k].p[2];
        caption += &format!(
            "   {} at z = {} m",
            scene.model.frames[k].name,
            Rounded(z, 3)
        );
    }
    root.draw(&Text::new(
        caption,
        (12, 12),
        ("sans-serif", 18).into_font(),
    ))
    .map_err(|x| e(&x))?;
    Ok(())
}

/// A floor grid at the bottom of the view, fixed in the world: its lines on multiples of a
/// tenth of the view, so a tracking camera sees it slide by. A model's ground is drawn
/// instead, in its own plane and colour.
fn draw_floor(
    scene: &Scene,
    line: &dyn Fn([f64; 3], [f64; 3], ShapeStyle) -> Result<(), String>,
) -> Result<(), String> {
    let (lo, hi) = (scene.lo, scene.hi);
    let extent = (0..3).map(|i| hi[i] - lo[i]).fold(1e-3, f64::max);
    let cell = extent / 10.0;
    if let Some(ground) = scene.model.contacts.ground {
        return draw_ground(&ground, lo, hi, cell, line);
    }
    let z = lo[2] - 0.02 * extent;
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
    Ok(())
}

/// The ground's plane `n·x = height` as a grid of lines `cell` apart, about the view's centre
/// set down onto it, a quarter of the view beyond it each way.
fn draw_ground(
    ground: &tree_mech::model::Ground,
    lo: [f64; 3],
    hi: [f64; 3],
    cell: f64,
    line: &dyn Fn([f64; 3], [f64; 3], ShapeStyle) -> Result<(), String>,
) -> Result<(), String> {
    let n = ground.normal;
    let [t1, t2] = tangents(&n);
    let centre = [0, 1, 2].map(|i| 0.5 * (lo[i] + hi[i]));
    let lift = dot(centre, n) - ground.height;
    let on = [0, 1, 2].map(|i| centre[i] - lift * n[i]);
    let half = 0.75 * (0..3).map(|i| hi[i] - lo[i]).fold(1e-3, f64::max);
    let steps = (half / cell).floor() as i64;
    let at = |a: f64, b: f64| [0, 1, 2].map(|i| on[i] + a * t1[i] + b * t2[i]);
    for k in -steps..=steps {
        let x = k as f64 * cell;
        line(at(x, -half), at(x, half), GROUND.stroke_width(1))?;
        line(at(-half, x), at(half, x), GROUND.stroke_width(1))?;
    }
    Ok(())
}

/// The contact spheres as circles of their radius at their frames (a point as a small
/// cross-less ring).
fn draw_spheres(root: &Area, scene: &Scene, poses: &[Pose]) -> Result<(), String> {
    for sphere in &scene.model.contacts.spheres {
        let p = poses[sphere.frame].p;
        let Some((at, depth)) = scene.camera.project(p) else {
            continue;
        };
        let r = (scene.camera.focal * sphere.radius / depth)
            .round()
            .max(2.0) as i32;
        root.draw(&Circle::new(at, r, CONTACT.stroke_width(2)))
            .map_err(|x| drawing_error(&x))?;
    }
    Ok(())
}

/// The contact forces as arrows from their points, the run's largest a quarter of the view
/// (`extent`) long, each with a head of two strokes.
fn draw_arrows(
    scene: &Scene,
    extent: f64,
    line: &dyn Fn([f64; 3], [f64; 3], ShapeStyle) -> Result<(), String>,
) -> Result<(), String> {
    if scene.largest_force <= 0.0 {
        return Ok(());
    }
    let scale = 0.25 * extent / scene.largest_force;
    for a in scene.arrows {
        let v = a.force.map(|x| scale * x);
        let length = dot(v, v).sqrt();
        if length < 1e-3 * extent {
            continue;
        }
        let tip = [0, 1, 2].map(|i| a.at[i] + v[i]);
        line(a.at, tip, FORCE.stroke_width(3))?;
        // The head: two strokes back from the tip, in a plane holding the arrow.
        let back = v.map(|x| -0.25 * x);
        let [side, _] = tangents(&unit(v));
        for s in [-1.0, 1.0] {
            let end = [0, 1, 2].map(|i| tip[i] + back[i] + s * 0.12 * length * side[i]);
            line(tip, end, FORCE.stroke_width(3))?;
        }
    }
    Ok(())
}

/// The point masses (bodies without a size) as dots sized by mass, far to near so nearer
/// dots cover farther ones.
fn draw_dots(root: &Area, scene: &Scene, poses: &[Pose]) -> Result<(), String> {
    let figure = scene.figure;
    let sized: Vec<usize> = figure.boxes.iter().map(|b| b.frame).collect();
    let heaviest = figure.masses.iter().map(|m| m.1).fold(0.0, f64::max);
    let mut dots: Vec<((i32, i32), f64, i32)> = figure
        .masses
        .iter()
        .filter(|(k, _)| !sized.contains(k))
        .filter_map(|&(k, m)| {
            let (at, depth) = scene.camera.project(poses[k].p)?;
            let radius = 2.0 + 6.0 * (m / heaviest).cbrt();
            Some((at, depth, radius.round() as i32))
        })
        .collect();
    dots.sort_by(|a, b| b.1.total_cmp(&a.1));
    for (at, _, r) in dots {
        root.draw(&Circle::new(at, r, WOOD.filled()))
            .map_err(|x| drawing_error(&x))?;
        root.draw(&Circle::new(at, r, BLACK.stroke_width(1)))
            .map_err(|x| drawing_error(&x))?;
    }
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
    use super::*;
    use tree_mech::integrate::{simulate, Method, SimOptions, ViSettings};
    use tree_mech::nalgebra::Dyn;
    use tree_mech::runtime::Vector;
    use tree_mech::{NoForce, System, TreeSystem};

    /// The humanoid's poses over a 2 s fall (19 m: no floor stops it), 21 pictures.
    fn falling_humanoid() -> (Model, Vec<Vec<Pose>>) {
        let path = concat!(env!("CARGO_MANIFEST_DIR"), "/models/humanoid.toml");
        let model = tree_mech::model::from_toml_file(path).unwrap();
        let mut sys = TreeSystem::new(&model).unwrap();
        let (q0, dq0) = sys.initial_state();
        let options = SimOptions::new(Method::Vi(ViSettings::default()), 0.01, 2.0);
        let traj = simulate(&mut sys, &q0, &dq0, &options, &mut NoForce, &mut |_| {}).unwrap();
        let pictures = (0..traj.len())
            .step_by(10)
            .map(|k| {
                let mut poses = vec![Pose::IDENTITY; sys.frame_count()];
                sys.poses(&Vector::<Dyn>::from_column_slice(traj.q(k)), &mut poses);
                poses
            })
            .collect();
        (model, pictures)
    }

    #[test]
    fn every_body_stays_in_the_picture_with_either_camera() {
        let (model, pictures) = falling_humanoid();
        let figure = Figure::of(&model);
        assert!(figure.boxes.len() > 5, "the humanoid's links have sizes");
        let target = [[0.5, 0.0, 2.0]];
        for mode in [CameraMode::Fixed, CameraMode::Track] {
            let view = View::of(&figure, &model, &pictures, &target, mode);
            let mut filled = 0.0f64;
            for poses in &pictures {
                let (lo, hi) = view.at(poses);
                let camera = Camera::framing(lo, hi);
                let mut points: Vec<[f64; 3]> =
                    figure.masses.iter().map(|m| poses[m.0].p).collect();
                for body in &figure.boxes {
                    points.extend(body.corners(&poses[body.frame]));
                }
                if mode == CameraMode::Fixed {
                    points.extend(target);
                }
                let (mut top, mut bottom) = (f64::MAX, f64::MIN);
                for p in points {
                    let ((x, y), _) = camera.project(p).unwrap();
                    assert!((0..SIZE.0 as i32).contains(&x), "{mode:?}: x = {x}");
                    assert!((0..SIZE.1 as i32).contains(&y), "{mode:?}: y = {y}");
                    (top, bottom) = (top.min(y as f64), bottom.max(y as f64));
                }
                filled = filled.max((bottom - top) / SIZE.1 as f64);
            }
            if mode == CameraMode::Track {
                // Following it, the camera keeps the body large: most of the picture's height.
                assert!(filled > 0.5, "the body fills {filled} of the height");
            }
        }
    }

    /// One picture of the model at `path` (from the repository's root) in its start pose, or
    /// with `z` its third variable, with `arrows` for its contact forces (`impulse` of its
    /// unilateral rows): how many pixels have each of `colours`.
    fn pixels(path: &str, z: Option<f64>, impulse: &[f64], colours: &[RGBColor]) -> Vec<usize> {
        let _ = register_font("sans-serif", FontStyle::Normal, FONT);
        let path = format!("{}/{path}", env!("CARGO_MANIFEST_DIR"));
        let model = tree_mech::model::from_toml_file(path).unwrap();
        let mut sys = TreeSystem::new(&model).unwrap();
        let (mut q0, _) = sys.initial_state();
        if let Some(z) = z {
            q0[2] = z;
        }
        let mut poses = vec![Pose::IDENTITY; sys.frame_count()];
        sys.poses(&q0, &mut poses);
        let arrows = crate::cli::forces::arrows(&model, &poses, impulse);
        let overlay = Overlay {
            arrows: std::slice::from_ref(&arrows),
            ..Default::default()
        };
        let figure = Figure::of(&model);
        let frames = vec![poses.clone()];
        let view = View::of(&figure, &model, &frames, &[], CameraMode::Fixed);
        let (lo, hi) = view.at(&poses);
        let camera = Camera::framing(lo, hi);
        let scene = Scene {
            figure: &figure,
            camera: &camera,
            lo,
            hi,
            rails: &[],
            targets: &[],
            root: None,
            model: &model,
            arrows: &arrows,
            largest_force: overlay.largest_force(),
        };
        let rgb = render(&scene, 0.0, &poses).unwrap();
        (colours.iter())
            .map(|c| {
                (rgb.chunks_exact(3))
                    .filter(|p| *p == [c.0, c.1, c.2])
                    .count()
            })
            .collect()
    }

    /// A model's ground is drawn as a grid in its own colour and its contact spheres as rings;
    /// without them, neither colour appears.
    #[test]
    fn the_ground_and_the_contact_spheres_are_drawn() {
        let count = |path: &str| pixels(path, None, &[], &[GROUND, CONTACT]);
        let floor = count("models/marionette-floor.toml");
        assert!(
            floor[0] > 50 && floor[1] > 100,
            "ground and rings {floor:?} px"
        );
        assert_eq!(count("models/marionette.toml"), [0, 0]);
    }

    /// `--forces`: the ball resting on the ground with an impulse draws an arrow in the
    /// force colour; with no impulse, none.
    #[test]
    fn contact_forces_are_drawn_as_arrows() {
        let count =
            |impulse: [f64; 3]| pixels("tests/models/ball.toml", Some(0.1), &impulse, &[FORCE])[0];
        let drawn = count([9.81e-3, 0.0, 0.0]);
        assert!(drawn > 30, "{drawn} px of arrow");
        assert_eq!(count([0.0; 3]), 0);
    }

    #[test]
    fn the_caption_time_is_short_at_any_size() {
        assert_eq!(caption_time(0.125), "0.12");
        assert_eq!(caption_time(12.0), "12.00");
        assert_eq!(caption_time(1e300), "1e300");
        assert_eq!(caption_time(2.5e9), "2.5e9");
    }
}
