//! # tree-model
//!
//! The description of a mechanical system as a tree of frames (Johnson & Murphey, *Scalable
//! Variational Integrators for Constrained Mechanical Systems in Generalized Coordinates*,
//! §III): each frame hangs off its parent by one primitive transform (`tx ty tz rx ry rz`),
//! constant or driven by one configuration variable; masses sit at frame origins.
//!
//! Models come from TOML ([`from_toml_str`], [`from_toml_file`]), from the
//! [`ModelBuilder`], or from the `tree_model!` macro. All three produce a [`ModelSpec`]
//! that one validator turns into a [`Model`], so a model means the same on every path.

mod builder;
mod error;
mod model;
mod primitive;
mod spec;
mod toml_format;
mod validate;

pub use builder::{n_link_pendulum, ModelBuilder};
pub use error::{FrameField, ModelError, Problem, Site};
pub use model::{Frame, Joint, Mass, Model, Variable, DEFAULT_GRAVITY};
pub use primitive::{Primitive, PrimitiveKind, Value};
pub use spec::{FrameSpec, ModelSpec, VariableSpec};
pub use toml_format::{from_toml_file, from_toml_str};
pub use validate::validate;
