//! Optimal-control task files (README, "Optimal control"): what to optimise on which model —
//! horizon, integrator, controls, start, running and terminal cost terms, limits — read from
//! TOML with source spans and resolved against the model, so every problem names its line.
//! The numbers are the runtime's business (`tree_control`); this module only says
//! what was asked, with names turned into indices.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use serde::Deserialize;
use toml::{Spanned, Value};

use crate::contact::GapKind;
use crate::error::{ModelError, Problem, Site};
use crate::model::Model;
use crate::source::LineIndex;
use crate::toml_format::{toml_error, with_written_contacts, RawContact, RawGround};
use crate::urdf_format::{from_file, UrdfOptions};

/// The integrator a task steps with: `vi` (the default, on `(q_d, p_d)`) or `rk4` (on
/// `(q_d, q̇_d)`); a task file refuses `rk45`.
pub type TaskIntegrator = crate::Integrator;

/// One decision per knot.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Control {
    /// Input `k` of the model: a generalized force held over the step.
    Input(usize),
    /// Kinematic variable `i`: its value at the knot's end becomes a decision (trep's ρ).
    Kinematic(usize),
}

/// What a `control` term measures the controls from.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum About {
    /// `u − g(q)`: the inputs that would hold the knot's configuration at rest (default).
    #[default]
    Gravity,
    /// `u`: the controls themselves.
    Zero,
}

/// Where a `frame` term wants its frame's origin.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Target {
    /// A point in the world.
    World([f64; 3]),
    /// An offset from the frame's position at the start.
    Offset([f64; 3]),
}

/// One cost term `½ w |r|²` (running terms are summed as `Σ_{k<N} Δt ℓ`).
#[derive(Clone, Debug, PartialEq)]
pub enum CostTerm {
    /// `r = (q − q_ref, q̇ − q̇_ref)` over every variable (per-variable weights).
    State {
        /// `q_ref` (default: the start).
        q_ref: Vec<f64>,
        /// `q̇_ref` (default: the start).
        dq_ref: Vec<f64>,
        /// Weights on `q`.
        q_weight: Vec<f64>,
        /// Weights on `q̇`.
        dq_weight: Vec<f64>,
    },
    /// `r = u − g(q)` or `u` on inputs; `value − start value` on kinematic controls.
    Control {
        /// Per control.
        weight: Vec<f64>,
        /// What the inputs are measured from.
        about: About,
    },
    /// `r = (v_k − v_{k−1})/Δt` per control.
    ControlRate {
        /// Per control.
        weight: Vec<f64>,
    },
    /// `r = p_frame(q) − target`.
    Frame {
        /// The frame's index.
        frame: usize,
        /// Where it should be.
        target: Target,
        /// Per axis x, y, z.
        weight: [f64; 3],
    },
    /// `r = log(R_targetᵀ R_frame)` (the rotation vector from target to frame).
    Orientation {
        /// The frame's index.
        frame: usize,
        /// `R_target` (None: the frame's orientation at the start).
        target: Option<[[f64; 3]; 3]>,
        /// Per axis of the rotation vector.
        weight: [f64; 3],
    },
}

impl CostTerm {
    /// The frame a term names, if any.
    pub fn frame(&self) -> Option<usize> {
        match self {
            CostTerm::Frame { frame, .. } | CostTerm::Orientation { frame, .. } => Some(*frame),
            _ => None,
        }
    }
}

/// Which optimiser a task asks for.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum TaskSolver {
    /// iLQR (default).
    #[default]
    Ilqr,
    /// DDP (the VI's contracted second derivatives).
    Ddp,
}

/// A task resolved against its model.
#[derive(Clone, Debug, PartialEq)]
pub struct Task {
    /// The model file, as the task names it, resolved against the task's directory.
    pub model_path: PathBuf,
    /// Whether the model (a URDF) gets a floating base.
    pub floating_base: bool,
    /// The step length.
    pub dt: f64,
    /// Steps `N` (horizon `N Δt`).
    pub knots: usize,
    /// The discretisation.
    pub integrator: TaskIntegrator,
    /// The solver the file asks for (the CLI may override).
    pub solver: TaskSolver,
    /// The iteration limit the file asks for.
    pub max_iterations: Option<usize>,
    /// The decisions per knot, in order.
    pub controls: Vec<Control>,
    /// Start configuration (every variable).
    pub q0: Vec<f64>,
    /// Start velocity (every variable).
    pub dq0: Vec<f64>,
    /// Running terms.
    pub running: Vec<CostTerm>,
    /// Terminal terms.
    pub terminal: Vec<CostTerm>,
    /// Box limits per control (`None`: unbounded). Inputs default to the model's limits.
    pub limits: Vec<Option<[f64; 2]>>,
    /// The line of each control's limits (for errors found later, e.g. a start outside
    /// them), or of `controls`.
    pub limit_lines: Vec<Option<usize>>,
    /// The contacts' relaxations `κ` the optimiser goes through, largest first (each solve
    /// warm-starts the next; the plan is the last one's): empty when the model has no
    /// unilateral rows (docs/derivations.md §14).
    pub kappa: Vec<f64>,
}

impl Task {
    /// Whether a running `control_rate` term differences an input against its previous value
    /// (so the optimiser's state must remember the inputs).
    pub fn reads_previous_inputs(&self) -> bool {
        self.running
            .iter()
            .any(|t| matches!(t, CostTerm::ControlRate { .. }))
            && self.controls.iter().any(|c| matches!(c, Control::Input(_)))
    }

    /// The name of control `c` (an input's or a kinematic variable's).
    pub fn control_name<'m>(&self, model: &'m Model, c: usize) -> &'m str {
        match self.controls[c] {
            Control::Input(k) => &model.inputs[k].name,
            Control::Kinematic(i) => &model.variables[i].name,
        }
    }
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawTask {
    model: Spanned<String>,
    floating_base: Option<bool>,
    dt: Spanned<f64>,
    knots: Spanned<i64>,
    integrator: Option<Spanned<String>>,
    solver: Option<Spanned<String>>,
    max_iterations: Option<Spanned<i64>>,
    controls: Option<Spanned<Vec<Spanned<String>>>>,
    start: Option<RawStart>,
    #[serde(default)]
    cost: Vec<Spanned<RawCost>>,
    #[serde(default)]
    terminal: Vec<Spanned<RawCost>>,
    model_limits: Option<bool>,
    limits: Option<BTreeMap<String, Spanned<Vec<f64>>>>,
    kappa: Option<Spanned<Value>>,
    enforce_limits: Option<bool>,
    ground: Option<Spanned<RawGround>>,
    #[serde(default)]
    contact: Vec<Spanned<RawContact>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawStart {
    q: Option<Spanned<Value>>,
    dq: Option<Spanned<Value>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawCost {
    kind: Spanned<String>,
    weight: Option<Spanned<Value>>,
    q_weight: Option<Spanned<Value>>,
    dq_weight: Option<Spanned<Value>>,
    q_ref: Option<Spanned<Value>>,
    dq_ref: Option<Spanned<Value>>,
    about: Option<Spanned<String>>,
    frame: Option<Spanned<String>>,
    offset: Option<Spanned<[f64; 3]>>,
    target: Option<Spanned<[f64; 3]>>,
    rpy: Option<Spanned<[f64; 3]>>,
}

/// Collects problems with their lines (every one is reported, as for models).
struct Problems<'a> {
    lines: &'a LineIndex,
    found: Vec<Problem>,
}

impl Problems<'_> {
    fn at(&mut self, span: std::ops::Range<usize>, message: String) {
        let line = Some(self.lines.of(span.start));
        self.found.push(Problem {
            site: Site::Model,
            message,
            line,
        });
    }
}

/// A value given as a number (every entry), a list (in order) or a table by name (the
/// names in `names`; missing ones keep `default`).
fn per_name(
    p: &mut Problems,
    what: &str,
    value: &Spanned<Value>,
    names: &[&str],
    default: &[f64],
) -> Vec<f64> {
    let span = value.span();
    let mut out = default.to_vec();
    let number = |v: &Value| match v {
        Value::Float(x) => Some(*x),
        Value::Integer(i) => Some(*i as f64),
        _ => None,
    };
    match value.get_ref() {
        Value::Array(items) => {
            if items.len() != names.len() {
                p.at(
                    span,
                    format!(
                        "{what} has {}; it needs {} ({})",
                        crate::Counted(items.len(), "entry"),
                        names.len(),
                        names.join(", ")
                    ),
                );
                return out;
            }
            for (slot, item) in out.iter_mut().zip(items) {
                match number(item) {
                    Some(x) => *slot = x,
                    None => {
                        p.at(span.clone(), format!("{what} must hold numbers"));
                        return out;
                    }
                }
            }
        }
        Value::Table(table) => {
            for (name, item) in table {
                let Some(at) = names.iter().position(|n| n == name) else {
                    p.at(
                        span.clone(),
                        format!(
                            "{what} names `{name}`, which is not one of {}",
                            names.join(", ")
                        ),
                    );
                    continue;
                };
                match number(item) {
                    Some(x) => out[at] = x,
                    None => p.at(span.clone(), format!("{what}'s `{name}` must be a number")),
                }
            }
        }
        v => match number(v) {
            Some(x) => out.iter_mut().for_each(|s| *s = x),
            None => p.at(
                span,
                format!("{what} must be a number, a list or a table by name"),
            ),
        },
    }
    if let Some(x) = out.iter().find(|x| !x.is_finite()) {
        p.at(value.span(), format!("{what} must be finite, not {x}"));
    }
    out
}

/// Weights: [`per_name`], and none negative.
fn weights(
    p: &mut Problems,
    what: &str,
    value: Option<&Spanned<Value>>,
    names: &[&str],
    whole: std::ops::Range<usize>,
) -> Vec<f64> {
    let Some(value) = value else {
        p.at(whole, format!("the term needs `{what}`"));
        return vec![0.0; names.len()];
    };
    let w = per_name(
        p,
        &format!("`{what}`"),
        value,
        names,
        &vec![0.0; names.len()],
    );
    if let Some(x) = w.iter().find(|x| **x < 0.0) {
        p.at(
            value.span(),
            format!("`{what}` must not be negative, got {}", crate::Given(*x)),
        );
    }
    w
}

/// `R = R_z(yaw) R_y(pitch) R_x(roll)` (URDF's `rpy`).
fn rpy_matrix([r, p, y]: [f64; 3]) -> [[f64; 3]; 3] {
    let (sr, cr) = r.sin_cos();
    let (sp, cp) = p.sin_cos();
    let (sy, cy) = y.sin_cos();
    [
        [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
        [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
        [-sp, cp * sr, cp * cr],
    ]
}

/// Reads a task file and the model it names (relative to the task's directory).
pub fn read_task(path: impl AsRef<Path>) -> Result<(Task, Model), ModelError> {
    let path = path.as_ref();
    let text = crate::source::read_model_file(path).map_err(|mut e| {
        for p in &mut e.problems {
            p.message = p.message.replace("model file", "task file");
        }
        e
    })?;
    let base = path.parent().unwrap_or(Path::new("."));
    task_from_str(&text, Some(&path.display().to_string()), base)
}

/// Reads a task from TOML text: `source_name` prefixes messages, the model path is taken
/// relative to `base`.
pub fn task_from_str(
    text: &str,
    source_name: Option<&str>,
    base: &Path,
) -> Result<(Task, Model), ModelError> {
    let src = source_name.map(str::to_string);
    let lines = LineIndex::new(text);
    let raw: RawTask = toml::from_str(text).map_err(|e| toml_error(&e, &lines, &src))?;
    let model_path = base.join(raw.model.get_ref());
    let floating_base = raw.floating_base.unwrap_or(false);
    let model = from_file(
        &model_path,
        UrdfOptions {
            floating_base,
            ..Default::default()
        },
    )
    .map_err(|e| {
        ModelError::single(
            src.clone(),
            format!(
                "the task's model `{}` cannot be read: {e}",
                model_path.display()
            ),
            Some(lines.of(raw.model.span().start)),
        )
    })?;
    let model = with_task_contacts(model, &raw, &lines, &src)?;
    let mut p = Problems {
        lines: &lines,
        found: Vec::new(),
    };
    let task = resolve(&mut p, raw, &model, model_path, floating_base);
    if p.found.is_empty() {
        Ok((task, model))
    } else {
        Err(ModelError {
            source_name: src,
            problems: p.found,
        })
    }
}

/// The model with the task's `enforce_limits`, `[ground]` and `[[contact]]` (as a model
/// file writes them), each problem at its line.
fn with_task_contacts(
    model: Model,
    raw: &RawTask,
    lines: &LineIndex,
    src: &Option<String>,
) -> Result<Model, ModelError> {
    if raw.enforce_limits.is_none() && raw.ground.is_none() && raw.contact.is_empty() {
        return Ok(model);
    }
    let written = (
        raw.enforce_limits,
        raw.ground.as_ref(),
        raw.contact.as_slice(),
    );
    with_written_contacts(model, written, lines, src)
}

/// The message for a model with unilateral rows and no `kappa`: name the relaxations, or —
/// when its only rows are its enforced limits — plan without them.
fn unrelaxed_rows(model: &Model, rows: usize) -> String {
    let limits = (model.gaps().iter())
        .filter(|g| matches!(g.kind, GapKind::Lower { .. } | GapKind::Upper { .. }))
        .count();
    let relax = format!(
        "the model has {rows} unilateral rows (limits, contacts, slack strings): name the relaxations the optimiser goes through, largest first, e.g. `kappa = [1e-3, 1e-4, 1e-5]` (φγ in m·N·s)"
    );
    if limits == rows {
        format!("{relax}, or plan without enforcing its {limits} joint limits (`enforce_limits = false`)")
    } else {
        relax
    }
}

/// `kappa`: one relaxation or a list, each positive and finite, each smaller than the one
/// before; required when the model has unilateral rows (their units, m·N·s, are the
/// model's), refused otherwise.
fn kappa_of(p: &mut Problems, raw: &RawTask, model: &Model) -> Vec<f64> {
    let rows = model.gaps().len();
    let Some(k) = &raw.kappa else {
        if rows > 0 {
            p.found.push(Problem {
                site: Site::Model,
                message: unrelaxed_rows(model, rows),
                line: None,
            });
        }
        return Vec::new();
    };
    if rows == 0 {
        p.at(
            k.span(),
            "`kappa` relaxes unilateral rows, and the model has none (enforce its limits, or add a ground or contacts)".into(),
        );
        return Vec::new();
    }
    let values: Vec<Option<f64>> = match k.get_ref() {
        Value::Array(list) => list.iter().map(number).collect(),
        other => vec![number(other)],
    };
    let mut kappa = Vec::new();
    for (i, v) in values.iter().enumerate() {
        match *v {
            Some(x) if x.is_finite() && x > 0.0 && kappa.last().is_none_or(|&l| x < l) => {
                kappa.push(x)
            }
            Some(x) if x.is_finite() && x > 0.0 => p.at(
                k.span(),
                format!(
                    "`kappa` must decrease: entry {} ({x}) is not below the one before",
                    i + 1
                ),
            ),
            _ => p.at(
                k.span(),
                format!(
                    "`kappa` entry {} must be a positive number (a relaxation φγ in m·N·s)",
                    i + 1
                ),
            ),
        }
    }
    if values.is_empty() {
        p.at(k.span(), "`kappa` is empty".into());
    }
    kappa
}

/// A TOML number as `f64`.
fn number(v: &Value) -> Option<f64> {
    match v {
        Value::Float(x) => Some(*x),
        Value::Integer(i) => Some(*i as f64),
        _ => None,
    }
}

fn resolve(
    p: &mut Problems,
    raw: RawTask,
    model: &Model,
    model_path: PathBuf,
    floating_base: bool,
) -> Task {
    let settings = settings(p, &raw);
    let kappa = kappa_of(p, &raw, model);
    if settings.integrator == TaskIntegrator::Rk4 && !kappa.is_empty() {
        let span = raw.integrator.as_ref().map_or(0..0, |i| i.span());
        p.at(
            span,
            "a task through contact steps with the VI (`integrator = \"vi\"`): RK4 does not hold unilateral rows".into(),
        );
    }
    let (controls, control_lines) = controls_of(p, &raw, model);
    if settings.integrator == TaskIntegrator::Rk4 {
        kinematic_controls_need_the_vi(p, &raw, model, &controls);
    }
    let names: Vec<&str> = model.variables.iter().map(|v| v.name.as_str()).collect();
    let (q0, dq0) = start_of(p, &raw, model, &names);
    let control_names: Vec<String> = controls
        .iter()
        .map(|c| match c {
            Control::Input(k) => model.inputs[*k].name.clone(),
            Control::Kinematic(i) => model.variables[*i].name.clone(),
        })
        .collect();
    let (limits, limit_lines) = limits_of(p, &raw, model, &controls, &control_names, control_lines);
    limits_hold_the_start(p, &controls, &control_names, (&limits, &limit_lines), &q0);
    let cnames: Vec<&str> = control_names.iter().map(String::as_str).collect();
    let costs = Costs {
        model,
        names: &names,
        cnames: &cnames,
        q0: &q0,
        dq0: &dq0,
    };
    let running: Vec<CostTerm> = (raw.cost.iter())
        .filter_map(|c| costs.term(p, c, false))
        .collect();
    let terminal: Vec<CostTerm> = (raw.terminal.iter())
        .filter_map(|c| costs.term(p, c, true))
        .collect();
    if raw.cost.is_empty() && raw.terminal.is_empty() {
        p.found.push(Problem {
            site: Site::Model,
            message: "the task has no cost: add [[cost]] or [[terminal]] terms".into(),
            line: None,
        });
    }
    let Settings {
        dt,
        knots,
        integrator,
        solver,
        max_iterations,
    } = settings;
    Task {
        model_path,
        floating_base,
        dt,
        knots: knots.max(0) as usize,
        integrator,
        solver,
        max_iterations,
        controls,
        q0,
        dq0,
        running,
        terminal,
        limits,
        limit_lines,
        kappa,
    }
}

/// The task's own settings, checked.
struct Settings {
    dt: f64,
    knots: i64,
    integrator: TaskIntegrator,
    solver: TaskSolver,
    max_iterations: Option<usize>,
}

/// `dt`, `knots`, `integrator`, `solver`, `max_iterations`: each in range or named.
fn settings(p: &mut Problems, raw: &RawTask) -> Settings {
    let dt = *raw.dt.get_ref();
    if !(dt.is_finite() && dt > 0.0) {
        p.at(
            raw.dt.span(),
            format!("`dt` must be positive, got {}", crate::Given(dt)),
        );
    }
    let knots = *raw.knots.get_ref();
    if !(1..=1_000_000).contains(&knots) {
        p.at(
            raw.knots.span(),
            format!("`knots` must be between 1 and 1000000, got {knots}"),
        );
    }
    let integrator = match raw.integrator.as_ref().map(|s| s.get_ref().parse()) {
        None => TaskIntegrator::Vi,
        Some(Ok(i @ (TaskIntegrator::Vi | TaskIntegrator::Rk4))) => i,
        Some(_) => {
            let other = raw.integrator.as_ref().unwrap().get_ref();
            let span = raw.integrator.as_ref().unwrap().span();
            p.at(
                span,
                format!("`integrator` is `{other}`; it must be `vi` or `rk4`"),
            );
            TaskIntegrator::Vi
        }
    };
    let solver = match raw.solver.as_ref().map(|s| s.get_ref().as_str()) {
        None | Some("ilqr") => TaskSolver::Ilqr,
        Some("ddp") => TaskSolver::Ddp,
        Some(other) => {
            let span = raw.solver.as_ref().unwrap().span();
            p.at(
                span,
                format!("`solver` is `{other}`; it must be `ilqr` or `ddp`"),
            );
            TaskSolver::Ilqr
        }
    };
    let max_iterations = raw.max_iterations.as_ref().and_then(|m| {
        let v = *m.get_ref();
        if v < 1 {
            p.at(
                m.span(),
                format!("`max_iterations` must be at least 1, got {v}"),
            );
            None
        } else {
            Some(v as usize)
        }
    });
    Settings {
        dt,
        knots,
        integrator,
        solver,
        max_iterations,
    }
}

/// The controls: named inputs or kinematic variables (default every input), with the line
/// each is named on.
fn controls_of(
    p: &mut Problems,
    raw: &RawTask,
    model: &Model,
) -> (Vec<Control>, Vec<Option<usize>>) {
    let mut controls = Vec::new();
    let mut control_lines = Vec::new();
    match &raw.controls {
        None => {
            controls.extend((0..model.inputs.len()).map(Control::Input));
            control_lines.resize(controls.len(), None);
        }
        Some(list) => {
            for name in list.get_ref() {
                let n = name.get_ref();
                let control = if let Some(k) = model.inputs.iter().position(|i| &i.name == n) {
                    Control::Input(k)
                } else if let Some(i) = model.variable_index(n) {
                    if model.variables[i].is_kinematic() {
                        Control::Kinematic(i)
                    } else {
                        p.at(
                            name.span(),
                            format!(
                                "control `{n}` is a dynamic variable with no input; a control must be an input or a kinematic variable"
                            ),
                        );
                        continue;
                    }
                } else {
                    p.at(
                        name.span(),
                        format!("control `{n}` is neither an input nor a variable of the model"),
                    );
                    continue;
                };
                if controls.contains(&control) {
                    p.at(name.span(), format!("control `{n}` is listed twice"));
                    continue;
                }
                controls.push(control);
                control_lines.push(Some(p.lines.of(name.span().start)));
            }
            if list.get_ref().is_empty() {
                p.at(list.span(), "`controls` is empty".into());
            }
        }
    }
    if controls.is_empty() && raw.controls.is_none() {
        p.found.push(Problem {
            site: Site::Model,
            message: "the model has no inputs: name kinematic variables in `controls`".into(),
            line: None,
        });
    }
    (controls, control_lines)
}

/// RK4 would need a kinematic control's velocity and acceleration between knots.
fn kinematic_controls_need_the_vi(
    p: &mut Problems,
    raw: &RawTask,
    model: &Model,
    controls: &[Control],
) {
    if let Some(at) = controls
        .iter()
        .position(|c| matches!(c, Control::Kinematic(_)))
    {
        let name = match controls[at] {
            Control::Kinematic(i) => model.variables[i].name.clone(),
            Control::Input(_) => unreachable!(),
        };
        let span = raw.controls.as_ref().map_or(0..0, |c| c.span());
        p.at(
            span,
            format!(
                "kinematic control `{name}` needs the VI: RK4 would need its velocity and acceleration between knots"
            ),
        );
    }
}

/// The start: the model's `q0`, `dq0`, or the file's by name.
fn start_of(
    p: &mut Problems,
    raw: &RawTask,
    model: &Model,
    names: &[&str],
) -> (Vec<f64>, Vec<f64>) {
    let mut q0: Vec<f64> = model.variables.iter().map(|v| v.q0).collect();
    let mut dq0: Vec<f64> = model.variables.iter().map(|v| v.dq0).collect();
    if let Some(start) = &raw.start {
        if let Some(q) = &start.q {
            q0 = per_name(p, "`start.q`", q, names, &q0);
        }
        if let Some(dq) = &start.dq {
            dq0 = per_name(p, "`start.dq`", dq, names, &dq0);
        }
    }
    (q0, dq0)
}

/// The limits: the model's input limits (unless `model_limits = false`), then the file's,
/// with the line each came from.
fn limits_of(
    p: &mut Problems,
    raw: &RawTask,
    model: &Model,
    controls: &[Control],
    control_names: &[String],
    control_lines: Vec<Option<usize>>,
) -> (Vec<Option<[f64; 2]>>, Vec<Option<usize>>) {
    let mut limits: Vec<Option<[f64; 2]>> = controls
        .iter()
        .map(|c| match c {
            Control::Input(k) if raw.model_limits != Some(false) => model.inputs[*k].limits,
            _ => None,
        })
        .collect();
    let mut limit_lines = control_lines;
    for (name, value) in raw.limits.iter().flatten() {
        let Some(c) = control_names.iter().position(|n| n == name) else {
            p.at(
                value.span(),
                format!(
                    "limits are given for `{name}`, which is not a control (the controls: {})",
                    control_names.join(", ")
                ),
            );
            continue;
        };
        let v = value.get_ref();
        if v.len() != 2 || v[0].is_nan() || v[1].is_nan() || v[0] > v[1] {
            p.at(
                value.span(),
                format!("the limits of `{name}` must be [lo, hi] with lo ≤ hi, got {v:?}"),
            );
            continue;
        }
        limits[c] = Some([v[0], v[1]]);
        limit_lines[c] = Some(p.lines.of(value.span().start));
    }
    (limits, limit_lines)
}

/// A kinematic control's limits must hold its start value.
fn limits_hold_the_start(
    p: &mut Problems,
    controls: &[Control],
    control_names: &[String],
    (limits, limit_lines): (&[Option<[f64; 2]>], &[Option<usize>]),
    q0: &[f64],
) {
    for (c, control) in controls.iter().enumerate() {
        if let (Control::Kinematic(i), Some([lo, hi])) = (control, limits[c]) {
            let x = q0[*i];
            if !(lo..=hi).contains(&x) {
                p.found.push(Problem {
                    site: Site::Model,
                    message: format!(
                        "the limits [{lo}, {hi}] of `{}` exclude its start value {x}",
                        control_names[c]
                    ),
                    line: limit_lines[c],
                });
            }
        }
    }
}

/// What a cost term is resolved against: the model, its variables' and the controls'
/// names, and the start (a state term's default reference).
struct Costs<'a> {
    model: &'a Model,
    names: &'a [&'a str],
    cnames: &'a [&'a str],
    q0: &'a [f64],
    dq0: &'a [f64],
}

impl Costs<'_> {
    /// One `[[cost]]` (or, `terminal`, `[[terminal]]`) term: its kind, the fields that kind
    /// takes, then its values.
    fn term(&self, p: &mut Problems, c: &Spanned<RawCost>, terminal: bool) -> Option<CostTerm> {
        let whole = c.span();
        let rc = c.get_ref();
        let kind = rc.kind.get_ref().as_str();
        // Which fields each kind takes; anything else is named.
        let given: [(&str, bool); 10] = [
            ("weight", rc.weight.is_some()),
            ("q_weight", rc.q_weight.is_some()),
            ("dq_weight", rc.dq_weight.is_some()),
            ("q_ref", rc.q_ref.is_some()),
            ("dq_ref", rc.dq_ref.is_some()),
            ("about", rc.about.is_some()),
            ("frame", rc.frame.is_some()),
            ("offset", rc.offset.is_some()),
            ("target", rc.target.is_some()),
            ("rpy", rc.rpy.is_some()),
        ];
        let allowed: &[&str] = match kind {
            "state" => &["q_weight", "dq_weight", "q_ref", "dq_ref"],
            "control" => &["weight", "about"],
            "control_rate" => &["weight"],
            "frame" => &["frame", "offset", "target", "weight"],
            "orientation" => &["frame", "rpy", "weight"],
            other => {
                p.at(
                    rc.kind.span(),
                    format!(
                        "cost kind `{other}` is unknown: use state, control, control_rate, frame or orientation"
                    ),
                );
                return None;
            }
        };
        for (field, present) in given {
            if present && !allowed.contains(&field) {
                p.at(
                    whole.clone(),
                    format!(
                        "a `{kind}` term takes no `{field}` (it takes {})",
                        allowed.join(", ")
                    ),
                );
            }
        }
        if terminal && matches!(kind, "control" | "control_rate") {
            p.at(
                rc.kind.span(),
                format!("a `{kind}` term can only be a running cost: there is no control at the last knot"),
            );
            return None;
        }
        Some(match kind {
            "state" => self.state(p, rc, whole),
            "control" => self.control(p, rc, whole),
            "control_rate" => CostTerm::ControlRate {
                weight: weights(p, "weight", rc.weight.as_ref(), self.cnames, whole),
            },
            "frame" => self.frame_term(p, rc, whole)?,
            _ => self.orientation(p, rc, whole)?,
        })
    }

    /// The frame a `frame` or `orientation` term names.
    fn frame(
        &self,
        p: &mut Problems,
        rc: &RawCost,
        whole: std::ops::Range<usize>,
    ) -> Option<usize> {
        let kind = rc.kind.get_ref();
        let model = self.model;
        let Some(f) = &rc.frame else {
            p.at(whole.clone(), format!("a `{kind}` term needs `frame`"));
            return None;
        };
        let found = model.frame_index(f.get_ref());
        if found.is_none() {
            p.at(
                f.span(),
                format!(
                    "frame `{}` is not in the model{}",
                    f.get_ref(),
                    crate::nearest(
                        f.get_ref(),
                        &model
                            .frames
                            .iter()
                            .map(|f| f.name.as_str())
                            .collect::<Vec<_>>()
                    )
                ),
            );
        }
        found
    }

    /// The per-axis weight of a `frame` or `orientation` term.
    fn axis_weight(
        &self,
        p: &mut Problems,
        rc: &RawCost,
        whole: std::ops::Range<usize>,
    ) -> [f64; 3] {
        let w = weights(p, "weight", rc.weight.as_ref(), &["x", "y", "z"], whole);
        [w[0], w[1], w[2]]
    }

    /// A `state` term: references (default the start) and weights on `q` and `q̇`.
    fn state(&self, p: &mut Problems, rc: &RawCost, whole: std::ops::Range<usize>) -> CostTerm {
        let (names, q0, dq0) = (self.names, self.q0, self.dq0);
        let q_ref = rc
            .q_ref
            .as_ref()
            .map_or(q0.to_vec(), |v| per_name(p, "`q_ref`", v, names, q0));
        let dq_ref = rc
            .dq_ref
            .as_ref()
            .map_or(dq0.to_vec(), |v| per_name(p, "`dq_ref`", v, names, dq0));
        // Either may be left out (zero), not both.
        let mut optional = |what: &str, value: &Option<Spanned<Value>>| match value {
            Some(_) => weights(p, what, value.as_ref(), names, whole.clone()),
            None => vec![0.0; names.len()],
        };
        let q_weight = optional("q_weight", &rc.q_weight);
        let dq_weight = optional("dq_weight", &rc.dq_weight);
        if rc.q_weight.is_none() && rc.dq_weight.is_none() {
            p.at(
                whole,
                "a `state` term needs `q_weight` or `dq_weight`".into(),
            );
        }
        CostTerm::State {
            q_ref,
            dq_ref,
            q_weight,
            dq_weight,
        }
    }

    /// A `control` term: weights on the controls, about gravity's or zero.
    fn control(&self, p: &mut Problems, rc: &RawCost, whole: std::ops::Range<usize>) -> CostTerm {
        let about = match rc.about.as_ref().map(|a| a.get_ref().as_str()) {
            None | Some("gravity") => About::Gravity,
            Some("zero") => About::Zero,
            Some(other) => {
                p.at(
                    rc.about.as_ref().unwrap().span(),
                    format!("`about` is `{other}`; it must be `gravity` or `zero`"),
                );
                About::Gravity
            }
        };
        CostTerm::Control {
            weight: weights(p, "weight", rc.weight.as_ref(), self.cnames, whole),
            about,
        }
    }

    /// A `frame` term: a point on a frame (`offset`) or in the world (`target`) to reach.
    fn frame_term(
        &self,
        p: &mut Problems,
        rc: &RawCost,
        whole: std::ops::Range<usize>,
    ) -> Option<CostTerm> {
        let frame = self.frame(p, rc, whole.clone());
        let weight = self.axis_weight(p, rc, whole.clone());
        let target = match (&rc.offset, &rc.target) {
            (Some(o), None) => Target::Offset(*o.get_ref()),
            (None, Some(t)) => Target::World(*t.get_ref()),
            _ => {
                p.at(
                    whole,
                    "a `frame` term needs exactly one of `offset` and `target`".into(),
                );
                return None;
            }
        };
        let finite = match target {
            Target::World(x) | Target::Offset(x) => x.iter().all(|v| v.is_finite()),
        };
        if !finite {
            p.at(whole, "the frame term's point must be finite".into());
        }
        Some(CostTerm::Frame {
            frame: frame?,
            target,
            weight,
        })
    }

    /// An `orientation` term: the frame's attitude against `rpy` (or none: kept level).
    fn orientation(
        &self,
        p: &mut Problems,
        rc: &RawCost,
        whole: std::ops::Range<usize>,
    ) -> Option<CostTerm> {
        let frame = self.frame(p, rc, whole.clone());
        let weight = self.axis_weight(p, rc, whole.clone());
        let target = rc.rpy.as_ref().map(|r| rpy_matrix(*r.get_ref()));
        if rc
            .rpy
            .as_ref()
            .is_some_and(|r| r.get_ref().iter().any(|v| !v.is_finite()))
        {
            p.at(whole, "`rpy` must be finite".into());
        }
        Some(CostTerm::Orientation {
            frame: frame?,
            target,
            weight,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rpy_is_z_y_x() {
        let r = rpy_matrix([0.0, 0.0, std::f64::consts::FRAC_PI_2]);
        // yaw 90°: x goes to y.
        assert!((r[1][0] - 1.0).abs() < 1e-15 && r[0][0].abs() < 1e-15);
        let r = rpy_matrix([std::f64::consts::FRAC_PI_2, 0.0, 0.0]);
        // roll 90°: y goes to z.
        assert!((r[2][1] - 1.0).abs() < 1e-15);
    }
}
