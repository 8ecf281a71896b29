//! The `tree-mech` command line: outputs, and one-line errors with a non-zero exit.

use std::process::Command;

pub(super) fn tree_mech(args: &[&str]) -> (bool, String, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_tree-mech"))
        .args(args)
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .output()
        .unwrap();
    (
        out.status.success(),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

#[test]
fn simulate_writes_a_trajectory_and_a_picture() {
    let dir = scratch("cli");
    let csv = dir.join("t.csv");
    let png = dir.join("t.png");
    for integrator in ["vi", "rk4", "rk45"] {
        let (ok, stdout, stderr) = tree_mech(&[
            "simulate",
            "models/double-pendulum.toml",
            "--integrator",
            integrator,
            "--dt",
            "0.01",
            "--duration",
            "1",
            "--out",
            csv.to_str().unwrap(),
            "--plot",
            png.to_str().unwrap(),
        ]);
        assert!(ok, "{stderr}");
        assert!(
            stdout.contains("Simulated `double-pendulum`") && stdout.contains("drift"),
            "{stdout}"
        );
        let text = std::fs::read_to_string(&csv).unwrap();
        let mut lines = text.lines();
        assert_eq!(
            lines.next().unwrap(),
            "t,theta1,theta2,dtheta1,dtheta2,energy"
        );
        let rows: Vec<&str> = lines.collect();
        if integrator != "rk45" {
            assert_eq!(rows.len(), 101);
        }
        assert!(rows.last().unwrap().starts_with('1'), "last time is 1 s");
        let png_bytes = std::fs::read(&png).unwrap();
        assert_eq!(&png_bytes[1..4], b"PNG");
    }
}

#[test]
fn eval_prints_every_term_as_json() {
    let (ok, stdout, stderr) =
        tree_mech(&["eval", "models/pendulum.toml", "--q", "0.3", "--dq", "-1"]);
    assert!(ok, "{stderr}");
    let v: serde_json::Value = serde_json::from_str(&stdout).unwrap();
    for key in [
        "variables",
        "L",
        "dL_dq",
        "dL_ddq",
        "M",
        "d2L_ddqdq",
        "d2L_dqdq",
        "qdd",
        "poses",
    ] {
        assert!(v.get(key).is_some(), "missing {key}");
    }
    // Pendulum: L = ½ θ̇² + 9.81 cos θ, q̈ = −9.81 sin θ, bob at (0, sin θ, −cos θ).
    let l = v["L"].as_f64().unwrap();
    assert!((l - (0.5 + 9.81 * 0.3f64.cos())).abs() < 1e-12);
    assert!((v["qdd"][0].as_f64().unwrap() + 9.81 * 0.3f64.sin()).abs() < 1e-12);
    assert!((v["poses"]["bob"][1][3].as_f64().unwrap() - 0.3f64.sin()).abs() < 1e-15);
    assert_eq!(v["variables"][0], "theta");
}

/// `eval --frame`: a frame's pose, Jacobian, twist and accelerations under the dynamics, and
/// the centre of mass — on the pendulum against its closed form (bob at (0, sin θ, −cos θ),
/// moving at θ̇ (0, cos θ, sin θ)), on the unforced cart-pole against the conservation of
/// horizontal momentum (c̈_x = 0).
#[test]
fn eval_reports_a_frames_kinematics_and_the_centre_of_mass() {
    let (ok, stdout, stderr) = tree_mech(&[
        "eval",
        "models/pendulum.toml",
        "--q",
        "0.3",
        "--dq",
        "-1",
        "--frame",
        "bob",
    ]);
    assert!(ok, "{stderr}");
    let v: serde_json::Value = serde_json::from_str(&stdout).unwrap();
    let bob = &v["frames"]["bob"];
    let (s, c) = (0.3f64.sin(), 0.3f64.cos());
    let at = |x: &serde_json::Value, i: usize| x[i].as_f64().unwrap();
    assert!((bob["pose"][1][3].as_f64().unwrap() - s).abs() < 1e-15);
    for (i, expected) in [(0, 0.0), (1, -c), (2, -s), (3, -1.0)] {
        assert!((at(&bob["velocity"], i) - expected).abs() < 1e-14, "{bob}");
    }
    assert!((at(&bob["jacobian"][1], 0) - c).abs() < 1e-15, "{bob}");
    // The origin's acceleration: θ̈ (0, cos θ, sin θ) + θ̇² (0, −sin θ, cos θ).
    let qdd = -9.81 * s;
    let expected = [0.0, qdd * c - s, qdd * s + c];
    for (i, e) in expected.iter().enumerate() {
        assert!(
            (at(&bob["classical_acceleration"], i) - e).abs() < 1e-12,
            "{bob}"
        );
    }
    let (ok, stdout, stderr) = tree_mech(&[
        "eval",
        "models/cartpole.toml",
        "--q",
        "0.1,0.4",
        "--dq",
        "0.5,-1",
    ]);
    assert!(ok, "{stderr}");
    let v: serde_json::Value = serde_json::from_str(&stdout).unwrap();
    let com = &v["center_of_mass"];
    assert!(at(&com["acom"], 0).abs() < 1e-12, "{com}");
    assert!(at(&com["acom"], 2).abs() > 0.1, "{com}");
    assert_eq!(v["frames"], serde_json::json!({}));
    let (ok, _, stderr) = tree_mech(&["eval", "models/cartpole.toml", "--frame", "hand"]);
    assert!(!ok);
    assert!(
        stderr
            .contains("--frame: there is no frame `hand`; the frames are `cart`, `pivot`, `pole`"),
        "{stderr}"
    );
}

#[test]
fn constrained_models_report_constraints_everywhere() {
    let model = "tests/models/string-pendulum.toml";
    // eval: the new fields, λ at rest at 0.5 rad: 2ℓλ = −m g cos θ.
    let (ok, stdout, stderr) = tree_mech(&["eval", model]);
    assert!(ok, "{stderr}");
    let v: serde_json::Value = serde_json::from_str(&stdout).unwrap();
    assert_eq!(v["dynamic"], serde_json::json!(["x", "y", "z"]));
    assert_eq!(v["kinematic"], serde_json::json!([]));
    assert_eq!(v["constraints"], serde_json::json!(["string"]));
    assert!(v["h"][0].as_f64().unwrap().abs() < 1e-12);
    assert_eq!(v["dh_dq"][0].as_array().unwrap().len(), 3);
    let lambda = v["lambda"][0].as_f64().unwrap();
    assert!(
        (3.0 * lambda + 9.81 * 0.5f64.cos()).abs() < 1e-9,
        "λ = {lambda}"
    );
    // simulate: λ and violation columns, every second step recorded, worst violation said.
    let dir = scratch("string");
    let csv = dir.join("t.csv");
    let (ok, stdout, stderr) = tree_mech(&[
        "simulate",
        model,
        "--duration",
        "0.1",
        "--every",
        "2",
        "--out",
        csv.to_str().unwrap(),
    ]);
    assert!(ok, "{stderr}");
    assert!(stdout.contains("Worst constraint violation"), "{stdout}");
    let text = std::fs::read_to_string(&csv).unwrap();
    let lines: Vec<&str> = text.lines().collect();
    assert_eq!(lines[0], "t,x,y,z,dx,dy,dz,energy,lambda_string,violation");
    assert_eq!(lines.len(), 1 + 6, "t = 0, 0.02, …, 0.1");
    // check: the constraint is listed.
    let (ok, stdout, _) = tree_mech(&["check", "tests/models/elements.toml"]);
    assert!(ok);
    for expected in [
        "string               distance `len` between `tip` and `hand_z`",
        "kinematic, 0.3 + 0.1·sin(2π·0.5·t + 0.3)",
        "spring on `bend`: k = 5, rest = 0.1",
        "damper between `lower` and `hand_z`: c = 0.7",
        "len                  sets a constraint length",
    ] {
        assert!(
            stdout.contains(expected),
            "missing `{expected}` in:\n{stdout}"
        );
    }
    // Extreme values read in exponent form, not as three hundred digits.
    let dir = scratch("check");
    let stiff = dir.join("stiff.toml");
    let text = std::fs::read_to_string("tests/models/elements.toml")
        .unwrap()
        .replace("stiffness = 5.0", "stiffness = 1e300")
        .replace("damping = 0.7", "damping = 2.5e-9")
        .replace("tz = 0.5\nmass = 1.0", "tz = -1e200\nmass = 1e250");
    std::fs::write(&stiff, text).unwrap();
    let (ok, stdout, _) = tree_mech(&["check", stiff.to_str().unwrap()]);
    assert!(ok);
    assert!(
        stdout.contains("spring on `bend`: k = 1e300, rest = 0.1") && stdout.contains("c = 2.5e-9"),
        "{stdout}"
    );
    // The masses' list and the tree too (a length and a mass as given, not 200 digits).
    assert!(
        stdout.contains("total mass 1e250 kg")
            && stdout.contains("tz(-1e200)  [m = 1e250, I = (")
            && !stdout.contains("00000000000"),
        "{stdout}"
    );
}

#[test]
fn check_draws_the_tree() {
    let (ok, stdout, _) = tree_mech(&["check", "models/humanoid.toml"]);
    assert!(ok);
    assert!(stdout.contains("22 variables"), "{stdout}");
    assert!(stdout.contains("└─ torso = rx(roll)"), "{stdout}");
}

/// `check` names a variable's followers beside its own frame; `--independent-mimics` makes
/// each URDF mimic joint a variable of its own.
#[test]
fn check_names_the_frames_that_follow_a_variable() {
    let (ok, stdout, stderr) = tree_mech(&["check", "tests/models/mimic.toml"]);
    assert!(ok, "{stderr}");
    assert!(
        stdout.contains(
            "grip                 drives `finger_a` by tx and `finger_b` by tx(-1·grip);"
        ),
        "{stdout}"
    );
    let (ok, stdout, stderr) = tree_mech(&["check", "models/panda-hand.urdf"]);
    assert!(ok && stdout.contains("8 variables"), "{stdout}{stderr}");
    let (ok, stdout, stderr) =
        tree_mech(&["check", "models/panda-hand.urdf", "--independent-mimics"]);
    assert!(ok && stdout.contains("9 variables"), "{stdout}{stderr}");
}

#[test]
fn bad_input_is_a_short_error_and_a_failing_exit() {
    let dir = scratch("bad");
    let bad = dir.join("bad.toml");
    std::fs::write(&bad, "name = \"bad\"\n[[frame]]\nname = \"a\"\nbogus = 2\n").unwrap();
    let bad_shown = format!("{}:4: TOML error: unknown field `bogus`", bad.display());
    let cases: [(&[&str], &str); 10] = [
        (
            &["simulate", "models/pendulum.toml", "--dt", "1e-300"],
            "the run needs 1.00e301 steps",
        ),
        (
            &["simulate", "models/pendulum.toml", "--every", "0"],
            "every K-th step needs K ≥ 1",
        ),
        (
            &["simulate", "models/pendulum.toml", "--baumgarte", "1"],
            "--baumgarte: `1` is not two numbers a,b",
        ),
        (
            &["eval", "models/pendulum.toml", "--t", "nan"],
            "--t: `NaN` is not a finite time",
        ),
        (&["check", "models/missing.toml"], "cannot read model file"),
        (&["simulate"], "required"),
        (
            &["eval", "models/pendulum.toml", "--q", "1,2"],
            "--q has 2 values; the model has 1 variable (theta)",
        ),
        (
            &["eval", "models/pendulum.toml", "--dq", "x"],
            "--dq: `x` is not a finite number",
        ),
        (
            &["simulate", "models/pendulum.toml", "--dt", "-1"],
            "time step must be a positive finite number",
        ),
        (&["check", bad.to_str().unwrap()], &bad_shown),
    ];
    for (args, expected) in cases {
        let (ok, _, stderr) = tree_mech(args);
        assert!(!ok, "{args:?} should fail");
        assert!(
            stderr.starts_with("error: ") && stderr.contains(expected),
            "{args:?}: {stderr}"
        );
        assert!(!stderr.contains("panicked"), "{stderr}");
    }
}

#[test]
fn simulate_animates_the_marionette_and_plots_its_constraint_forces() {
    let dir = scratch("anim");
    let (gif, png) = (dir.join("m.gif"), dir.join("m.png"));
    let (ok, stdout, stderr) = tree_mech(&[
        "simulate",
        "models/marionette.toml",
        "--duration",
        "0.4",
        "--animate",
        gif.to_str().unwrap(),
        "--plot",
        png.to_str().unwrap(),
    ]);
    assert!(ok, "{stderr}");
    assert!(stdout.contains("Animation: "), "{stdout}");
    let bytes = std::fs::read(&gif).unwrap();
    assert_eq!(&bytes[..6], b"GIF89a");
    // 0.4 s at 25 frames a second: frames at 0, 0.04, …, 0.4, each 640×480.
    let mut decoder = gif::DecodeOptions::new()
        .read_info(std::io::Cursor::new(&bytes))
        .unwrap();
    assert_eq!((decoder.width(), decoder.height()), (640, 480));
    let mut frames = 0;
    while let Some(frame) = decoder.read_next_frame().unwrap() {
        assert_eq!(frame.delay, 4, "40 ms a frame");
        frames += 1;
    }
    assert_eq!(frames, 11, "GIF frames");
    // Nine panels of 280 pixels: the 21 angles as three of 7 curves, the lengths, the 18
    // kinematic variables as three of 6, the energy, the multipliers.
    let png = std::fs::read(&png).unwrap();
    let width = u32::from_be_bytes(png[16..20].try_into().unwrap());
    let height = u32::from_be_bytes(png[20..24].try_into().unwrap());
    assert_eq!(width, 1200);
    assert_eq!(height, 9 * 280);
}

#[test]
fn huge_energies_are_printed_in_scientific_notation() {
    let dir = scratch("huge");
    let model = dir.join("heavy.toml");
    std::fs::write(
        &model,
        "[[frame]]\nname = \"j\"\nrx = \"q\"\n[[frame]]\nname = \"b\"\nparent = \"j\"\n\
         tz = -1.0\nmass = 1e300\n[variables.q]\nq0 = 0.5\n",
    )
    .unwrap();
    let (ok, stdout, stderr) =
        tree_mech(&["simulate", model.to_str().unwrap(), "--duration", "0.1"]);
    assert!(ok, "{stderr}");
    let summary = stdout.lines().last().unwrap();
    assert!(summary.contains("Energy went from -8.6"), "{summary}");
    assert!(summary.contains("e300"), "{summary}");
    assert!(summary.len() < 400, "no 300-digit numbers: {summary}");
}

#[test]
fn a_closed_pipe_ends_the_output_quietly() {
    use std::io::Read;
    use std::process::Stdio;
    let mut child = Command::new(env!("CARGO_BIN_EXE_tree-mech"))
        .args(["check", "models/marionette.toml"])
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // Read one byte, then close the pipe as `| head -c 1` would.
    let mut first = [0u8; 1];
    child.stdout.take().unwrap().read_exact(&mut first).unwrap();
    let mut stderr = String::new();
    child
        .stderr
        .take()
        .unwrap()
        .read_to_string(&mut stderr)
        .unwrap();
    child.wait().unwrap();
    assert!(!stderr.contains("panicked"), "{stderr}");
}

#[test]
fn urdf_models_are_read_wherever_toml_is() {
    let (ok, stdout, stderr) = tree_mech(&["check", "models/ur5.urdf"]);
    assert!(ok, "{stderr}");
    assert!(
        stdout.contains("model `ur5`: valid") && stdout.contains("6 variables"),
        "{stdout}"
    );
    assert!(
        stdout.contains("limits [-3.14159265359, 3.14159265359] (enforced)"),
        "{stdout}"
    );
    let (ok, stdout, stderr) = tree_mech(&["check", "models/solo12.urdf", "--floating-base"]);
    assert!(ok, "{stderr}");
    assert!(
        stdout.contains("18 variables") && stdout.contains("root_pitch"),
        "{stdout}"
    );
    let (ok, stdout, stderr) = tree_mech(&["eval", "models/panda.urdf"]);
    assert!(ok, "{stderr}");
    let v: serde_json::Value = serde_json::from_str(&stdout).unwrap();
    assert_eq!(v["variables"].as_array().unwrap().len(), 9);
    let (ok, stdout, stderr) = tree_mech(&[
        "simulate",
        "models/ur5.urdf",
        "--duration",
        "0.2",
        "--integrator",
        "rk4",
        "--dt",
        "0.001",
    ]);
    assert!(ok, "{stderr}");
    assert!(stdout.contains("Simulated `ur5` (6 variables)"), "{stdout}");
    let (ok, _, stderr) = tree_mech(&["check", "models/pendulum.toml", "--floating-base"]);
    assert!(
        !ok && stderr.contains("floating base is added to URDF models only"),
        "{stderr}"
    );
}

#[test]
fn a_sparsely_recorded_animation_still_plays_in_real_time() {
    let dir = scratch("anim-every");
    let gif = dir.join("p.gif");
    // Δt = 0.01 recorded every 10th step: a picture each 0.1 s, shown for 100 ms.
    let (ok, _, stderr) = tree_mech(&[
        "simulate",
        "models/double-pendulum.toml",
        "--duration",
        "1",
        "--every",
        "10",
        "--animate",
        gif.to_str().unwrap(),
    ]);
    assert!(ok, "{stderr}");
    let bytes = std::fs::read(&gif).unwrap();
    let mut decoder = gif::DecodeOptions::new()
        .read_info(std::io::Cursor::new(&bytes))
        .unwrap();
    let mut frames = 0;
    while let Some(frame) = decoder.read_next_frame().unwrap() {
        assert_eq!(frame.delay, 10, "100 ms a picture");
        frames += 1;
    }
    assert_eq!(frames, 11);
}

/// A fresh scratch directory for one test, removed when the test passes (a failing test's
/// files stay, to be looked at).
pub(super) struct Scratch(std::path::PathBuf);

impl std::ops::Deref for Scratch {
    type Target = std::path::Path;
    fn deref(&self) -> &std::path::Path {
        &self.0
    }
}

impl AsRef<std::path::Path> for Scratch {
    fn as_ref(&self) -> &std::path::Path {
        &self.0
    }
}

impl Drop for Scratch {
    fn drop(&mut self) {
        if !std::thread::panicking() {
            let _ = std::fs::remove_dir_all(&self.0);
        }
    }
}

pub(super) fn scratch(name: &str) -> Scratch {
    let dir = std::env::temp_dir().join(format!("tree-mech-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    Scratch(dir)
}

/// A shipped task file's text with its model path made absolute (to be written elsewhere).
pub(super) fn shipped_task(name: &str) -> String {
    let root = env!("CARGO_MANIFEST_DIR");
    std::fs::read_to_string(format!("{root}/tasks/{name}.toml"))
        .unwrap()
        .replace("../models/", &format!("{root}/models/"))
}

#[test]
fn outputs_never_overwrite_the_model_or_each_other_and_are_checked_before_the_run() {
    let dir = scratch("paths");
    let model = dir.join("m.toml");
    std::fs::copy(
        concat!(env!("CARGO_MANIFEST_DIR"), "/models/pendulum.toml"),
        &model,
    )
    .unwrap();
    let original = std::fs::read(&model).unwrap();
    let m = model.to_str().unwrap();
    let at = |name: &str| dir.join(name).to_str().unwrap().to_string();
    let dotted = format!("{}/./m.toml", dir.display());
    let (png, csv, missing) = (at("x.png"), at("x.csv"), at("missing/x.png"));
    let cases: [(Vec<&str>, &str); 6] = [
        (vec!["--out", m], "is the same file as"),
        (vec!["--out", &dotted], "is the same file as"),
        (vec!["--out", &png, "--plot", &png], "is the same file as"),
        (vec!["--plot", &csv], "the file name must end in .png"),
        (vec!["--animate", &png], "the file name must end in .gif"),
        (vec!["--plot", &missing], "does not exist"),
    ];
    for (args, expected) in cases {
        let mut all = vec!["simulate", m, "--duration", "1"];
        all.extend(args.iter().copied());
        let (ok, stdout, stderr) = tree_mech(&all);
        assert!(!ok && stdout.is_empty(), "{args:?}: {stdout}");
        assert!(
            stderr.starts_with("error: --") && stderr.contains(expected),
            "{args:?}: {stderr}"
        );
        assert!(
            !stderr.contains("Os {") && !stderr.contains("Error("),
            "{stderr}"
        );
    }
    assert_eq!(
        std::fs::read(&model).unwrap(),
        original,
        "the model is untouched"
    );
    // Nothing half-written is left behind, and no temporary either.
    let left: Vec<_> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    assert_eq!(left, vec![std::ffi::OsString::from("m.toml")], "{left:?}");
}

#[test]
fn a_failed_run_leaves_no_half_file_and_keeps_an_existing_one() {
    let dir = scratch("failed");
    let model = dir.join("spin.toml");
    // Spun at 1e200 rad/s: step 0's energy overflows.
    std::fs::write(
        &model,
        "[[frame]]\nname = \"j\"\nrx = \"q\"\n[[frame]]\nname = \"b\"\nparent = \"j\"\ntz = -1.0\nmass = 1.0\n[variables.q]\ndq0 = 1e200\n",
    )
    .unwrap();
    let csv = dir.join("t.csv");
    std::fs::write(&csv, "an earlier run\n").unwrap();
    for integrator in ["rk4", "vi"] {
        let (ok, _, stderr) = tree_mech(&[
            "simulate",
            model.to_str().unwrap(),
            "--integrator",
            integrator,
            "--out",
            csv.to_str().unwrap(),
        ]);
        assert!(!ok && stderr.contains("is not finite"), "{stderr}");
        assert_eq!(std::fs::read_to_string(&csv).unwrap(), "an earlier run\n");
    }
    assert_eq!(
        std::fs::read_dir(&dir).unwrap().count(),
        2,
        "no temporary left"
    );
    // eval and check: an error with a non-zero exit, never a JSON null.
    let (ok, stdout, stderr) = tree_mech(&["eval", model.to_str().unwrap()]);
    assert!(!ok && stdout.is_empty(), "{stdout}");
    assert!(
        stderr.contains("at this state, L is not finite"),
        "{stderr}"
    );
}

#[test]
fn csv_headers_quote_names_with_commas() {
    let dir = scratch("quote");
    let model = dir.join("q.toml");
    std::fs::write(
        &model,
        "[[frame]]\nname = \"j\"\nrx = \"x,y\"\n[[frame]]\nname = \"b\"\nparent = \"j\"\ntz = -1.0\nmass = 1.0\n[variables.\"x,y\"]\nq0 = 0.5\n",
    )
    .unwrap();
    let csv = dir.join("t.csv");
    let (ok, _, stderr) = tree_mech(&[
        "simulate",
        model.to_str().unwrap(),
        "--duration",
        "0.1",
        "--out",
        csv.to_str().unwrap(),
    ]);
    assert!(ok, "{stderr}");
    let text = std::fs::read_to_string(&csv).unwrap();
    let header = text.lines().next().unwrap();
    assert_eq!(header, "t,\"x,y\",\"dx,y\",energy");
    // Every row has as many fields as the header names (4), and reads back as numbers.
    for row in text.lines().skip(1) {
        let fields: Vec<f64> = row.split(',').map(|f| f.parse().unwrap()).collect();
        assert_eq!(fields.len(), 4, "{row}");
    }
}

#[test]
fn a_large_output_is_announced_before_the_run() {
    let dir = scratch("large");
    let csv = dir.join("t.csv");
    // 10⁸ steps of a 1-variable model: some 8 GB of CSV. The run is refused at once by a
    // bad option after the note, so nothing is written.
    let (ok, _, stderr) = tree_mech(&[
        "simulate",
        "models/pendulum.toml",
        "--dt",
        "1e-6",
        "--duration",
        "100",
        "--alpha",
        "2",
        "--out",
        csv.to_str().unwrap(),
    ]);
    assert!(!ok);
    assert!(
        stderr.contains("note: ") && stderr.contains("GB"),
        "{stderr}"
    );
    assert!(stderr.contains("VI alpha must lie in [0, 1]"), "{stderr}");
    assert!(!csv.exists());
}

#[test]
fn lock_holds_joints_as_constants_in_every_command() {
    let fingers = "panda_finger_joint1,panda_finger_joint2=0.02";
    let (ok, stdout, stderr) = tree_mech(&["check", "models/panda.urdf", "--lock", fingers]);
    assert!(ok, "{stderr}");
    assert!(stdout.contains("31 frames, 7 variables:"), "{stdout}");
    assert!(!stdout.contains("panda_finger_joint1 "), "{stdout}");
    assert!(stdout
        .contains("locked (held as constants): panda_finger_joint1, panda_finger_joint2=0.02"));
    // The finger frame holds the locked value.
    let (ok, stdout, stderr) = tree_mech(&["eval", "models/panda.urdf", "--lock", fingers]);
    assert!(ok, "{stderr}");
    let json: serde_json::Value = serde_json::from_str(&stdout).unwrap();
    assert_eq!(json["variables"].as_array().unwrap().len(), 7);
    let (ok, stdout, stderr) = tree_mech(&[
        "simulate",
        "models/panda.urdf",
        "--lock",
        fingers,
        "--duration",
        "0.5",
    ]);
    assert!(ok && stdout.contains("(7 variables)"), "{stdout}{stderr}");
    for (lock, expected) in [
        ("nope", "cannot lock `nope`: the model has no such variable"),
        ("theta=x", "--lock `theta=x`: `x` is not a finite number"),
        ("theta,theta", "`theta` is locked twice"),
        ("theta", "every variable is locked"),
    ] {
        let (ok, _, stderr) = tree_mech(&["check", "models/pendulum.toml", "--lock", lock]);
        assert!(!ok && stderr.contains(expected), "{lock}: {stderr}");
    }
}

/// How many pixels of the masses' colour (palette entry 6, wood) each GIF frame has.
fn wood_pixels(gif_bytes: &[u8]) -> Vec<usize> {
    let mut options = gif::DecodeOptions::new();
    options.set_color_output(gif::ColorOutput::Indexed);
    let mut decoder = options.read_info(std::io::Cursor::new(gif_bytes)).unwrap();
    let mut counts = Vec::new();
    while let Some(frame) = decoder.read_next_frame().unwrap() {
        counts.push(frame.buffer.iter().filter(|&&i| i == 6).count());
    }
    counts
}

#[test]
fn the_camera_holds_the_whole_run_or_tracks_the_root_at_a_fixed_scale() {
    // The humanoid's free torso falls 20 m in two seconds: a fixed camera frames the whole
    // fall (the figure small, never out of view), a tracking one keeps it large and the
    // same size.
    let dir = scratch("camera");
    let gif = dir.join("h.gif");
    let mut pixels = Vec::new();
    for camera in ["fixed", "track"] {
        let (ok, _, stderr) = tree_mech(&[
            "simulate",
            "models/humanoid.toml",
            "--duration",
            "2",
            "--animate",
            gif.to_str().unwrap(),
            "--camera",
            camera,
        ]);
        assert!(ok, "{stderr}");
        pixels.push(wood_pixels(&std::fs::read(&gif).unwrap()));
    }
    let (fixed, track) = (&pixels[0], &pixels[1]);
    assert_eq!(fixed.len(), 51);
    assert!(
        fixed.iter().all(|&n| n > 100),
        "the figure is in view throughout: {fixed:?}"
    );
    assert!(
        track[0] > 4 * fixed[0],
        "followed, it is drawn larger: {track:?} {fixed:?}"
    );
    let last = *track.last().unwrap() as f64;
    assert!(
        (last / track[0] as f64 - 1.0).abs() < 0.3,
        "the same size followed: {track:?}"
    );
}

#[test]
fn simulate_takes_inputs_constant_or_from_a_file_and_writes_them() {
    let dir = scratch("inputs");
    let csv = dir.join("t.csv");
    let (ok, _, stderr) = tree_mech(&[
        "simulate",
        "tests/models/cart.toml",
        "--duration",
        "0.5",
        "--u",
        "2",
        "--out",
        csv.to_str().unwrap(),
    ]);
    assert!(ok, "{stderr}");
    let text = std::fs::read_to_string(&csv).unwrap();
    assert_eq!(
        text.lines().next().unwrap(),
        "t,x,theta,dx,dtheta,energy,u_push"
    );
    assert!(text.lines().skip(1).all(|l| l.ends_with(",2.0")), "{text}");
    // From a file: −1 from 0.2 s on.
    let schedule = dir.join("u.csv");
    std::fs::write(&schedule, "t,push\n0,1\n0.2,-1\n").unwrap();
    let (ok, _, stderr) = tree_mech(&[
        "simulate",
        "tests/models/cart.toml",
        "--duration",
        "0.5",
        "--inputs",
        schedule.to_str().unwrap(),
        "--out",
        csv.to_str().unwrap(),
    ]);
    assert!(ok, "{stderr}");
    let text = std::fs::read_to_string(&csv).unwrap();
    let u: Vec<&str> = text
        .lines()
        .skip(1)
        .map(|l| l.rsplit(',').next().unwrap())
        .collect();
    assert_eq!(
        (u[0], u[19], u[20], u[50]),
        ("1.0", "1.0", "-1.0", "-1.0"),
        "{u:?}"
    );
    // check lists the input; eval takes --u.
    let (ok, stdout, _) = tree_mech(&["check", "tests/models/cart.toml"]);
    assert!(
        ok && stdout.contains("1 input (generalized forces u):")
            && stdout.contains("push                 on `x`; limits [-10, 10]"),
        "{stdout}"
    );
    let (ok, stdout, stderr) = tree_mech(&[
        "eval",
        "tests/models/cart.toml",
        "--q",
        "0,0",
        "--dq",
        "0,0",
        "--u",
        "1.2",
    ]);
    assert!(ok, "{stderr}");
    let json: serde_json::Value = serde_json::from_str(&stdout).unwrap();
    assert_eq!(json["inputs"][0], "push");
    // A push on the cart at rest, the pendulum hanging: the bob (on a massless rod) swings
    // back at first and takes none of it, so ẍ = F / m_cart, θ̈ = ẍ / ℓ (ry tilts it back).
    let (xdd, thdd) = (
        json["qdd"][0].as_f64().unwrap(),
        json["qdd"][1].as_f64().unwrap(),
    );
    assert!((xdd - 1.2).abs() < 1e-12, "ẍ = {xdd}");
    assert!((thdd - 1.2 / 0.5).abs() < 1e-12, "θ̈ = {thdd}");
    for (args, expected) in [
        (
            vec!["--u", "1,2"],
            "--u has 2 values; the model has 1 input (push)",
        ),
        (vec!["--u", "x"], "--u: `x` is not a finite number"),
        (vec!["--inputs", "missing.csv"], "cannot read `missing.csv`"),
        // A push too large for the model: the overflow names the input behind it.
        (
            vec!["--u", "1e308"],
            "step 0 (t = 0): discrete Euler–Lagrange residual, under the inputs push = 1e308, is not finite",
        ),
        (
            vec!["--u", "-1e308", "--integrator", "rk4"],
            "acceleration q̈, under the inputs push = -1e308, is not finite",
        ),
    ] {
        let mut all = vec!["simulate", "tests/models/cart.toml", "--duration", "0.1"];
        all.extend(args.iter().copied());
        let (ok, _, stderr) = tree_mech(&all);
        assert!(!ok && stderr.contains(expected), "{args:?}: {stderr}");
    }
    for command in ["eval", "linearize"] {
        let (ok, _, stderr) = tree_mech(&[command, "tests/models/cart.toml", "--u", "1e308"]);
        assert!(
            !ok && stderr.contains(
                "at this state, acceleration q̈, under the inputs push = 1e308, is not finite"
            ),
            "{command}: {stderr}"
        );
    }
    std::fs::write(&schedule, "t,pull\n0,1\n").unwrap();
    let (ok, _, stderr) = tree_mech(&[
        "simulate",
        "tests/models/cart.toml",
        "--inputs",
        schedule.to_str().unwrap(),
    ]);
    assert!(
        !ok && stderr.contains(":1: no column for input `push`"),
        "{stderr}"
    );
    let (ok, _, stderr) = tree_mech(&["simulate", "models/pendulum.toml", "--u", "1"]);
    assert!(
        !ok && stderr.contains("model `pendulum` has no inputs"),
        "{stderr}"
    );
    // Malformed rows name their line: a field too many, a time going back.
    for (text, expected) in [
        (
            "t,push\n0,1,2\n",
            "u.csv`:2: 3 fields where the header has 2",
        ),
        (
            "t,push\n0,1\n\n0.5,2\n0.3,1\n",
            "u.csv`:5: time 0.3 must be later than the row before (0.5)",
        ),
    ] {
        std::fs::write(&schedule, text).unwrap();
        let (ok, _, stderr) = tree_mech(&[
            "simulate",
            "tests/models/cart.toml",
            "--inputs",
            schedule.to_str().unwrap(),
        ]);
        assert!(!ok && stderr.contains(expected), "{stderr}");
    }
}

/// An optimal plan replays: `optimize --out` writes the controls as `u_<input>` beside the
/// joints' own columns (the UR5's inputs bear its joints' names), `simulate --inputs` reads
/// those and `--q0` starts where the task starts, and the run ends where the plan does.
#[test]
fn an_optimal_plan_replays_in_simulate() {
    let dir = scratch("replay");
    let task = dir.join("reach.toml");
    let text = shipped_task("ur5-reach");
    assert!(text
        .contains("q = { shoulder_lift_joint = -1.2, elbow_joint = 1.5, wrist_1_joint = -1.0 }"));
    std::fs::write(&task, text).unwrap();
    let (plan, json, replay) = (
        dir.join("plan.csv"),
        dir.join("plan.json"),
        dir.join("replay.csv"),
    );
    let (ok, _, stderr) = tree_mech(&[
        "optimize",
        task.to_str().unwrap(),
        "--quiet",
        "--out",
        plan.to_str().unwrap(),
        "--json",
        json.to_str().unwrap(),
    ]);
    assert!(ok, "{stderr}");
    let (ok, _, stderr) = tree_mech(&[
        "simulate",
        "models/ur5.urdf",
        "--inputs",
        plan.to_str().unwrap(),
        "--q0",
        "0,-1.2,1.5,-1.0,0,0",
        "--dq0",
        "0,0,0,0,0,0",
        "--dt",
        "0.01",
        "--duration",
        "1",
        "--out",
        replay.to_str().unwrap(),
    ]);
    assert!(ok, "{stderr}");
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    let text = std::fs::read_to_string(&replay).unwrap();
    let last: Vec<f64> = text
        .lines()
        .last()
        .unwrap()
        .split(',')
        .map(|x| x.parse().unwrap())
        .collect();
    for (i, q) in summary["q_final"].as_array().unwrap().iter().enumerate() {
        let q = q.as_f64().unwrap();
        assert!(
            (last[1 + i] - q).abs() < 1e-9,
            "joint {i}: {} against the plan's {q}",
            last[1 + i]
        );
    }
    // --q0 is checked as --q is.
    let (ok, _, stderr) = tree_mech(&["simulate", "models/ur5.urdf", "--q0", "1,2"]);
    assert!(
        !ok && stderr.contains("--q0 has 2 values; the model has 6 variables"),
        "{stderr}"
    );
}

/// A plan through contact replays at hard contact: the cart-pole's swing-up against its
/// rail's stops, optimised at κ down to 1e-6, run by `simulate --inputs` (κ = 0, hard), ends
/// where `optimize` says, and the summary reports the replay it made itself.
#[test]
fn a_plan_through_contact_replays_at_hard_contact() {
    let dir = scratch("rail");
    let (plan, json, replay) = (
        dir.join("plan.csv"),
        dir.join("plan.json"),
        dir.join("replay.csv"),
    );
    let (ok, stdout, stderr) = tree_mech(&[
        "optimize",
        "tasks/cartpole-rail.toml",
        "--quiet",
        "--out",
        plan.to_str().unwrap(),
        "--json",
        json.to_str().unwrap(),
    ]);
    assert!(ok, "{stderr}");
    assert!(
        stdout.contains("Solved")
            && stdout.contains("Through contact at κ = 1e-2 → 1e-3 → 1e-4 → 1e-5 → 1e-6 m·N·s"),
        "{stdout}"
    );
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    assert!(summary["hard_replay"]["deviation"].as_f64().unwrap() < 1e-2);
    assert!(summary["hard_replay"]["failure"].is_null());
    // Its policy, feedback included, keeps closer still (2.7e-4 against 2.4e-3 open loop).
    let policy = &summary["policy_replay"];
    assert!(policy["failure"].is_null(), "{policy}");
    assert!(policy["deviation"].as_f64().unwrap() < 1e-3, "{policy}");
    let (ok, _, stderr) = tree_mech(&[
        "simulate",
        "models/cartpole-rail.toml",
        "--inputs",
        plan.to_str().unwrap(),
        "--q0",
        "0,3.141592653589793",
        "--dt",
        "0.02",
        "--duration",
        "3",
        "--out",
        replay.to_str().unwrap(),
    ]);
    assert!(ok, "{stderr}");
    let (header, rows) = csv_table(&replay);
    let last = rows.last().unwrap();
    let column = |name: &str| header.iter().position(|h| h == name).unwrap();
    let x = last[column("x")];
    let gaps: Vec<usize> = (0..header.len())
        .filter(|&c| header[c].starts_with("gap_"))
        .collect();
    assert!(gaps.contains(&column("gap_x.upper")), "{header:?}");
    let min_gap = (rows.iter())
        .flat_map(|row| gaps.iter().map(|&c| row[c]))
        .fold(f64::INFINITY, f64::min);
    assert!(min_gap >= -1e-6, "a stop passed by {min_gap} m");
    for (i, q) in summary["q_final"].as_array().unwrap().iter().enumerate() {
        let q = q.as_f64().unwrap();
        assert!(
            (last[1 + i] - q).abs() < 1e-2,
            "variable {i}: {} against the plan's {q}",
            last[1 + i]
        );
    }
    assert!(x.abs() < 0.02, "the cart ends at {x}");
}

/// A numeric CSV written by the CLI: its header and its rows as numbers.
fn csv_table(path: &std::path::Path) -> (Vec<String>, Vec<Vec<f64>>) {
    let text = std::fs::read_to_string(path).unwrap();
    let mut lines = text.lines();
    let header = lines.next().unwrap().split(',').map(String::from).collect();
    let rows = lines
        .map(|row| row.split(',').map(|v| v.parse().unwrap()).collect())
        .collect();
    (header, rows)
}

/// The last CSV row of `simulate tests/models/cart.toml ARGS --out csv`, as numbers.
fn last_row(csv: &std::path::Path, args: &[&str]) -> Vec<f64> {
    let mut all = vec!["simulate", "tests/models/cart.toml"];
    all.extend(args);
    all.extend(["--out", csv.to_str().unwrap()]);
    let (ok, _, stderr) = tree_mech(&all);
    assert!(ok, "{stderr}");
    let text = std::fs::read_to_string(csv).unwrap();
    let row = text.lines().last().unwrap();
    row.split(',').map(|x| x.parse().unwrap()).collect()
}

#[test]
fn linearize_prints_the_exact_derivatives_and_one_vi_step_as_a_map() {
    let (ok, stdout, stderr) = tree_mech(&[
        "linearize",
        "tests/models/cart.toml",
        "--q",
        "0,0.1",
        "--dq",
        "0,0",
        "--u",
        "1",
        "--dt",
        "0.01",
    ]);
    assert!(ok, "{stderr}");
    let j: serde_json::Value = serde_json::from_str(&stdout).unwrap();
    let shape = |v: &serde_json::Value| {
        (
            v.as_array().unwrap().len(),
            v[0].as_array().map_or(0, |r| r.len()),
        )
    };
    assert_eq!(shape(&j["qdd_dq"]), (2, 2));
    assert_eq!(shape(&j["qdd_ddq"]), (2, 2));
    assert_eq!(shape(&j["qdd_du"]), (2, 1));
    for key in ["q2_dq1", "q2_dp1", "p2_dq1", "p2_dp1"] {
        assert_eq!(shape(&j["vi"][key]), (2, 2), "{key}");
    }
    assert_eq!(shape(&j["vi"]["q2_du1"]), (2, 1));
    // The step is simulate's first step from the same state and input.
    let dir = scratch("linearize");
    let csv = dir.join("t.csv");
    let last = last_row(&csv, &["--duration", "0.01", "--u", "1"]);
    for i in 0..2 {
        let q2 = j["vi"]["q2"][i].as_f64().unwrap();
        assert!(
            (q2 - last[1 + i]).abs() < 1e-12,
            "q2[{i}] {q2} vs simulate's {}",
            last[1 + i]
        );
    }
    // ∂q̈/∂u is M⁻¹'s column of the cart: M = [[M + m, m ℓ cos θ], [m ℓ cos θ, m ℓ²]] with
    // M = 1, m = 0.2, ℓ = 0.5, θ = 0.1, so (M⁻¹)ₓₓ = m ℓ² / det.
    let c = 0.1f64.cos();
    let expected = 0.05 / (1.2 * 0.05 - (0.1 * c) * (0.1 * c));
    let got = j["qdd_du"][0][0].as_f64().unwrap();
    assert!((got - expected).abs() < 1e-12, "{got} vs {expected}");
    let (ok, _, stderr) = tree_mech(&["linearize", "tests/models/cart.toml", "--dt", "-1"]);
    assert!(
        !ok && stderr.contains("--dt must be a positive number"),
        "{stderr}"
    );
    // --integrator rk4: the RK4 step on (q, q̇), 4 × 4 for the cart, and simulate's RK4 step.
    let (ok, stdout, stderr) = tree_mech(&[
        "linearize",
        "tests/models/cart.toml",
        "--q",
        "0,0.1",
        "--dq",
        "0,0",
        "--u",
        "1",
        "--dt",
        "0.01",
        "--integrator",
        "rk4",
    ]);
    assert!(ok, "{stderr}");
    let j: serde_json::Value = serde_json::from_str(&stdout).unwrap();
    assert_eq!(shape(&j["rk4"]["x2_dx1"]), (4, 4));
    assert_eq!(shape(&j["rk4"]["x2_du1"]), (4, 1));
    let last = last_row(
        &csv,
        &["--integrator", "rk4", "--duration", "0.01", "--u", "1"],
    );
    for i in 0..4 {
        let x2 = j["rk4"]["x2"][i].as_f64().unwrap();
        assert!(
            (x2 - last[1 + i]).abs() < 1e-12,
            "x2[{i}] {x2} vs simulate's {}",
            last[1 + i]
        );
    }
}

#[test]
fn linearize_second_order_prints_trep_s_thirty_second_derivatives() {
    // The string pendulum: a constraint (λ rows) and dynamic variables.
    let args = [
        "linearize",
        "tests/models/string-pendulum.toml",
        "--dt",
        "0.01",
        "--second-order",
    ];
    let (ok, stdout, stderr) = tree_mech(&args);
    assert!(ok, "{stderr}");
    let j: serde_json::Value = serde_json::from_str(&stdout).unwrap();
    let vi = j["vi"].as_object().unwrap();
    let n = j["variables"].as_array().unwrap().len();
    let nd = j["dynamic"].as_array().unwrap().len();
    let m = j["constraints"].as_array().unwrap().len();
    let blocks = ["q1", "p1", "u1", "k2"];
    let mut count = 0;
    for out in ["q2", "p2", "lambda1"] {
        for (k, a) in blocks.iter().enumerate() {
            for b in &blocks[k..] {
                let key = format!("{out}_d{a}d{b}");
                let t = vi.get(&key).unwrap_or_else(|| panic!("no {key}"));
                let rows = if out == "lambda1" { m } else { nd };
                assert_eq!(t.as_array().unwrap().len(), rows, "{key}");
                count += 1;
            }
        }
    }
    assert_eq!(count, 30);
    // ∂²q₂/∂q₁∂q₁ is n × n per row and symmetric, and not zero.
    let h = &vi["q2_dq1dq1"][0];
    assert_eq!(h.as_array().unwrap().len(), n);
    let mut largest = 0.0f64;
    for a in 0..n {
        for b in 0..n {
            let (x, y) = (h[a][b].as_f64().unwrap(), h[b][a].as_f64().unwrap());
            assert!((x - y).abs() <= 1e-9 * x.abs().max(1.0), "{x} vs {y}");
            largest = largest.max(x.abs());
        }
    }
    assert!(largest > 0.0);
    // rk45's Dormand–Prince step on (q, q̇).
    let (ok, stdout, stderr) = tree_mech(&[
        "linearize",
        "tests/models/cart.toml",
        "--dt",
        "0.01",
        "--integrator",
        "rk45",
    ]);
    assert!(ok, "{stderr}");
    let j: serde_json::Value = serde_json::from_str(&stdout).unwrap();
    assert_eq!(j["rk45"]["x2_dx1"].as_array().unwrap().len(), 4);
    assert_eq!(j["rk45"]["x2_du1"][0].as_array().unwrap().len(), 1);
    let (ok, _, stderr) = tree_mech(&["linearize", "tests/models/cart.toml", "--second-order"]);
    assert!(
        !ok && stderr.contains("--second-order is for the VI step"),
        "{stderr}"
    );
}

#[test]
fn optimize_solves_a_task_and_writes_every_output() {
    let dir = scratch("optimize");
    let (csv, png, gif, json, gains) = (
        dir.join("s.csv"),
        dir.join("s.png"),
        dir.join("s.gif"),
        dir.join("s.json"),
        dir.join("g.json"),
    );
    let (ok, stdout, stderr) = tree_mech(&[
        "optimize",
        "tasks/cartpole-swingup.toml",
        "--out",
        csv.to_str().unwrap(),
        "--plot",
        png.to_str().unwrap(),
        "--animate",
        gif.to_str().unwrap(),
        "--json",
        json.to_str().unwrap(),
        "--gains",
        gains.to_str().unwrap(),
    ]);
    assert!(ok, "{stderr}");
    assert!(
        stdout.contains("iter") && stdout.contains("Solved"),
        "{stdout}"
    );
    let text = std::fs::read_to_string(&csv).unwrap();
    let mut lines = text.lines();
    assert_eq!(lines.next().unwrap(), "t,x,theta,dx,dtheta,energy,u_push");
    assert_eq!(lines.count(), 126);
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    assert_eq!(summary["converged"], true);
    assert_eq!(summary["stopped"], "converged");
    let theta = summary["q_final"][1].as_f64().unwrap();
    assert!(theta.abs() < 0.02, "the pole ends at {theta}");
    for key in ["iterations", "cost", "dq_final", "frames", "solve_seconds"] {
        assert!(!summary[key].is_null(), "no `{key}` in {summary}");
    }
    let g: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&gains).unwrap()).unwrap();
    assert_eq!(g["K"].as_array().unwrap().len(), 125);
    assert_eq!(&std::fs::read(&png).unwrap()[1..4], b"PNG");
    assert_eq!(&std::fs::read(&gif).unwrap()[..3], b"GIF");
    // A frame term names its frame's final position; a bad task is one line with its line.
    let (ok, _, stderr) = tree_mech(&[
        "optimize",
        "tasks/cartpole-swingup.toml",
        "--plot",
        dir.join("x.gif").to_str().unwrap(),
    ]);
    assert!(!ok && stderr.contains("must end in .png"), "{stderr}");
    let bad = dir.join("bad.toml");
    std::fs::write(
        &bad,
        format!(
            "model = \"{}/models/cartpole.toml\"\ndt = 0.02\nknots = 10\n[[cost]]\nkind = \"frame\"\nframe = \"hat\"\ntarget = [0.0, 0.0, 0.0]\nweight = 1.0\n",
            env!("CARGO_MANIFEST_DIR")
        ),
    )
    .unwrap();
    let (ok, _, stderr) = tree_mech(&["optimize", bad.to_str().unwrap()]);
    assert!(
        !ok && stderr.contains("bad.toml:6: frame `hat` is not in the model"),
        "{stderr}"
    );
    let (ok, _, stderr) = tree_mech(&[
        "optimize",
        "tasks/cartpole-swingup.toml",
        "--out",
        "tasks/cartpole-swingup.toml",
    ]);
    assert!(!ok && stderr.contains("same file"), "{stderr}");
    // Refused while setting up the solve: the error alone, no iteration table begun.
    let tight = dir.join("tight.toml");
    let reach = shipped_task("ur5-reach");
    std::fs::write(
        &tight,
        format!("{reach}\n[limits]\nshoulder_lift_joint = [-1.0, 1.0]\n"),
    )
    .unwrap();
    let (ok, stdout, stderr) = tree_mech(&["optimize", tight.to_str().unwrap()]);
    assert!(
        !ok && stderr.contains("exclude") && stdout.is_empty(),
        "{stdout}{stderr}"
    );
    // A step so long that the initial guess's cost overflows: an error naming the knot and
    // the task's `dt` (not an exit 0 with `cost inf`, a null in the JSON and NaN energies).
    let swingup = shipped_task("cartpole-swingup").replace("dt = 0.02", "dt = 1e300");
    let huge = dir.join("huge.toml");
    std::fs::write(&huge, swingup).unwrap();
    let (json, csv) = (dir.join("huge.json"), dir.join("huge.csv"));
    let (ok, stdout, stderr) = tree_mech(&[
        "optimize",
        huge.to_str().unwrap(),
        "--json",
        json.to_str().unwrap(),
        "--out",
        csv.to_str().unwrap(),
    ]);
    assert!(!ok, "{stdout}");
    assert!(
        stderr
            .contains("step 1 (t = 1e300): the cost of the initial guess rolled out is not finite")
            && stderr.contains("lower the task's `dt`")
            && !stderr.contains("--dt"),
        "{stderr}"
    );
    assert!(
        !json.exists() && !csv.exists(),
        "no outputs from a failed solve"
    );
}

/// A model whose start is off its constraints (tests/models/elements.toml: `wall` by 0.35) is
/// linearised from that start projected onto them, as `simulate` starts it; a step from a
/// configuration the user gives off the constraints fails with a sentence naming the
/// constraint and the gap, not Newton's failure alone.
#[test]
fn linearize_steps_from_the_start_on_the_constraints() {
    let (ok, stdout, stderr) =
        tree_mech(&["linearize", "tests/models/elements.toml", "--dt", "0.01"]);
    assert!(ok, "{stderr}");
    assert!(stdout.contains("\"vi\""), "{stdout}");
    let (ok, _, stderr) = tree_mech(&[
        "linearize",
        "tests/models/elements.toml",
        "--dt",
        "0.01",
        "--q",
        "0.2,0,0.3,0,0.33,1.2,0.9",
    ]);
    assert!(!ok);
    assert!(
        stderr.contains("off constraint `wall` by") && stderr.contains("on the constraints"),
        "{stderr}"
    );
}

#[test]
fn a_solve_that_stops_says_why() {
    let dir = scratch("stops");
    let run = |name: &str, text: &str, iterations: &str| {
        let task = dir.join(format!("{name}.toml"));
        let json = dir.join(format!("{name}.json"));
        std::fs::write(&task, text).unwrap();
        let (ok, stdout, stderr) = tree_mech(&[
            "optimize",
            task.to_str().unwrap(),
            "--max-iterations",
            iterations,
            "--json",
            json.to_str().unwrap(),
        ]);
        assert!(ok, "{stderr}");
        let summary: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
        (stdout, summary)
    };
    // Out of iterations: raising the limit is the way on.
    let reach = shipped_task("ur5-reach").replace("knots = 100", "knots = 20");
    let (stdout, summary) = run("short", &reach, "2");
    assert!(
        stdout.contains("Did not converge") && stdout.contains("raise --max-iterations"),
        "{stdout}"
    );
    assert_eq!(summary["stopped"], "iteration limit");
    // Every weight scaled by 1e40 (a cost in other units): the regularisation is relative,
    // so the same iterations end at the same place. Without a control cost `Q_uu` is only
    // semi-definite and the regularisation does the work: an absolute μ, negligible against a
    // curvature of 1e40, stopped at once.
    let free = reach.replacen("weight = 1e-3", "weight = 0.0", 1);
    assert_ne!(free, reach);
    let (_, plain) = run("plain", &free, "50");
    let heavy = ["weight = 1e5", "dq_weight = 0.01", "dq_weight = 10.0"]
        .iter()
        .fold(free.clone(), |t, w| {
            assert!(t.contains(w), "the shipped task has no `{w}`");
            let (key, value) = w.split_once(" = ").unwrap();
            let scaled = value.parse::<f64>().unwrap() * 1e40;
            t.replace(w, &format!("{key} = {scaled:e}"))
        });
    let (stdout, summary) = run("heavy", &heavy, "50");
    assert!(stdout.contains("Solved"), "{stdout}");
    assert_eq!(summary["stopped"], "converged");
    assert_eq!(summary["iterations"], plain["iterations"]);
    let ends = |s: &serde_json::Value| s["frames"]["ee_link"].clone();
    for i in 0..3 {
        let (a, b) = (
            ends(&summary)[i].as_f64().unwrap(),
            ends(&plain)[i].as_f64().unwrap(),
        );
        assert!((a - b).abs() < 1e-9, "ee_link[{i}]: {a} against {b}");
    }
}

/// `--ground`, `--friction` and `--contact` add contact to a model from the command line:
/// `check` lists it, `simulate` lands the ball on it, rk4 stops where it lands (it cannot hold
/// the contact), a bad radius is a sentence.
#[test]
fn contact_is_added_from_the_command_line() {
    let (ok, stdout, stderr) = tree_mech(&[
        "check",
        "tests/models/string-pendulum.toml",
        "--ground=-2",
        "--friction",
        "0.5",
        "--contact",
        "bob:0.1",
    ]);
    assert!(ok, "{stderr}");
    assert!(
        stdout.contains("ground: n·x ≥ -2") && stdout.contains("friction 0.5"),
        "{stdout}"
    );
    assert!(
        stdout.contains("bob                  sphere of radius 0.1 on `bob`"),
        "{stdout}"
    );
    // A URDF robot's collision spheres, asked for: the Go1's feet.
    let (ok, stdout, stderr) = tree_mech(&[
        "check",
        "tests/robots/example-robot-data/go1_description/urdf/go1.urdf",
        "--floating-base",
        "--contacts",
        "--ground",
    ]);
    assert!(ok, "{stderr}");
    assert!(
        stdout.contains("RL_foot              sphere of radius 0.02 on `RL_foot`, the ground only"),
        "{stdout}"
    );
    let dir = scratch("cli-contact");
    let csv = dir.join("ball.csv");
    let (ok, stdout, stderr) = tree_mech(&[
        "simulate",
        "tests/models/ball.toml",
        "--dt",
        "0.001",
        "--duration",
        "1",
        "--out",
        csv.to_str().unwrap(),
    ]);
    assert!(ok, "{stderr}");
    assert!(stdout.contains("Simulated `ball`"), "{stdout}");
    // Dropped 1 m onto the ground and resting: the impact took out m g h = 9.81 J, and the
    // summary says how deep any row went and what the contact steps cost.
    assert!(
        stdout.contains("impacts and friction took out 9.81000")
            && stdout.contains("deepest penetration"),
        "{stdout}"
    );
    let text = std::fs::read_to_string(&csv).unwrap();
    let last = text.lines().last().unwrap();
    let z: f64 = last.split(',').nth(3).unwrap().parse().unwrap();
    assert!((z - 0.1).abs() < 1e-9, "rests at {z}");
    // RK4 in flight writes the rows' gaps and no impulse.
    let flight = dir.join("flight.csv");
    let (ok, _, stderr) = tree_mech(&[
        "simulate",
        "tests/models/ball.toml",
        "--integrator",
        "rk4",
        "--duration",
        "0.3",
        "--out",
        flight.to_str().unwrap(),
    ]);
    assert!(ok, "{stderr}");
    let (header, rows) = csv_table(&flight);
    let last = rows.last().unwrap();
    let at = |name: &str| last[header.iter().position(|h| h == name).unwrap()];
    assert!((at("gap_ball") - (at("z") - 0.1)).abs() < 1e-12 && at("impulse_ball") == 0.0);
    let (ok, _, stderr) = tree_mech(&["simulate", "tests/models/ball.toml", "--integrator", "rk4"]);
    assert!(
        !ok && stderr.contains("`ball` closed")
            && stderr.contains("only the variational integrator"),
        "{stderr}"
    );
    let (ok, _, stderr) = tree_mech(&["check", "tests/models/ball.toml", "--contact", "by:wide"]);
    assert!(
        !ok && stderr.contains("--contact: contact `by:wide`: the radius after `:` must be a number (metres), got `wide`"),
        "{stderr}"
    );
    let (ok, _, stderr) = tree_mech(&["check", "tests/models/ball.toml", "--contact", "nowhere"]);
    assert!(
        !ok && stderr.contains("unknown frame `nowhere`"),
        "{stderr}"
    );
}

/// `linearize --dt --kappa` differentiates one VI step through contact; without a step (the
/// continuous equations know no contact) it is refused.
#[test]
fn linearize_goes_through_contact_with_a_step_only() {
    let (ok, stdout, stderr) = tree_mech(&[
        "linearize",
        "tests/models/box.toml",
        "--dt",
        "0.001",
        "--kappa",
        "1e-6",
    ]);
    assert!(ok, "{stderr}");
    let json: serde_json::Value = serde_json::from_str(&stdout).unwrap();
    // Resting on its four lower corners, the box's height cannot follow its start: ∂z₂/∂z₁
    // is far below the free body's 1.
    let z = json["vi"]["q2_dq1"][2][2].as_f64().unwrap();
    assert!(z.abs() < 0.5, "∂z₂/∂z₁ = {z}");
    let (ok, _, stderr) = tree_mech(&["linearize", "tests/models/box.toml"]);
    assert!(
        !ok && stderr.contains("linearise one VI step (--dt"),
        "{stderr}"
    );
    let (ok, _, stderr) = tree_mech(&[
        "linearize",
        "tests/models/box.toml",
        "--dt",
        "0.001",
        "--kappa",
        "-1",
    ]);
    assert!(
        !ok && stderr.contains("κ must be finite and not negative"),
        "{stderr}"
    );
}

/// `--forces` draws a run's contact forces on its animation, and says what is missing
/// when there is no animation or nothing to draw.
#[test]
fn simulate_draws_contact_forces_as_arrows_when_asked() {
    let dir = scratch("forces");
    let gif = dir.join("ball.gif");
    let g = gif.to_str().unwrap();
    let ball = ["simulate", "tests/models/ball.toml", "--duration", "0.6"];
    let (ok, stdout, stderr) = tree_mech(&[&ball[..], &["--animate", g, "--forces"]].concat());
    assert!(ok, "{stderr}");
    assert!(stdout.contains("Animation: "), "{stdout}");
    // The last picture: the ball resting, its ground's push as an orange arrow.
    let bytes = std::fs::read(&gif).unwrap();
    let mut decoder = gif::DecodeOptions::new();
    decoder.set_color_output(gif::ColorOutput::RGBA);
    let mut decoder = decoder.read_info(std::io::Cursor::new(&bytes)).unwrap();
    let mut last = Vec::new();
    while let Some(frame) = decoder.read_next_frame().unwrap() {
        last = frame.buffer.to_vec();
    }
    let orange = last
        .chunks_exact(4)
        .filter(|p| p[..3] == [255, 102, 0])
        .count();
    assert!(orange > 30, "{orange} px of arrow");
    let (ok, _, stderr) = tree_mech(&[&ball[..], &["--forces"]].concat());
    assert!(!ok && stderr.contains("give --animate"), "{stderr}");
    let pendulum = ["simulate", "models/pendulum.toml", "--duration", "0.1"];
    let (ok, _, stderr) = tree_mech(&[&pendulum[..], &["--animate", g, "--forces"]].concat());
    assert!(!ok && stderr.contains("has no contacts"), "{stderr}");
}
