//! The integration tests that need no `tree_model!`, as one binary (one link step instead of
//! eleven; as nalgebra's `tests/lib.rs`): the command line, constraints, derivatives against
//! finite differences, the discrete Lagrangian, errors, forcing, the fuzz corpus, frame
//! kinematics, units and the VI. Tests that compile a model keep a binary each, so that
//! changing one does not recompile the others' generated code.

#[macro_use]
mod common;
mod runtime;
