//! A programmatic builder, so tests and benchmarks can make models of any size.

use crate::error::ModelError;
use crate::error::{Problem, Site};
use crate::model::Model;
use crate::primitive::{Primitive, PrimitiveKind};
use crate::spec::{
    ConstraintSpec, DamperSpec, FrameSpec, ModelSpec, ParameterSpec, SineSpec, SpringSpec,
    VariableSpec,
};
use crate::validate::validate;

/// Builds a [`Model`] frame by frame; `build` runs the same validation as the file formats.
///
/// ```
/// use tree_model::{ModelBuilder, PrimitiveKind::*};
/// let model = ModelBuilder::new("pendulum")
///     .frame("pivot", "world", Rx, "theta")
///     .frame("bob", "pivot", Tz, -1.0)
///     .mass("bob", 1.0, [0.0; 3])
///     .initial("theta", 0.3, 0.0)
///     .build()
///     .unwrap();
/// assert_eq!(model.dof(), 1);
/// ```
#[derive(Clone, Debug)]
pub struct ModelBuilder {
    spec: ModelSpec,
    /// Problems found while building (a mass for an unknown frame), reported by `build`.
    pending: Vec<Problem>,
}

impl ModelBuilder {
    /// An empty model named `name` (gravity (0, 0, −9.81)).
    pub fn new(name: &str) -> Self {
        ModelBuilder {
            spec: ModelSpec::new(name),
            pending: Vec::new(),
        }
    }

    /// Sets the gravity vector (m/s², world axes).
    pub fn gravity(mut self, g: [f64; 3]) -> Self {
        self.spec.gravity = Some(g);
        self
    }

    /// Adds a frame hanging off `parent` ("world" for the root) by one primitive whose
    /// parameter is a constant (`f64`) or a variable name (`&str`).
    pub fn frame(
        mut self,
        name: &str,
        parent: &str,
        kind: PrimitiveKind,
        value: impl Into<crate::Value>,
    ) -> Self {
        self.spec.frames.push(FrameSpec {
            name: name.into(),
            parent: (parent != "world").then(|| parent.into()),
            primitives: vec![Primitive::new(kind, value)],
            mass: None,
            com: None,
            inertia: None,
        });
        self
    }

    /// Puts a mass with diagonal inertia at the origin of the frame named `frame`
    /// (added earlier). An unknown name is reported by `build`.
    pub fn mass(self, frame: &str, mass: f64, inertia: [f64; 3]) -> Self {
        self.body(frame, mass, [0.0; 3], &inertia)
    }

    /// Puts a rigid body on the frame named `frame`: its mass, centre of mass `com` and
    /// inertia about the centre of mass in the frame's axes, `[ixx, iyy, izz]` or
    /// `[ixx, iyy, izz, ixy, ixz, iyz]`. An unknown name is reported by `build`.
    pub fn body(mut self, frame: &str, mass: f64, com: [f64; 3], inertia: &[f64]) -> Self {
        match self.spec.frames.iter_mut().find(|f| f.name == frame) {
            Some(f) => {
                f.mass = Some(mass);
                f.com = (com != [0.0; 3]).then_some(com);
                f.inertia = Some(inertia.to_vec());
            }
            None => self.pending.push(Problem {
                site: Site::Model,
                message: format!("mass given for unknown frame `{frame}`"),
                line: None,
            }),
        }
        self
    }

    fn settings(&mut self, var: &str) -> &mut VariableSpec {
        if let Some(i) = self.spec.variables.iter().position(|v| v.name == var) {
            return &mut self.spec.variables[i];
        }
        self.spec.variables.push(VariableSpec {
            name: var.into(),
            ..Default::default()
        });
        self.spec.variables.last_mut().unwrap()
    }

    /// Initial value and velocity of a variable.
    pub fn initial(mut self, var: &str, q0: f64, dq0: f64) -> Self {
        let s = self.settings(var);
        s.q0 = Some(q0);
        s.dq0 = Some(dq0);
        self
    }

    /// Viscous damping coefficient of a variable.
    pub fn damping(mut self, var: &str, c: f64) -> Self {
        self.settings(var).damping = Some(c);
        self
    }

    /// Makes a variable kinematic, held at its `q0` moving at `dq0` (see [`Self::initial`]).
    pub fn kinematic(mut self, var: &str) -> Self {
        self.settings(var).kinematic = Some(true);
        self
    }

    /// Makes a variable kinematic, moving as `offset + amplitude·sin(2πf t + phase)`.
    pub fn sine(
        mut self,
        var: &str,
        offset: f64,
        amplitude: f64,
        frequency: f64,
        phase: f64,
    ) -> Self {
        let s = self.settings(var);
        s.kinematic = Some(true);
        s.motion = Some(SineSpec {
            offset: Some(offset),
            amplitude: Some(amplitude),
            frequency: Some(frequency),
            phase: Some(phase),
        });
        self
    }

    /// Makes a variable kinematic, following a natural cubic spline through `(t, q)` samples.
    pub fn samples(mut self, var: &str, samples: &[[f64; 2]]) -> Self {
        let s = self.settings(var);
        s.kinematic = Some(true);
        s.samples = Some(samples.to_vec());
        self
    }

    /// A distance constraint `‖p_a − p_b‖² − ℓ² = 0`; `length` is a number or a variable name.
    pub fn distance(
        mut self,
        name: &str,
        a: &str,
        b: &str,
        length: impl Into<crate::Value>,
    ) -> Self {
        let length = match length.into() {
            crate::Value::Constant(x) => ParameterSpec::Constant(x),
            crate::Value::Variable(v) => {
                self.settings(&v);
                ParameterSpec::Variable(v)
            }
            crate::Value::Mimic(m) => {
                self.pending.push(Problem {
                    site: Site::Model,
                    message: format!(
                        "distance constraint `{name}`: a length is a number or a variable, not a mimic of `{}`",
                        m.variable
                    ),
                    line: None,
                });
                ParameterSpec::Constant(1.0)
            }
        };
        self.spec.constraints.push(ConstraintSpec {
            name: Some(name.into()),
            kind: "distance".into(),
            frames: vec![a.into(), b.into()],
            length: Some(length),
            ..Default::default()
        });
        self
    }

    /// A plane constraint `n·(p_b − p_a) = 0`, `n` in frame a's axes.
    pub fn plane(mut self, name: &str, a: &str, b: &str, normal: [f64; 3]) -> Self {
        self.spec.constraints.push(ConstraintSpec {
            name: Some(name.into()),
            kind: "plane".into(),
            frames: vec![a.into(), b.into()],
            normal: Some(normal),
            ..Default::default()
        });
        self
    }

    /// A point constraint `e_i·(p_a − p_b) = 0` for each world axis in `axes` (e.g. `"xz"`).
    pub fn point(mut self, name: &str, a: &str, b: &str, axes: &str) -> Self {
        self.spec.constraints.push(ConstraintSpec {
            name: Some(name.into()),
            kind: "point".into(),
            frames: vec![a.into(), b.into()],
            axes: Some(axes.into()),
            ..Default::default()
        });
        self
    }

    /// A spring `½k(‖p_a − p_b‖ − rest)²` between two frames' origins.
    pub fn spring(mut self, a: &str, b: &str, stiffness: f64, rest: f64) -> Self {
        self.spec.springs.push(SpringSpec {
            frames: Some(vec![a.into(), b.into()]),
            variable: None,
            stiffness: Some(stiffness),
            rest: Some(rest),
        });
        self
    }

    /// A spring `½k(q − rest)²` on one variable.
    pub fn variable_spring(mut self, var: &str, stiffness: f64, rest: f64) -> Self {
        self.spec.springs.push(SpringSpec {
            frames: None,
            variable: Some(var.into()),
            stiffness: Some(stiffness),
            rest: Some(rest),
        });
        self
    }

    /// A damper with force `−c·ḋ` along the line between two frames' origins.
    pub fn damper(mut self, a: &str, b: &str, damping: f64) -> Self {
        self.spec.dampers.push(DamperSpec {
            frames: vec![a.into(), b.into()],
            damping: Some(damping),
        });
        self
    }

    /// Validates the model built so far: every problem at once, as for a file.
    pub fn build(self) -> Result<Model, ModelError> {
        let result = validate(&self.spec);
        let mut problems = self.pending;
        match result {
            Ok(model) if problems.is_empty() => Ok(model),
            Ok(_) => Err(ModelError {
                source_name: None,
                problems,
            }),
            Err(mut more) => {
                problems.append(&mut more);
                Err(ModelError {
                    source_name: None,
                    problems,
                })
            }
        }
    }
}

/// The paper's N-link pendulum (Fig. 3): link i is `rx(q_i)` then `tz(−1)` carrying a 1 kg
/// point mass. Variables `q1 … qN`, all starting at rest; `q1 = 0.5` so it swings.
/// `n` must be at least 1 (a model needs a variable); `n = 0` panics.
pub fn n_link_pendulum(n: usize) -> Model {
    let mut b = ModelBuilder::new(&format!("pendulum-{n}"));
    let mut parent = "world".to_string();
    for i in 1..=n {
        let joint = format!("joint{i}");
        let link = format!("link{i}");
        b = b
            .frame(&joint, &parent, PrimitiveKind::Rx, format!("q{i}").as_str())
            .frame(&link, &joint, PrimitiveKind::Tz, -1.0)
            .mass(&link, 1.0, [0.0; 3]);
        parent = link;
    }
    b = b.initial("q1", 0.5, 0.0);
    b.build().expect("the N-link pendulum is a valid model")
}
