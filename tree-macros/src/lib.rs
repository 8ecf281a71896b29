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
//!         frame upper = tz(-1.0) { mass = 1.0; }
//!         frame elbow = rx(theta2) {
//!             frame lower = tz(-1.0) { mass = 1.0; inertia = [0.0, 0.0, 0.0]; }
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
mod trace;

use proc_macro::TokenStream;
use syn::parse_macro_input;

/// Compiles a tree model (inline, or `from "file.toml"` relative to the calling crate's
/// manifest directory) into a system type. See the crate documentation for the syntax.
#[proc_macro]
pub fn tree_model(input: TokenStream) -> TokenStream {
    let input = parse_macro_input!(input as ast::Input);
    expand::expand(input)
        .unwrap_or_else(syn::Error::into_compile_error)
        .into()
}
