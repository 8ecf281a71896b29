//! Every validation problem is reported with a message naming the frame or variable and the
//! TOML line it is on.

use tree_model::{from_toml_file, from_toml_str, n_link_pendulum, ModelBuilder, PrimitiveKind};

const GOOD_HEAD: &str = r#"name = "t"
[[frame]]
name = "a"
rx = "q"
"#; // lines 1-4

/// Parses `text` and returns the whole error message (panics if it parses).
fn error_of(text: &str) -> String {
    match from_toml_str(text, Some("m.toml")) {
        Ok(_) => panic!("model should be rejected:\n{text}"),
        Err(e) => e.to_string(),
    }
}

#[track_caller]
fn assert_reports(text: &str, expected: &[&str]) {
    let msg = error_of(text);
    for e in expected {
        assert!(msg.contains(e), "expected `{e}` in:\n{msg}");
    }
}

#[test]
fn a_valid_model_parses_with_variables_in_order_of_appearance() {
    let m = from_toml_str(
        &format!("{GOOD_HEAD}[[frame]]\nname = \"b\"\nparent = \"a\"\ntz = -1\nmass = 2\n[[frame]]\nname = \"c\"\nparent = \"b\"\nry = \"p\"\ninertia = [1, 2, 3]\n[variables.p]\nq0 = 0.25\ndamping = 0.5\n"),
        None,
    )
    .unwrap();
    assert_eq!(
        m.variables
            .iter()
            .map(|v| v.name.as_str())
            .collect::<Vec<_>>(),
        ["q", "p"]
    );
    assert_eq!(m.variables[1].q0, 0.25);
    assert_eq!(m.variables[1].damping, 0.5);
    assert_eq!(m.frames[1].mass.unwrap().mass, 2.0);
    assert_eq!(m.frames[2].mass.unwrap().inertia, [1.0, 2.0, 3.0]);
    assert_eq!(m.gravity, [0.0, 0.0, -9.81]);
}

#[test]
fn unknown_parent() {
    assert_reports(
        &format!(
            "{GOOD_HEAD}[[frame]]\nname = \"b\"\nparent = \"nowhere\"\ntz = 1.0\nmass = 1.0\n"
        ),
        &["m.toml:7:", "frame `b` has unknown parent `nowhere`"],
    );
}

#[test]
fn parent_listed_after_child() {
    assert_reports(
        &format!("{GOOD_HEAD}[[frame]]\nname = \"b\"\nparent = \"c\"\ntz = 1.0\n[[frame]]\nname = \"c\"\nparent = \"a\"\ntz = 1.0\nmass = 1.0\n"),
        &["m.toml:7:", "parent `c` is listed after its child"],
    );
}

#[test]
fn duplicate_frame_name() {
    assert_reports(
        &format!("{GOOD_HEAD}mass = 1.0\n[[frame]]\nname = \"a\"\nparent = \"a\"\ntz = 1.0\n"),
        &["m.toml:7:", "duplicate frame name `a`"],
    );
}

#[test]
fn frame_without_a_transform() {
    assert_reports(
        &format!("{GOOD_HEAD}[[frame]]\nname = \"b\"\nparent = \"a\"\nmass = 1.0\n"),
        &["m.toml:5:", "frame `b` has no transform"],
    );
}

#[test]
fn frame_with_several_transforms() {
    assert_reports(
        &format!(
            "{GOOD_HEAD}[[frame]]\nname = \"b\"\nparent = \"a\"\ntz = 1.0\nrx = 0.5\nmass = 1.0\n"
        ),
        &["m.toml:8:", "frame `b` has several transforms (tz, rx)"],
    );
}

#[test]
fn variable_driving_two_transforms() {
    assert_reports(
        &format!("{GOOD_HEAD}[[frame]]\nname = \"b\"\nparent = \"a\"\nry = \"q\"\n[[frame]]\nname = \"c\"\nparent = \"b\"\ntz = 1\nmass = 1\n"),
        &["m.toml:8:", "variable `q` drives frames `a` and `b`"],
    );
}

#[test]
fn negative_or_non_finite_mass_and_inertia() {
    assert_reports(
        &format!("{GOOD_HEAD}[[frame]]\nname = \"b\"\nparent = \"a\"\ntz = 1\nmass = -1.0\n"),
        &[
            "m.toml:9:",
            "frame `b`: mass -1 must be finite and not negative",
        ],
    );
    assert_reports(
        &format!("{GOOD_HEAD}[[frame]]\nname = \"b\"\nparent = \"a\"\ntz = 1\nmass = nan\n"),
        &["m.toml:9:", "frame `b`: mass NaN must be finite"],
    );
    assert_reports(
        &format!("{GOOD_HEAD}[[frame]]\nname = \"b\"\nparent = \"a\"\ntz = 1\nmass = 1\ninertia = [1, -2, inf]\n"),
        &["m.toml:10:", "frame `b`: inertia [1, -2, inf] must be finite and not negative"],
    );
}

#[test]
fn settings_for_a_variable_that_drives_nothing() {
    assert_reports(
        &format!("{GOOD_HEAD}inertia = [1, 1, 1]\n[variables.ghost]\nq0 = 1.0\n"),
        &[
            "m.toml:6:",
            "settings for variable `ghost`, which drives no transform",
        ],
    );
}

#[test]
fn model_without_variables() {
    assert_reports(
        "name = \"t\"\n[[frame]]\nname = \"a\"\ntz = 1.0\nmass = 1.0\n",
        &["m.toml: model has no configuration variables"],
    );
}

#[test]
fn variable_that_moves_no_mass() {
    // Nothing below `a` at all.
    assert_reports(GOOD_HEAD, &["m.toml:4:", "variable `q` moves no mass"]);
    // A point mass on the rotation axis, reached without translation.
    assert_reports(
        &format!("{GOOD_HEAD}mass = 3.0\n[[frame]]\nname = \"b\"\nparent = \"a\"\ntz = 1\nmass = 1\n[[frame]]\nname = \"c\"\nparent = \"b\"\nry = \"r\"\nmass = 2\n"),
        &["m.toml:14:", "variable `r` moves no mass"],
    );
}

#[test]
fn every_problem_is_reported_at_once() {
    let msg = error_of(&format!(
        "{GOOD_HEAD}[[frame]]\nname = \"b\"\nparent = \"x\"\ntz = 1\nmass = -1\n[[frame]]\nname = \"b\"\nparent = \"a\"\n"
    ));
    assert_eq!(msg.lines().count(), 4, "{msg}");
}

#[test]
fn toml_syntax_errors_and_unknown_fields_name_their_line() {
    assert_reports(
        "name = \"t\"\n[[frame]]\nname = \"a\"\nrx = = 1\n",
        &["m.toml:4:", "TOML error"],
    );
    assert_reports(
        &format!("{GOOD_HEAD}masss = 1.0\n"),
        &["m.toml:5:", "TOML error", "unknown field `masss`"],
    );
    assert_reports(
        &format!("{GOOD_HEAD}mass = \"heavy\"\n"),
        &["m.toml:5:", "TOML error"],
    );
}

#[test]
fn kinematic_variables_are_rejected_for_now() {
    assert_reports(
        &format!("{GOOD_HEAD}mass = 1\ninertia = [1, 1, 1]\n[variables.q]\nkinematic = true\n"),
        &["m.toml:7:", "kinematic"],
    );
}

#[test]
fn missing_file() {
    let e = from_toml_file("/no/such/model.toml")
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("cannot read model file `/no/such/model.toml`"),
        "{e}"
    );
}

#[test]
fn builder_validates_too_and_makes_pendulums_of_any_size() {
    let m = n_link_pendulum(40);
    assert_eq!(m.dof(), 40);
    assert_eq!(m.frames.len(), 80);
    let e = ModelBuilder::new("bad")
        .frame("a", "world", PrimitiveKind::Rx, "q")
        .mass("nope", 1.0, [0.0; 3])
        .build()
        .unwrap_err()
        .to_string();
    assert!(e.contains("mass given for unknown frame `nope`"), "{e}");
    assert!(e.contains("variable `q` moves no mass"), "{e}");
}
