//! # tree-model
//!
//! The description of a mechanical system as a tree of frames (Johnson & Murphey, *Discrete and
//! Continuous Mechanics for Tree Representations of Mechanical Systems*, ICRA 2008, §II): each frame hangs off its parent by one primitive transform (`tx ty tz rx ry rz`),
//! constant or driven by one configuration variable; masses sit at frame origins.
//!
//! Models come from TOML ([`from_toml_str`], [`from_toml_file`]), from URDF
//! ([`from_urdf_str`], [`from_urdf_file`]; [`from_file`] picks by extension), from the
//! [`ModelBuilder`], or from the `tree_model!` macro. All three produce a [`ModelSpec`]
//! that one validator turns into a [`Model`], so a model means the same on every path.
//!
//! ```
//! let model = tree_model::from_toml_str(
//!     r#"
//!     [[frame]]
//!     name = "shoulder"
//!     rx = "theta"
//!     [[frame]]
//!     name = "bob"
//!     parent = "shoulder"
//!     tz = -1.0
//!     mass = 1.0
//!     [variables.theta]
//!     q0 = 0.5
//!     "#,
//!     Some("pendulum.toml"),
//! )?;
//! assert_eq!(model.dof(), 1);
//! assert_eq!(model.variables[0].q0, 0.5);
//! // Every problem at once, each with its line:
//! let err = tree_model::from_toml_str("[[frame]]\nname = \"a\"\nrx = \"q\"\nmass = -1.0\n", Some("bad.toml"))
//!     .unwrap_err();
//! assert!(err.to_string().starts_with("bad.toml:4: frame `a`: mass -1"));
//! # Ok::<(), tree_model::ModelError>(())
//! ```
#![warn(missing_docs)]

mod builder;
mod contact;
mod elements;
mod error;
mod integrator;
mod lock;
mod model;
mod motion;
mod number;
mod primitive;
mod rigid;
mod source;
mod spec;
mod suggest;
mod task;
mod toml_format;
mod urdf_format;
mod validate;

pub use builder::{n_link_pendulum, ModelBuilder};
pub use contact::{
    tangents, ContactSpec, ContactSphere, Contacts, ContactsSpec, Gap, GapKind, Ground, GroundSpec,
};
pub use error::{FrameField, ModelError, Problem, Section, Site};
pub use integrator::Integrator;
pub use lock::Lock;
pub use model::{
    Constraint, ConstraintKind, Damper, Frame, Input, Joint, Mass, Mimic, Model, Parameter, Spring,
    SpringKind, Variable, DEFAULT_GRAVITY,
};
pub use motion::{CubicSpline, Motion};
pub use number::{Counted, Given, Rounded};
pub use primitive::{MimicSpec, Primitive, PrimitiveKind, Value};
pub use source::{MAX_FILE_BYTES, MAX_XML_ATTRIBUTES, MAX_XML_DEPTH};
pub use spec::{
    ConstraintSpec, DamperSpec, FrameSpec, InputSpec, ModelSpec, ParameterSpec, SineSpec,
    SpringSpec, VariableSpec,
};
pub use suggest::nearest;
pub use task::{
    read_task, task_from_str, About, Control, CostTerm, Target, Task, TaskIntegrator, TaskSolver,
};
pub use toml_format::{from_toml_file, from_toml_str};
pub use urdf_format::{from_file, from_urdf_file, from_urdf_str, UrdfOptions, FLOATING_BASE};
pub use validate::validate;
