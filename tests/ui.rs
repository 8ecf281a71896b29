//! Compile-time errors of `tree_model!`: each bad model is a compile error at the token or the
//! file line at fault (the expected messages are the `.stderr` files in `tests/ui/`).

#[test]
fn ui() {
    // trybuild compiles the cases from its own directory: let the macro resolve model paths
    // against this crate instead.
    std::env::set_var("CARGO_MANIFEST_DIR_OVERRIDE", env!("CARGO_MANIFEST_DIR"));
    let t = trybuild::TestCases::new();
    t.compile_fail("tests/ui/*.rs");
}
