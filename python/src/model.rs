//! `Model`: a model read at run time with its interpreted system — what it is made of (names,
//! defaults), its arguments checked against it, and `load`/`loads`. What it computes lives by
//! topic: `evaluation.rs`, `frames.rs`, `simulate.rs`, `linearize.rs`, `rollouts.rs`.

use std::path::PathBuf;
use std::sync::Mutex;

use numpy::ndarray::Ix1;
use pyo3::prelude::*;
use pyo3::types::PyDict;
use tree_mech::model;
use tree_mech::nalgebra::Dyn;
use tree_mech::runtime::kinematics::Kinematics as FrameKinematics;
use tree_mech::runtime::Vector;
use tree_mech::runtime::{ModelMotions, Prescription};
use tree_mech::{System, TreeSystem};

use crate::arrays::{check_finite, vector};
use crate::errors::{bad, model_error, system_error, ModelError};
use crate::numbers::{Numbers, PerVariable};

/// A model read at run time, with its interpreted system.
#[pyclass(module = "tree_mech", frozen)]
pub(crate) struct Model {
    pub(crate) model: model::Model,
    pub(crate) sys: Mutex<TreeSystem>,
    /// The frames' kinematics (`frame_jacobian` and the rest).
    pub(crate) frames: Mutex<FrameKinematics>,
}

impl Model {
    pub(crate) fn of(model: model::Model) -> PyResult<Self> {
        let sys = TreeSystem::new(&model).map_err(|e| system_error(&e))?;
        let frames =
            FrameKinematics::new(&model).map_err(|e| ModelError::new_err(e.to_string()))?;
        Ok(Model {
            model,
            sys: Mutex::new(sys),
            frames: Mutex::new(frames),
        })
    }

    /// The frames' kinematics at `(q, dq, ddq)` (defaults: the model's q0, dq0 and zero).
    pub(crate) fn frames_at(
        &self,
        q: Option<PerVariable<'_>>,
        dq: Option<PerVariable<'_>>,
        ddq: Option<PerVariable<'_>>,
    ) -> PyResult<std::sync::MutexGuard<'_, FrameKinematics>> {
        let q = self.vector("q", q, |i| self.model.variables[i].q0)?;
        let dq = self.vector("dq", dq, |i| self.model.variables[i].dq0)?;
        let ddq = self.vector("ddq", ddq, |_| 0.0)?;
        let mut k = self.frames.lock().expect("no panic holds the lock");
        k.update(q.as_slice(), Some(dq.as_slice()), Some(ddq.as_slice()))
            .map_err(|e| bad(e.to_string()))?;
        Ok(k)
    }

    /// The frame `name`'s kinematics at `(q, dq, ddq)` and its index.
    pub(crate) fn frame_at(
        &self,
        name: &str,
        q: Option<PerVariable<'_>>,
        dq: Option<PerVariable<'_>>,
        ddq: Option<PerVariable<'_>>,
    ) -> PyResult<(std::sync::MutexGuard<'_, FrameKinematics>, usize)> {
        let k = self.frames_at(q, dq, ddq)?;
        let f = k.frame(name).map_err(|e| bad(e.to_string()))?;
        Ok((k, f))
    }

    pub(crate) fn system(&self) -> TreeSystem {
        self.sys.lock().expect("no panic holds the lock").clone()
    }

    /// A dict naming the model's parts in order (`variables`, `dynamic`, `kinematic`,
    /// `inputs`, `constraints`): how a linearisation's dict begins.
    pub(crate) fn named_parts<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let out = PyDict::new(py);
        out.set_item("variables", self.names())?;
        out.set_item("dynamic", self.dynamic())?;
        out.set_item("kinematic", self.kinematic())?;
        out.set_item("inputs", self.inputs())?;
        out.set_item("constraints", self.constraints())?;
        Ok(out)
    }

    pub(crate) fn n(&self) -> usize {
        self.model.variables.len()
    }

    /// A vector of every variable, or the model's default.
    pub(crate) fn vector(
        &self,
        what: &str,
        given: Option<PerVariable<'_>>,
        default: impl Fn(usize) -> f64,
    ) -> PyResult<Vector<Dyn>> {
        let n = self.n();
        match given {
            None => Ok(Vector::<Dyn>::from_fn(n, |i, _| default(i))),
            Some(PerVariable::Named(named)) => {
                let mut v = Vector::<Dyn>::from_fn(n, |i, _| default(i));
                for (name, x) in named {
                    let Some(i) = self.model.variable_index(&name) else {
                        let names = self.names();
                        let names: Vec<&str> = names.iter().map(String::as_str).collect();
                        return Err(bad(format!(
                            "{what} names `{name}`, which is not a variable of the model{}",
                            model::nearest(&name, &names)
                        )));
                    };
                    v[i] = x;
                }
                check_finite(what, v.as_slice(), &self.names())?;
                Ok(v)
            }
            Some(PerVariable::Array(a)) => {
                let v = a.as_array();
                if v.len() != n {
                    return Err(bad(format!(
                        "{what} has {}; the model has {} ({})",
                        model::Counted(v.len(), "entry"),
                        model::Counted(n, "variable"),
                        self.names().join(", ")
                    )));
                }
                let v: Vec<f64> = v.iter().copied().collect();
                check_finite(what, &v, &self.names())?;
                Ok(Vector::<Dyn>::from_vec(v))
            }
        }
    }

    /// A run's start `(q0, dq0)`: given (an array or a dict by name) or the model's, checked.
    pub(crate) fn start(
        &self,
        q0: Option<PerVariable<'_>>,
        dq0: Option<PerVariable<'_>>,
    ) -> PyResult<(Vec<f64>, Vec<f64>)> {
        let q0 = self.vector("q0", q0, |i| self.model.variables[i].q0)?;
        let dq0 = self.vector("dq0", dq0, |i| self.model.variables[i].dq0)?;
        Ok((q0.as_slice().to_vec(), dq0.as_slice().to_vec()))
    }

    /// One number per variable, as a numpy array.
    pub(crate) fn per_variable(
        &self,
        py: Python<'_>,
        of: impl Fn(&model::Variable) -> f64,
    ) -> Py<PyAny> {
        vector(py, &self.model.variables.iter().map(of).collect::<Vec<_>>())
    }

    pub(crate) fn input_names(&self) -> Vec<String> {
        self.model.inputs.iter().map(|u| u.name.clone()).collect()
    }

    /// The inputs at one state: one finite value per input, or zeros.
    pub(crate) fn input_vector(&self, given: Option<Numbers<'_, Ix1>>) -> PyResult<Vec<f64>> {
        match given {
            None => Ok(vec![0.0; self.model.inputs.len()]),
            Some(u) => self.checked_inputs(u.as_array().to_vec()),
        }
    }

    /// `u` if it holds one finite value per input, else a `ValueError` naming the inputs.
    pub(crate) fn checked_inputs(&self, u: Vec<f64>) -> PyResult<Vec<f64>> {
        if u.len() != self.model.inputs.len() {
            return Err(bad(format!(
                "u has {}; the model has {}",
                model::Counted(u.len(), "entry"),
                self.inputs_phrase()
            )));
        }
        check_finite("u", &u, &self.input_names())?;
        Ok(u)
    }

    /// "no inputs", "1 input (push)", or "2 inputs (push, pull)".
    pub(crate) fn inputs_phrase(&self) -> String {
        match self.model.inputs.len() {
            0 => "no inputs".to_string(),
            n => format!(
                "{} ({})",
                model::Counted(n, "input"),
                self.input_names().join(", ")
            ),
        }
    }

    /// The kinematic variables' motion for a call at one state: the model's prescription, or
    /// with `ddq` given, held at the given `q`, `dq` and `ddq`.
    pub(crate) fn kinematics(
        &self,
        sys: &TreeSystem,
        q: &Vector<Dyn>,
        dq: &Vector<Dyn>,
        ddq: Option<PerVariable<'_>>,
    ) -> PyResult<Kinematics> {
        Ok(match ddq {
            None => Kinematics::Model(ModelMotions::of(sys)),
            Some(ddq) => {
                let ddq = self.vector("ddq", Some(ddq), |_| 0.0)?;
                Kinematics::Given(q.clone(), dq.clone(), ddq)
            }
        })
    }

    pub(crate) fn names(&self) -> Vec<String> {
        self.model
            .variables
            .iter()
            .map(|v| v.name.clone())
            .collect()
    }

    /// The names of variables `list`.
    pub(crate) fn named(&self, list: &[usize]) -> Vec<String> {
        list.iter()
            .map(|&i| self.model.variables[i].name.clone())
            .collect()
    }
}

#[pymethods]
impl Model {
    /// The model's name.
    #[getter]
    fn name(&self) -> String {
        self.model.name.clone()
    }

    /// Every variable's name, in order (the order of q).
    #[getter]
    fn variables(&self) -> Vec<String> {
        self.names()
    }

    /// The number of configuration variables (Pinocchio's `nq`); q has this many entries.
    #[getter]
    fn nq(&self) -> usize {
        self.n()
    }

    /// The number of velocity variables (Pinocchio's `nv`): every variable here is one
    /// number (no quaternions), so it equals `nq`.
    #[getter]
    fn nv(&self) -> usize {
        self.n()
    }

    /// The dynamic (simulated) variables' names.
    #[getter]
    fn dynamic(&self) -> Vec<String> {
        self.named(&self.model.dynamic())
    }

    /// The kinematic (prescribed) variables' names.
    #[getter]
    fn kinematic(&self) -> Vec<String> {
        self.named(&self.model.kinematic())
    }

    /// The inputs' names (u's order).
    #[getter]
    fn inputs(&self) -> Vec<String> {
        self.model.inputs.iter().map(|i| i.name.clone()).collect()
    }

    /// The constraint equations' names (λ's order).
    #[getter]
    fn constraints(&self) -> Vec<String> {
        let sys = self.sys.lock().expect("no panic holds the lock");
        (0..sys.constraint_count())
            .map(|r| sys.constraint_name(r).to_string())
            .collect()
    }

    /// The frames' names.
    #[getter]
    fn frames(&self) -> Vec<String> {
        self.model.frames.iter().map(|f| f.name.clone()).collect()
    }

    /// The initial configuration.
    #[getter]
    fn q0(&self, py: Python<'_>) -> Py<PyAny> {
        self.per_variable(py, |v| v.q0)
    }

    /// The initial velocity.
    #[getter]
    fn dq0(&self, py: Python<'_>) -> Py<PyAny> {
        self.per_variable(py, |v| v.dq0)
    }

    fn __repr__(&self) -> String {
        format!(
            "Model({:?}: {} variables, {} frames, {} inputs, {} constraint rows)",
            self.model.name,
            self.n(),
            self.model.frames.len(),
            self.model.inputs.len(),
            self.model.constraint_rows()
        )
    }

    /// A copy with other parameters: `masses` {frame: kg} (its centre of mass and inertia
    /// kept), `constants` {frame: the value of its constant primitive, m or rad},
    /// `gravity` [x, y, z] — a parameter sweep's model (`rollouts(..., models=[…])`).
    #[pyo3(signature = (masses=None, constants=None, gravity=None))]
    fn with_parameters(
        &self,
        masses: Option<std::collections::BTreeMap<String, f64>>,
        constants: Option<std::collections::BTreeMap<String, f64>>,
        gravity: Option<[f64; 3]>,
    ) -> PyResult<Model> {
        let mut m = self.model.clone();
        for (frame, mass) in masses.iter().flatten() {
            m.set_mass(frame, *mass).map_err(bad)?;
        }
        for (frame, value) in constants.iter().flatten() {
            m.set_constant(frame, *value).map_err(bad)?;
        }
        if let Some(g) = gravity {
            if g.iter().any(|x| !x.is_finite()) {
                return Err(bad(format!("gravity must be finite, got {g:?}")));
            }
            m.gravity = g;
        }
        Model::of(m)
    }

    /// A copy with contact added, as the command line's `--ground`, `--friction`,
    /// `--contact` and `--limits` add it: `ground` the height of the plane under the world
    /// (replacing the model's own), with `friction` μ and `normal` (default +z); `contacts`
    /// spheres on frames, each `"FRAME"`, `"FRAME:RADIUS"` or a dict with `frame` and any of
    /// `radius`, `friction`, `collide`, `name` (docs/model-format.md, "Contact"); `limits`
    /// True or False to enforce the variables' limits or not, whatever the model says.
    #[pyo3(signature = (ground=None, friction=None, normal=None, contacts=None, limits=None))]
    fn with_contacts(
        &self,
        py: Python<'_>,
        ground: Option<f64>,
        friction: Option<f64>,
        normal: Option<[f64; 3]>,
        contacts: Option<Vec<Bound<'_, PyAny>>>,
        limits: Option<bool>,
    ) -> PyResult<Model> {
        let ground = (ground.is_some() || friction.is_some() || normal.is_some()).then_some(
            model::GroundSpec {
                height: ground,
                normal,
                friction,
            },
        );
        let contacts = (contacts.iter().flatten())
            .enumerate()
            .map(|(k, c)| contact_spec(k, c))
            .collect::<PyResult<Vec<_>>>()?;
        let spec = model::ContactsSpec {
            enforce_limits: limits,
            ground,
            contacts,
        };
        let m = (self.model.with_contacts(&spec)).map_err(|e| model_error(py, &e))?;
        Model::of(m)
    }
}

/// Contact `k` of [`Model::with_contacts`]: `"FRAME"`, `"FRAME:RADIUS"` or a dict.
fn contact_spec(k: usize, c: &Bound<'_, PyAny>) -> PyResult<model::ContactSpec> {
    if let Ok(text) = c.extract::<String>() {
        return model::ContactSpec::parse(&text).map_err(|e| bad(format!("contacts[{k}]: {e}")));
    }
    let dict = c.cast::<PyDict>().map_err(|_| {
        bad(format!(
            "contacts[{k}] must be \"FRAME\", \"FRAME:RADIUS\" or a dict with `frame`"
        ))
    })?;
    let mut spec = model::ContactSpec::default();
    for (key, value) in dict.iter() {
        let key: String = key.extract()?;
        let wrong = |what: &str| bad(format!("contacts[{k}][{key:?}] must be {what}"));
        match key.as_str() {
            "frame" => spec.frame = value.extract().map_err(|_| wrong("a frame's name"))?,
            "name" => spec.name = Some(value.extract().map_err(|_| wrong("a string"))?),
            "radius" => spec.radius = Some(value.extract().map_err(|_| wrong("a number"))?),
            "friction" => spec.friction = Some(value.extract().map_err(|_| wrong("a number"))?),
            "collide" => spec.collide = Some(value.extract().map_err(|_| wrong("True or False"))?),
            _ => {
                return Err(bad(format!(
                    "contacts[{k}] has `{key}`: a contact takes frame, radius, friction, \
                     collide and name"
                )))
            }
        }
    }
    if spec.frame.is_empty() {
        return Err(bad(format!("contacts[{k}] names no `frame`")));
    }
    Ok(spec)
}

/// The kinematic variables' motion at one state: the model's prescription at `t`, or the
/// caller's own `(q, dq, ddq)` (trep's way: `ddq=` given).
pub(crate) enum Kinematics {
    Model(ModelMotions),
    Given(Vector<Dyn>, Vector<Dyn>, Vector<Dyn>),
}

impl Prescription for Kinematics {
    fn kinematic(&mut self, i: usize, t: f64) -> [f64; 3] {
        match self {
            Kinematics::Model(m) => m.kinematic(i, t),
            Kinematics::Given(q, dq, ddq) => [q[i], dq[i], ddq[i]],
        }
    }
}

/// Reads a model file (TOML, or URDF by its extension or its XML), with the variables of
/// `lock` held still (the command line's `--lock`); a URDF's mimic joints follow their
/// leaders unless `independent_mimics` (the command line's `--independent-mimics`); its
/// `<collision><sphere>` elements become contact spheres when `contacts` (`--contacts`).
#[pyfunction]
#[pyo3(signature = (path, floating_base=false, lock=None, independent_mimics=false, contacts=false))]
pub(crate) fn load(
    py: Python<'_>,
    path: PathBuf,
    floating_base: bool,
    lock: Option<&Bound<'_, PyAny>>,
    independent_mimics: bool,
    contacts: bool,
) -> PyResult<Model> {
    let m = model::from_file(
        &path,
        model::UrdfOptions {
            floating_base,
            independent_mimics,
            collision_spheres: contacts,
        },
    )
    .map_err(|e| model_error(py, &e))?;
    Model::of(locked(py, m, lock)?)
}

/// Reads a model from text: `format` "toml" or "urdf"; `lock`, `independent_mimics` and
/// `contacts` as [`load`]'s.
#[pyfunction]
#[pyo3(signature = (text, format="toml", floating_base=false, lock=None, independent_mimics=false, contacts=false))]
pub(crate) fn loads(
    py: Python<'_>,
    text: &str,
    format: &str,
    floating_base: bool,
    lock: Option<&Bound<'_, PyAny>>,
    independent_mimics: bool,
    contacts: bool,
) -> PyResult<Model> {
    let m = match format {
        "toml" => model::from_toml_str(text, None),
        "urdf" => model::from_urdf_str(
            text,
            None,
            model::UrdfOptions {
                floating_base,
                independent_mimics,
                collision_spheres: contacts,
            },
        ),
        other => return Err(bad(format!("format `{other}`: use `toml` or `urdf`"))),
    }
    .map_err(|e| model_error(py, &e))?;
    Model::of(locked(py, m, lock)?)
}

/// `m` with the variables of `lock` held: a dict `{name: value or None}` (None: at its
/// q0), a list of `"name"`/`"name=value"`, or one such string, comma-separated.
fn locked(
    py: Python<'_>,
    m: model::Model,
    lock: Option<&Bound<'_, PyAny>>,
) -> PyResult<model::Model> {
    let Some(lock) = lock else {
        return Ok(m);
    };
    let in_python = |e: String| bad(e.replace("--lock", "lock"));
    let mut locks = Vec::new();
    if let Ok(dict) = lock.cast::<pyo3::types::PyDict>() {
        for (name, value) in dict.iter() {
            let variable: String = name
                .extract()
                .map_err(|_| bad("lock's keys are variable names"))?;
            let value: Option<f64> = value
                .extract()
                .map_err(|_| bad(format!("lock's `{variable}`: a number, or None for its q0")))?;
            if value.is_some_and(|x| !x.is_finite()) {
                return Err(bad(format!("lock's `{variable}` must be a finite number")));
            }
            locks.push(model::Lock { variable, value });
        }
    } else if let Ok(text) = lock.extract::<String>() {
        for part in text.split(',') {
            locks.push(model::Lock::parse(part).map_err(in_python)?);
        }
    } else {
        let parts: Vec<String> = lock.extract().map_err(|_| {
            bad("lock is a dict {name: value or None}, a list of \"name\" or \"name=value\", or such a string")
        })?;
        for part in &parts {
            locks.push(model::Lock::parse(part).map_err(in_python)?);
        }
    }
    m.locked(&locks).map_err(|e| model_error(py, &e))
}
