//! # tree_model!
//!
//! Compiles a tree model into a concrete type implementing `tree_mech::System`, its
//! evaluations unrolled into straight-line Rust for that one topology: the runtime's
//! recursions are run at compile time over a tracing scalar (module `trace`), which folds constants
//! (constant transform chains included), drops structurally zero terms (massless branches,
//! zero inertias, the untouched columns of each primitive) and records what is left
//! (module `program`). The model is validated by `tree-model`, the same code the interpreted
//! runtime uses; every problem is a compile error at the token, or the file line, at fault.
//!
//! ```ignore
//! tree_mech::tree_model! {
//!     pub struct DoublePendulum;
//!     gravity = [0.0, 0.0, -9.81];
//!     frame shoulder = rx(theta1) {
//!         frame upper = tz(-1.0) {
//!             mass = 1.0;
//!             frame elbow = rx(theta2) {
//!                 frame lower = tz(-1.0) { mass = 1.0; inertia = [0.0, 0.0, 0.0]; }
//!             }
//!         }
//!     }
//!     variable theta1 { q0 = 0.5; dq0 = 0.0; damping = 0.0; }
//! }
//! tree_mech::tree_model!(pub struct Humanoid from "models/humanoid.toml");
//! ```
//!
//! Use it through the `tree-mech` facade: the expansion names `::tree_mech`.

mod ast;
mod expand;
mod lower;
mod program;
mod system_impl;
mod trace;

use proc_macro::TokenStream;
use syn::parse_macro_input;

/// Compiles a tree model into a type implementing `tree_mech::System`, its evaluation
/// unrolled into straight-line Rust for that one tree (generated ≡ interpreted to 1e-12).
///
/// # From a file
///
/// ```ignore
/// tree_mech::tree_model!(pub struct Humanoid from "models/humanoid.toml");
/// tree_mech::tree_model!(pub struct Solo from "models/solo12.urdf", floating_base);
/// tree_mech::tree_model!(pub struct SoloStand from "models/solo12.urdf", floating_base,
///     contacts from "tasks/solo12-stand.toml");
/// ```
///
/// The path is relative to the calling crate's `Cargo.toml`; TOML or URDF by extension
/// (`floating_base` adds `root_x root_y root_z root_yaw root_pitch root_roll` under a URDF
/// robot's root link; `contacts from` adds the ground, contacts and enforced limits a TOML
/// file — a task's, say — writes; `enforce_limits = false` leaves the limits unenforced). The same reader and validator as the runtime; editing the file
/// rebuilds. A file's errors are compile errors naming `file:line`.
///
/// # Inline
///
/// ```ignore
/// tree_mech::tree_model! {
///     /// Attributes and doc comments go on the struct.
///     pub struct Swing;
///     gravity = [0.0, 0.0, -9.81];                        // optional (this is the default)
///     // frame NAME = PRIMITIVE(VARIABLE | NUMBER) { settings and child frames }
///     // PRIMITIVE: tx ty tz (translations, m) | rx ry rz (rotations, rad)
///     frame x = tx(x) { frame y = ty(y) { frame bob = tz(z) {
///         mass = 1.0;                                     // kg
///         com = [0.0, 0.0, 0.0];                          // centre of mass in the frame, m
///         inertia = [0.01, 0.01, 0.01];                   // principal Ixx Iyy Izz, or
///                                                         // [xx, yy, zz, xy, xz, yz], kg m²
///     } } }
///     frame hand = ty(hand) { frame hand_top = tz(1.0); } // no settings: end in `;`
///     frame wall = tz(0.0);
///     // variable NAME { q0; dq0; damping (N·s/m or N·m·s/rad); limits; kinematic; motion }
///     variable z { q0 = -0.5; dq0 = 0.0; damping = 0.1; limits = [-2.0, 0.0]; }
///     variable hand { kinematic = true; motion = sine(offset = 0.0, amplitude = 0.2,
///                                                     frequency = 0.5, phase = 0.0); }
///     variable len { kinematic = true; samples = [[0.0, 1.5], [2.0, 1.2], [4.0, 1.5]]; }
///     // constraint NAME = distance | plane | point (FRAME_A, FRAME_B) { … }
///     constraint string = distance(bob, hand_top) { length = len; }  // or a number
///     constraint keep = plane(wall, bob) { normal = [1.0, 0.0, 0.0]; } // in FRAME_A's axes
///     // constraint rail = point(a, b) { axes = xz; }                  // world axes held equal
///     spring(bob, hand_top) { stiffness = 20.0; rest = 0.3; }         // between two frames
///     spring(z) { stiffness = 5.0; rest = 0.0; }                      // on one variable
///     damper(bob, hand_top) { damping = 0.7; }                        // along the line
/// }
/// ```
///
/// Names are Rust identifiers (a TOML file's may be any string); the model's name is the
/// struct's. A variable is created by the first frame it drives (each variable drives one
/// frame; a constraint's length may be a kinematic variable of its own). Kinematic
/// variables follow `motion` (a sine `offset + amplitude·sin(2π·frequency·t + phase)`),
/// `samples` (a cubic spline through `[t, q]` pairs) or, without either, `q0 + dq0·t`.
/// Every problem is a compile error at the token at fault.
///
/// # What the type gets
///
/// A unit struct: `Swing` (or `Swing::new()`, a `const fn`) is a value, holding no state.
/// Constants: `DOF`, `VARIABLES`, `FRAMES`, `Q0`, `DQ0`, `DAMPING`, `KINEMATIC`,
/// `CONSTRAINTS` (the constraint equations' names), `STATEMENTS` (one full evaluation's
/// size), an index per variable (`Swing::Z`) and per frame (`Swing::FRAME_BOB`); `model()`,
/// the same model for the interpreted runtime (`TreeSystem::new(&Swing::model())`); and the
/// `System` impl (`lagrangian`, `constraints`, `poses`, `initial_state()` from `q0`/`dq0`),
/// over `nalgebra::Const<DOF>` so nothing is allocated per step.
#[proc_macro]
pub fn tree_model(input: TokenStream) -> TokenStream {
    let input = parse_macro_input!(input as ast::Input);
    expand::expand(input)
        .unwrap_or_else(syn::Error::into_compile_error)
        .into()
}
