//! Bad input never panics or hangs: the TOML and URDF readers, and the interpreted system built
//! from whatever they accept, on a property-based corpus of mangled model files — truncated,
//! bytes replaced, tokens spliced in (NaN, huge numbers, wrong types, brackets) — and on
//! generated pathological ones (cycles, a link with two parents, 20 000-deep nesting).

use proptest::prelude::*;
use tree_mech::integrate::{run, Method, SimOptions, ViSettings};
use tree_mech::model::{self, UrdfOptions};
use tree_mech::runtime::ModelMotions;
use tree_mech::{NoForce, Order, System, TreeSystem};

fn seed(path: &str) -> String {
    std::fs::read_to_string(std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join(path)).unwrap()
}

/// Whatever a reader accepts must also build and evaluate without a panic (errors are fine).
fn exercise(model: Result<model::Model, model::ModelError>) {
    let Ok(model) = model else { return };
    let Ok(mut sys) = TreeSystem::new(&model) else {
        return;
    };
    let (q, dq) = sys.initial_state();
    let terms = sys.evaluate(&q, &dq, Order::Full);
    let _ = terms.l;
    // A few steps: whatever a run hands out is finite (or the run is an error).
    for method in [Method::Vi(ViSettings::default()), Method::Rk4] {
        let options = SimOptions::new(method, 0.01, 0.03);
        let mut motion = ModelMotions::of(&sys);
        let _ = run(
            &mut sys,
            &q,
            &dq,
            &options,
            &mut NoForce,
            &mut motion,
            &mut |s| {
                let values = s.q.iter().chain(s.dq).chain(s.lambda);
                assert!(values
                    .chain([&s.energy, &s.violation])
                    .all(|x| x.is_finite()));
                Ok(())
            },
        );
    }
}

const TOKENS: [&str; 21] = [
    "nan",
    "inf",
    "-1e308",
    "1e308",
    "1e200",
    "1e-300",
    "\"x\"",
    "[",
    "]]",
    "{",
    "=",
    "\n[[frame]]\n",
    "<",
    "/>",
    "\"></joint>",
    "<link name=\"a\"/>",
    // Names with separators: a CSV header must survive them.
    "\"x,y\"",
    "\"a\\nb\"",
    "\"\"",
    // Deep XML (past the nesting limit) and an element heavy with attributes.
    DEEP_XML,
    MANY_ATTRIBUTES,
];

const DEEP_XML: &str = concat!(
    "<a><a><a><a><a><a><a><a><a><a><a><a><a><a><a><a><a><a><a><a><a><a><a><a><a>",
    "<a><a><a><a><a><a><a><a><a><a><a><a><a><a><a><a><a><a><a><a><a><a><a><a><a>",
    "<a><a><a><a><a><a><a><a><a><a><a><a><a><a><a><a><a><a><a><a><a><a><a><a><a>",
    "<a><a><a><a><a><a><a><a><a><a><a><a><a><a><a><a><a><a><a><a><a><a><a><a><a>",
    "<a><a><a><a><a>",
);

const MANY_ATTRIBUTES: &str = concat!(
    "<x a0=\"1\" a1=\"1\" a2=\"1\" a3=\"1\" a4=\"1\" a5=\"1\" a6=\"1\" a7=\"1\" a8=\"1\" a9=\"1\" ",
    "b0=\"1\" b1=\"1\" b2=\"1\" b3=\"1\" b4=\"1\" b5=\"1\" b6=\"1\" b7=\"1\" b8=\"1\" b9=\"1\" ",
    "c0=\"1\" c1=\"1\" c2=\"1\" c3=\"1\" c4=\"1\" c5=\"1\" c6=\"1\" c7=\"1\" c8=\"1\" c9=\"1\" ",
    "d0=\"1\" d1=\"1\" d2=\"1\" d3=\"1\" d4=\"1\" d5=\"1\" d6=\"1\" d7=\"1\" d8=\"1\" d9=\"1\" ",
    "e0=\"1\" e1=\"1\" e2=\"1\" e3=\"1\" e4=\"1\" e5=\"1\" e6=\"1\" e7=\"1\" e8=\"1\" e9=\"1\" ",
    "f0=\"1\" f1=\"1\" f2=\"1\" f3=\"1\" f4=\"1\" f5=\"1\" f6=\"1\" f7=\"1\" f8=\"1\" f9=\"1\" ",
    "g0=\"1\" g1=\"1\" g2=\"1\" g3=\"1\" g4=\"1\"/>",
);

/// A mangled copy of `text`: cut at `cut`, `byte` written at `at`, `token` spliced at `splice`.
fn mangle(text: &str, cut: usize, at: usize, byte: u8, splice: usize, token: &str) -> String {
    let mut bytes = text.as_bytes().to_vec();
    let n = bytes.len();
    if n > 0 {
        bytes[at % n] = byte;
        let s = splice % n;
        bytes.splice(s..s, token.bytes());
        bytes.truncate(cut % (bytes.len() + 1));
    }
    String::from_utf8_lossy(&bytes).into_owned()
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 400, ..ProptestConfig::default() })]

    #[test]
    fn mangled_toml_gives_a_result_never_a_panic(
        which in 0usize..4, cut in any::<usize>(), at in any::<usize>(), byte in any::<u8>(),
        splice in any::<usize>(), token in 0usize..TOKENS.len()
    ) {
        let file = ["models/double-pendulum.toml", "models/marionette.toml",
            "tests/models/elements.toml", "tests/models/bodies.toml"][which];
        let text = mangle(&seed(file), cut, at, byte, splice, TOKENS[token]);
        exercise(model::from_toml_str(&text, Some("fuzz.toml")));
    }

    #[test]
    fn mangled_urdf_gives_a_result_never_a_panic(
        which in 0usize..3, cut in any::<usize>(), at in any::<usize>(), byte in any::<u8>(),
        splice in any::<usize>(), token in 0usize..TOKENS.len(), floating in any::<bool>()
    ) {
        let file = ["models/ur5.urdf", "models/panda.urdf", "models/solo12.urdf"][which];
        let text = mangle(&seed(file), cut, at, byte, splice, TOKENS[token]);
        let options = UrdfOptions { floating_base: floating, ..Default::default() };
        exercise(model::from_urdf_str(&text, Some("fuzz.urdf"), options));
    }

    /// Numbers anywhere in a valid file replaced by extreme values.
    #[test]
    fn extreme_numbers_are_refused_or_simulated_never_a_panic(
        which in 0usize..2, nth in 0usize..200, value in prop_oneof![
            Just("nan"), Just("-inf"), Just("1e308"), Just("-1e308"), Just("1e-320"), Just("0")]
    ) {
        let (file, urdf) = [("models/humanoid.toml", false), ("models/panda.urdf", true)][which];
        let text = seed(file);
        // The nth number-like token (digits with an optional sign and point).
        let re_like: Vec<(usize, usize)> = {
            let b = text.as_bytes();
            let mut out = Vec::new();
            let mut i = 0;
            while i < b.len() {
                if b[i].is_ascii_digit() {
                    let start = i;
                    while i < b.len() && (b[i].is_ascii_digit() || b[i] == b'.') { i += 1; }
                    out.push((start, i));
                } else { i += 1; }
            }
            out
        };
        let (s, e) = re_like[nth % re_like.len()];
        let text = format!("{}{}{}", &text[..s], value, &text[e..]);
        if urdf {
            exercise(model::from_urdf_str(&text, None, UrdfOptions::default()));
        } else {
            exercise(model::from_toml_str(&text, None));
        }
    }
}

#[test]
fn pathological_urdf_trees_are_named_errors_or_models() {
    let link = |i: usize| {
        format!("<link name=\"l{i}\"><inertial><mass value=\"1\"/><inertia ixx=\"1\" ixy=\"0\" ixz=\"0\" iyy=\"1\" iyz=\"0\" izz=\"1\"/></inertial></link>")
    };
    let joint = |i: usize, p: usize, c: usize| {
        format!("<joint name=\"j{i}\" type=\"revolute\"><parent link=\"l{p}\"/><child link=\"l{c}\"/><axis xyz=\"1 0 0\"/><origin xyz=\"0 0 0.1\"/><limit lower=\"-1\" upper=\"1\" effort=\"1\" velocity=\"1\"/></joint>")
    };
    // 20 000 links deep: read without recursion.
    let n = 20_000;
    let mut text = String::from("<robot name=\"deep\">");
    for i in 0..n {
        text += &link(i);
    }
    for i in 1..n {
        text += &joint(i, i - 1, i);
    }
    text += "</robot>";
    let m = model::from_urdf_str(&text, None, UrdfOptions::default()).unwrap();
    assert_eq!(m.dof(), n - 1);
    // Its sweeps would need 2·10⁸ Jacobian columns: refused up front, not allocated.
    let Err(e) = TreeSystem::new(&m) else {
        panic!("too deep to interpret")
    };
    assert!(e.to_string().contains("Jacobian columns"), "{e}");
    // A cycle through the root, and two parents.
    let cycle = format!(
        "<robot name=\"c\">{}{}{}{}</robot>",
        link(0),
        link(1),
        joint(1, 0, 1),
        joint(2, 1, 0)
    );
    let e = model::from_urdf_str(&cycle, None, UrdfOptions::default()).unwrap_err();
    assert!(e.to_string().contains("cycle"), "{e}");
    let two = format!(
        "<robot name=\"t\">{}{}{}{}{}</robot>",
        link(0),
        link(1),
        link(2),
        joint(1, 0, 2),
        joint(2, 1, 2)
    );
    let e = model::from_urdf_str(&two, None, UrdfOptions::default()).unwrap_err();
    assert!(e.to_string().contains("two parents"), "{e}");
}

#[test]
fn pathological_toml_is_a_named_error() {
    // 10 000 joints deep (a joint, then a link with a mass off its axis): valid.
    let mut text = String::new();
    let mut parent = "world".to_string();
    for i in 0..10_000 {
        text += &format!("[[frame]]\nname = \"f{i}\"\nparent = \"{parent}\"\nrx = \"q{i}\"\n");
        text += &format!("[[frame]]\nname = \"g{i}\"\nparent = \"f{i}\"\ntz = -0.1\nmass = 1.0\n");
        parent = format!("g{i}");
    }
    assert_eq!(model::from_toml_str(&text, None).unwrap().dof(), 10_000);
    // A frame that is its own parent, and deep bracket nesting.
    let e = model::from_toml_str(
        "[[frame]]\nname = \"a\"\nparent = \"a\"\nrx = \"q\"\n",
        None,
    )
    .unwrap_err();
    assert!(e.to_string().contains("`a`"), "{e}");
    let nested = format!("x = {}1{}", "[".repeat(10_000), "]".repeat(10_000));
    assert!(model::from_toml_str(&nested, None).is_err());
}
