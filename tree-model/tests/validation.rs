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
    assert_eq!(m.frames[2].mass.unwrap().diagonal(), Some([1.0, 2.0, 3.0]));
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
        &["m.toml:10:", "frame `b`: inertia [1, -2, inf] must be finite"],
    );
}

/// `body` is the frame's fields after `mass = 1`; the frame starts on line 5.
fn body_error(body: &str) -> String {
    error_of(&format!(
        "{GOOD_HEAD}[[frame]]\nname = \"b\"\nparent = \"a\"\ntz = 1\nmass = 1\n{body}\n"
    ))
}

#[test]
fn full_rigid_bodies_parse_and_bad_ones_are_named() {
    let m = from_toml_str(
        &format!("{GOOD_HEAD}[[frame]]\nname = \"b\"\nparent = \"a\"\ntz = 1\nmass = 2\ncom = [0.1, 0.2, 0.3]\ninertia = [1, 2, 2.5, 0.1, -0.2, 0.3]\n"),
        None,
    )
    .unwrap();
    let b = m.frames[1].mass.unwrap();
    assert_eq!(b.com, [0.1, 0.2, 0.3]);
    assert_eq!(b.inertia6(), [1.0, 2.0, 2.5, 0.1, -0.2, 0.3]);
    assert_eq!(b.inertia[1][0], 0.1, "symmetric");
    assert_eq!(b.diagonal(), None);

    // Zeros with rounding noise (iCub's ankle: ixz = 1.35525e-20 on 0.27 kg) are a point mass,
    // within what the mass has a micrometre from its centre; a tensor negative beyond that
    // is not.
    let noisy = |ixz: &str| {
        format!("{GOOD_HEAD}[[frame]]\nname = \"b\"\nparent = \"a\"\ntz = 1\nmass = 0.2675\ninertia = [0, 0, 0, 0, {ixz}, 0]\n")
    };
    assert!(from_toml_str(&noisy("1.35525e-20"), None).is_ok());
    let e = from_toml_str(&noisy("1e-9"), None).unwrap_err().to_string();
    assert!(e.contains("is not positive semi-definite"), "{e}");
    let e = body_error("inertia = [1, 1, 1, 2, 0, 0]");
    assert!(
        e.contains("m.toml:10:")
            && e.contains("frame `b`: inertia [1, 1, 1, 2, 0, 0] is not positive semi-definite"),
        "{e}"
    );
    let e = body_error("inertia = [1, 1, 3]");
    assert!(
        e.contains("m.toml:10:")
            && e.contains("breaks the triangle inequality: principal moment 3")
            && !e.contains("welded"),
        "{e}"
    );
    let e = body_error("inertia = [1, 1, 1, 0]");
    assert!(
        e.contains("inertia has 4 numbers; give 3 (ixx, iyy, izz) or 6"),
        "{e}"
    );
    let e = body_error("com = [0, nan, 0]");
    assert!(
        e.contains("m.toml:10:") && e.contains("frame `b`: com [0, NaN, 0] must be finite"),
        "{e}"
    );
    // A rod: principal moments (0, I, I) are on the triangle's edge, and allowed.
    assert!(from_toml_str(
        &format!("{GOOD_HEAD}[[frame]]\nname = \"b\"\nparent = \"a\"\ntz = 1\nmass = 1\ninertia = [0.5, 0.5, 0]\n"),
        None
    )
    .is_ok());
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
fn an_unquoted_name_is_said_to_need_quotes() {
    let text = GOOD_HEAD.replace("rx = \"q\"", "rx = theta");
    assert_reports(
        &text,
        &["m.toml:4: TOML error", "write \"theta\" in quotes"],
    );
    // A number or a boolean misspelt gets no such hint.
    let msg = error_of(&GOOD_HEAD.replace("rx = \"q\"", "rx = 1.2.3"));
    assert!(!msg.contains("quotes"), "{msg}");
}

#[test]
fn non_finite_gravity_names_its_line() {
    let text = GOOD_HEAD.replace("name = \"t\"\n", "name = \"t\"\ngravity = [0, 0, -inf]\n");
    assert_reports(
        &text,
        &["m.toml:2: gravity must be three finite numbers, got [0, 0, -inf]"],
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
    // Read from a string with no file name, the message still names the line.
    let e = tree_model::from_toml_str("[[frame]]\nname = 1\n", None).unwrap_err();
    assert!(
        e.to_string()
            .starts_with("line 2: TOML error: invalid type"),
        "{e}"
    );
}

/// A two-link arm with a hook, a control point moved by kinematic `cx`, and room for elements.
const ARM: &str = r#"name = "arm"
[[frame]]
name = "a"
rx = "q"
[[frame]]
name = "b"
parent = "a"
tz = -1
mass = 1
[[frame]]
name = "c"
parent = "b"
ry = "r"
[[frame]]
name = "d"
parent = "c"
tx = 0.5
mass = 1
[[frame]]
name = "control"
ty = "cx"
[variables.cx]
kinematic = true
"#; // lines 1-23

#[test]
fn kinematic_variables_elements_and_their_motions_parse() {
    let text = format!(
        "{ARM}[variables.len]\nkinematic = true\nsamples = [[0, 1], [1, 1.2], [2, 1.1]]\n\
         [[constraint]]\nname = \"s\"\nkind = \"distance\"\nframes = [\"d\", \"control\"]\nlength = \"len\"\n\
         [[spring]]\nframes = [\"b\", \"control\"]\nstiffness = 3\nrest = 0.2\n\
         [[spring]]\nvariable = \"r\"\nstiffness = 1\n\
         [[damper]]\nframes = [\"b\", \"d\"]\ndamping = 0.5\n"
    );
    let m = from_toml_str(&text, None).unwrap();
    // Frames' variables first, then the constraint's length.
    let names: Vec<&str> = m.variables.iter().map(|v| v.name.as_str()).collect();
    assert_eq!(names, ["q", "r", "cx", "len"]);
    assert_eq!(m.dynamic(), [0, 1]);
    assert_eq!(m.kinematic(), [2, 3]);
    assert!(m.variables[3].frame.is_none());
    assert_eq!(
        m.variables[3].q0, 1.0,
        "a spline starts at its first sample"
    );
    assert_eq!(
        (m.constraints.len(), m.springs.len(), m.dampers.len()),
        (1, 2, 1)
    );
}

#[test]
fn constraint_problems_name_their_line() {
    let entry = |body: &str| format!("{ARM}[[constraint]]\n{body}");
    // The entry starts on line 24 (`[[constraint]]`), its fields on the lines after it.
    assert_reports(
        &entry("name = \"s\"\nkind = \"distance\"\nframes = [\"d\", \"nowhere\"]\nlength = 1\n"),
        &["m.toml:27: constraint `s`: unknown frame `nowhere`"],
    );
    assert_reports(
        &entry("name = \"s\"\nkind = \"distance\"\nframes = [\"d\", \"d\"]\nlength = 1\n"),
        &["m.toml:27: constraint `s`: connects frame `d` to itself"],
    );
    assert_reports(
        &entry("name = \"s\"\nkind = \"rope\"\nframes = [\"d\", \"b\"]\n"),
        &["m.toml:26: constraint `s`: unknown kind `rope`: expected distance, plane or point"],
    );
    assert_reports(
        &entry("name = \"s\"\nkind = \"distance\"\nframes = [\"d\", \"b\"]\n"),
        &["m.toml:24: constraint `s`: a distance constraint needs `length`"],
    );
    assert_reports(
        &entry("name = \"s\"\nkind = \"distance\"\nframes = [\"d\", \"b\"]\nlength = 1\nnormal = [0, 0, 1]\n"),
        &["m.toml:29: constraint `s`: `normal` does not belong to a distance constraint"],
    );
    assert_reports(
        &entry("name = \"s\"\nkind = \"plane\"\nframes = [\"d\", \"b\"]\nnormal = [0, 0, 0]\n"),
        &["m.toml:28: constraint `s`: normal [0, 0, 0] must be finite and not zero"],
    );
    assert_reports(
        &entry("name = \"s\"\nkind = \"plane\"\nframes = [\"d\", \"b\"]\n"),
        &["m.toml:24: constraint `s`: a plane constraint needs `normal`"],
    );
    assert_reports(
        &entry("name = \"s\"\nkind = \"point\"\nframes = [\"d\", \"b\"]\naxes = \"xw\"\n"),
        &["m.toml:28: constraint `s`: axes `xw` must list some of x, y, z, each once"],
    );
    assert_reports(
        &entry("name = \"s\"\nkind = \"point\"\nframes = [\"d\", \"b\"]\naxes = \"xx\"\n"),
        &["axes `xx` must list some of x, y, z, each once"],
    );
    assert_reports(
        &entry("name = \"s\"\nkind = \"distance\"\nframes = [\"d\", \"b\"]\nlength = -1\n"),
        &["m.toml:28: constraint `s`: length -1 must be finite and not negative"],
    );
    assert_reports(
        &entry("name = \"s\"\nkind = \"distance\"\nframes = [\"d\", \"b\"]\nlength = \"ghost\"\n"),
        &["m.toml:28: constraint length `ghost` is not a variable"],
    );
    assert_reports(
        &entry("name = \"s\"\nkind = \"distance\"\nframes = [\"d\"]\nlength = 1\n"),
        &["m.toml:27: constraint `s`: `frames` must name exactly two frames, found 1"],
    );
    // Duplicate names (the second entry starts on line 29).
    let twice = format!(
        "{ARM}[[constraint]]\nname = \"s\"\nkind = \"point\"\nframes = [\"d\", \"b\"]\naxes = \"x\"\n\
         [[constraint]]\nname = \"s\"\nkind = \"point\"\nframes = [\"d\", \"b\"]\naxes = \"y\"\n"
    );
    assert_reports(
        &twice,
        &["m.toml:30: duplicate constraint name `s` (constraints 1 and 2 of the list)"],
    );
    // More equations than dynamic variables (two: q and r).
    let three = format!(
        "{ARM}[[constraint]]\nname = \"s\"\nkind = \"point\"\nframes = [\"d\", \"control\"]\naxes = \"xyz\"\n"
    );
    assert_reports(
        &three,
        &["3 constraint equations but only 2 dynamic variables"],
    );
}

#[test]
fn spring_and_damper_problems_name_their_line() {
    assert_reports(
        &format!("{ARM}[[spring]]\nframes = [\"b\", \"d\"]\nstiffness = -2\n"),
        &["m.toml:26: spring 1: stiffness -2 must be finite and not negative"],
    );
    assert_reports(
        &format!("{ARM}[[spring]]\nframes = [\"b\", \"d\"]\nstiffness = 2\nrest = -1\n"),
        &["m.toml:27: spring 1: rest -1 must be finite and not negative"],
    );
    assert_reports(
        &format!("{ARM}[[spring]]\nvariable = \"cx\"\nstiffness = 2\n"),
        &["m.toml:25: spring 1: variable `cx` is kinematic"],
    );
    assert_reports(
        &format!("{ARM}[[spring]]\nframes = [\"b\", \"d\"]\nvariable = \"q\"\nstiffness = 2\n"),
        &["m.toml:24: spring 1: give either `frames` (two frames) or `variable`"],
    );
    assert_reports(
        &format!("{ARM}[[spring]]\nframes = [\"b\", \"zz\"]\nstiffness = 2\n"),
        &["m.toml:25: spring 1: unknown frame `zz`"],
    );
    assert_reports(
        &format!("{ARM}[[damper]]\nframes = [\"b\", \"d\"]\ndamping = -0.5\n"),
        &["m.toml:26: damper 1: damping -0.5 must be finite and not negative"],
    );
    assert_reports(
        &format!("{ARM}[[damper]]\nframes = [\"b\", \"d\"]\n"),
        &["m.toml:24: damper 1: `damping` is missing"],
    );
}

#[test]
fn kinematic_variable_problems_name_their_line() {
    let head = ARM.replace("[variables.cx]\nkinematic = true\n", "");
    // The [variables.cx] table starts on line 22.
    assert_reports(
        &format!("{head}[variables.cx]\nmotion = {{ amplitude = 1.0 }}\n"),
        &["m.toml:22: variable `cx` has a prescribed motion but is dynamic"],
    );
    assert_reports(
        &format!("{head}[variables.cx]\nkinematic = true\ndamping = 0.1\n"),
        &["m.toml:22: variable `cx` is kinematic: damping has no effect"],
    );
    assert_reports(
        &format!("{head}[variables.cx]\nkinematic = true\nsamples = [[0, 1], [0, 2]]\n"),
        &["m.toml:22: variable `cx`: samples must be at least two finite [t, q] pairs with t strictly increasing"],
    );
    assert_reports(
        &format!("{head}[variables.cx]\nkinematic = true\nsamples = [[0, 1], [1, nan]]\n"),
        &["samples must be at least two finite"],
    );
    // Times spanning ±1e308: finite samples whose curve is not (`check` printed q0 = NaN).
    assert_reports(
        &format!("{head}[variables.cx]\nkinematic = true\nsamples = [[-1e308, 0], [1e308, 1]]\n"),
        &["m.toml:22: variable `cx`: samples must be", "stays finite"],
    );
    assert_reports(
        &format!("{head}[variables.cx]\nkinematic = true\nsamples = [[0, 1], [1, 2]]\nmotion = {{ amplitude = 1.0 }}\n"),
        &["give `motion` or `samples`, not both"],
    );
    assert_reports(
        &format!("{head}[variables.cx]\nkinematic = true\nmotion = {{ frequency = -1.0 }}\n"),
        &["motion frequency must not be negative"],
    );
    // A frame-less length variable must be kinematic.
    assert_reports(
        &format!("{ARM}[variables.len]\nq0 = 1\n[[constraint]]\nname = \"s\"\nkind = \"distance\"\nframes = [\"d\", \"control\"]\nlength = \"len\"\n"),
        &["m.toml:24: variable `len` sets a constraint length but drives no frame: it must be kinematic"],
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

#[test]
fn reading_toml_takes_time_linear_in_its_size() {
    // `check` on a 20 000-frame chain took 22–46 s when every field's line was found by
    // rescanning the text. Eight times the frames must take about eight times as long, not
    // 64 (a complexity, not a speed: the bound of 20 is twice the ratio measured, about 10, and a
    // third of the quadratic one, beyond the machine's noise in every one of three repeats).
    let chain = |n: usize| {
        let mut s = String::from("name = \"c\"\n");
        for k in 0..n {
            let parent = if k == 0 {
                String::new()
            } else {
                format!("parent = \"l{}\"\n", k - 1)
            };
            s += &format!("[[frame]]\nname = \"j{k}\"\n{parent}rx = \"q{k}\"\n[[frame]]\nname = \"l{k}\"\nparent = \"j{k}\"\ntz = -1.0\nmass = 1.0\n");
        }
        s
    };
    let time = |n: usize| {
        let text = chain(n);
        let start = std::time::Instant::now();
        let model = tree_model::from_toml_str(&text, None).unwrap();
        assert_eq!(model.dof(), n);
        start.elapsed().as_secs_f64()
    };
    time(1_500);
    let ratio = (0..3)
        .map(|_| time(12_000) / time(1_500))
        .fold(f64::INFINITY, f64::min);
    assert!(
        ratio < 20.0,
        "eight times the chain took {ratio:.1}× the time"
    );
}

#[test]
fn names_that_break_outputs_and_overflowing_settings_are_refused() {
    let pendulum = |frame: &str, variable: &str, extra: &str| {
        format!(
            "[[frame]]\nname = \"{frame}\"\nrx = \"{variable}\"\n[[frame]]\nname = \"bob\"\nparent = \"{frame}\"\ntz = -1.0\nmass = 1.0\n{extra}"
        )
    };
    let err = |text: &str| {
        tree_model::from_toml_str(text, Some("m.toml"))
            .unwrap_err()
            .to_string()
    };
    assert!(err(&pendulum("pivot", "", "")).starts_with(
        "m.toml:3: frame `pivot`: variable name `` is empty or holds a control character"
    ));
    assert!(
        err(&pendulum("piv\\not", "q", ""))
            .contains("frame name `piv\\not` is reserved, empty or holds a control character"),
        "{}",
        err(&pendulum("piv\\not", "q", ""))
    );
    // A comma is fine: CSV headers quote it.
    assert!(tree_model::from_toml_str(&pendulum("pivot", "x,y", ""), None).is_ok());
    let heavy = "[[frame]]\nname = \"a\"\nparent = \"bob\"\ntx = 0.0\nmass = 1e308\n[[frame]]\nname = \"b\"\nparent = \"bob\"\ntx = 0.0\nmass = 1e308\n";
    assert_eq!(
        err(&pendulum("pivot", "q", heavy)),
        "m.toml: the masses add up to more than a floating-point number holds (the total mass overflows)"
    );
    let spin = "[[frame]]\nname = \"s\"\nparent = \"bob\"\nrz = \"k\"\n[variables.k]\nkinematic = true\nmotion = { amplitude = 1.0, frequency = 1e155 }\n";
    assert!(
        err(&pendulum("pivot", "q", spin)).ends_with("variable `k`: motion with amplitude 1 and frequency 1e155 has an acceleration a·(2πf)² that overflows"),
        "{}",
        err(&pendulum("pivot", "q", spin))
    );
    let triple = "[[frame]]\nname = \"s\"\nparent = \"bob\"\nty = \"k\"\n[variables.k]\nkinematic = true\nsamples = [[0.0, 0.0], [1.0, 2.0, 3.0]]\n";
    assert_eq!(
        err(&pendulum("pivot", "q", triple)),
        "m.toml:15: variable `k`: sample 2 has 3 numbers; each sample is a pair [t, q]"
    );
}

#[test]
fn a_file_over_the_size_limit_is_refused_without_reading_it_whole() {
    // /dev/zero never ends: read through the cap, it is refused at 64 MiB.
    if !std::path::Path::new("/dev/zero").exists() {
        return;
    }
    let err = tree_model::from_toml_file("/dev/zero")
        .unwrap_err()
        .to_string();
    assert_eq!(
        err,
        "model file `/dev/zero` is larger than the limit of 64 MiB"
    );
    let err = tree_model::from_file("/dev/zero.urdf", Default::default()).unwrap_err();
    assert!(
        err.to_string().starts_with("cannot read model file"),
        "{err}"
    );
}

#[test]
fn a_spring_or_damper_between_coinciding_frames_is_named_at_validation() {
    // Two frames at the same point at the start: the force's direction is 0/0 (the run failed
    // at step 0 with "acceleration q̈ is not finite").
    let text = |element: &str| {
        format!(
            "[[frame]]\nname = \"a\"\ntx = \"x\"\nmass = 1.0\n[[frame]]\nname = \"b\"\nty = 0.0\n{element}"
        )
    };
    let err = |t: &str| {
        tree_model::from_toml_str(t, Some("m.toml"))
            .unwrap_err()
            .to_string()
    };
    assert_eq!(
        err(&text("[[spring]]\nframes = [\"a\", \"b\"]\nstiffness = 10.0\nrest = 0.5\n")),
        "m.toml:9: spring 1: frames `a` and `b` coincide at the initial configuration, where a spring of rest length 0.5 has no direction; start them apart (or use rest = 0)"
    );
    assert_eq!(
        err(&text("[[damper]]\nframes = [\"a\", \"b\"]\ndamping = 1.0\n")),
        "m.toml:9: damper 1: frames `a` and `b` coincide at the initial configuration, where a damper has no direction; start them apart"
    );
    // Zero rest length is smooth through d = 0; apart, both are fine.
    assert!(tree_model::from_toml_str(
        &text("[[spring]]\nframes = [\"a\", \"b\"]\nstiffness = 10.0\n"),
        None
    )
    .is_ok());
    let apart =
        text("[[damper]]\nframes = [\"a\", \"b\"]\ndamping = 1.0\n[variables.x]\nq0 = 0.1\n");
    assert!(tree_model::from_toml_str(&apart, None).is_ok());
}

#[test]
fn locking_renumbers_variables_and_turns_lengths_and_springs_into_constants() {
    use tree_model::{ConstraintKind, Joint, Lock, Parameter, SpringKind};
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../tests/models/elements.toml");
    let model = tree_model::from_toml_file(path).unwrap();
    let lock = |s: &str| Lock::parse(s).unwrap();
    let held = model.locked(&[lock("bend=0.25"), lock("len")]).unwrap();
    assert_eq!(held.dof(), model.dof() - 2);
    let names: Vec<&str> = held.variables.iter().map(|v| v.name.as_str()).collect();
    assert!(
        !names.contains(&"bend") && !names.contains(&"len"),
        "{names:?}"
    );
    // Every frame still drives the variable it drove, by name.
    for (f, g) in model.frames.iter().zip(&held.frames) {
        match (f.joint, g.joint) {
            (Joint::Variable(i), Joint::Variable(j)) => {
                assert_eq!(model.variables[i].name, held.variables[j].name)
            }
            (Joint::Variable(i), Joint::Constant(x)) => {
                assert_eq!(model.variables[i].name, "bend");
                assert_eq!(x, 0.25);
            }
            (a, b) => assert_eq!(a, b),
        }
    }
    // The string's length is its q0 now; the spring on `bend` is gone.
    let len_q0 = model.variables[model.variable_index("len").unwrap()].q0;
    assert!(held.constraints.iter().any(|c| matches!(
        c.kind,
        ConstraintKind::Distance { length: Parameter::Constant(l) } if l == len_q0
    )));
    assert_eq!(held.springs.len(), model.springs.len() - 1);
    assert!(held
        .springs
        .iter()
        .all(|s| !matches!(s.kind, SpringKind::Variable(j) if held.variables[j].name == "bend")));
}

#[test]
fn a_body_is_judged_with_the_bodies_welded_to_it() {
    // A 1 µg placeholder with a made-up tensor welded (by constant transforms) to a real
    // body: the rigid body the dynamics sees is their sum, which is physical.
    let welded = |piece: &str| {
        format!(
            "{GOOD_HEAD}mass = 2\ninertia = [0.02, 0.02, 0.01]\n\
             [[frame]]\nname = \"offset\"\nparent = \"a\"\ntz = 0.1\n\
             [[frame]]\nname = \"placeholder\"\nparent = \"offset\"\nrz = 0.3\n{piece}\n"
        )
    };
    let m = from_toml_str(
        &welded("mass = 1e-9\ninertia = [1e-6, 1e-6, 1e-6, 1e-6, 1e-6, 1e-6]"),
        None,
    );
    assert!(m.is_ok(), "{:?}", m.err().map(|e| e.to_string()));
    // A piece bad enough to spoil the sum is named, with the sum.
    let e = error_of(&welded("mass = 1e-3\ninertia = [1, 1, 30]"));
    assert!(
        e.contains("frame `placeholder`: inertia [1, 1, 30] breaks the triangle inequality")
            && e.contains("and the rigid body it is welded into (frames a, placeholder, fused across constant transforms, 2.001 kg) breaks the triangle inequality"),
        "{e}"
    );
}

/// The builder's distance constraint takes a number or a variable as its length; a mimic
/// there is refused in a sentence naming the constraint and the variable.
#[test]
fn a_mimic_is_no_constraint_length() {
    let err = ModelBuilder::new("m")
        .frame("a", "world", PrimitiveKind::Tx, "x")
        .mass("a", 1.0, [0.0; 3])
        .frame("b", "world", PrimitiveKind::Tz, 1.0)
        .distance("string", "a", "b", tree_model::MimicSpec::new("x"))
        .build()
        .unwrap_err()
        .to_string();
    assert!(
        err.contains(
            "distance constraint `string`: a length is a number or a variable, not a mimic of `x`"
        ),
        "{err}"
    );
}
