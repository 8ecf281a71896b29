//! The `tree-mech` command line: outputs, and one-line errors with a non-zero exit.

use std::process::Command;

fn tree_mech(args: &[&str]) -> (bool, String, String) {
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
    let dir = std::env::temp_dir().join(format!("tree-mech-cli-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
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

#[test]
fn check_draws_the_tree() {
    let (ok, stdout, _) = tree_mech(&["check", "models/humanoid.toml"]);
    assert!(ok);
    assert!(stdout.contains("22 variables"), "{stdout}");
    assert!(stdout.contains("└─ torso = rx(roll)"), "{stdout}");
}

#[test]
fn bad_input_is_a_short_error_and_a_failing_exit() {
    let bad = std::env::temp_dir().join(format!("tree-mech-bad-{}.toml", std::process::id()));
    std::fs::write(&bad, "name = \"bad\"\n[[frame]]\nname = \"a\"\nbogus = 2\n").unwrap();
    let bad_shown = format!("{}:4: TOML error: unknown field `bogus`", bad.display());
    let cases: [(&[&str], &str); 6] = [
        (&["check", "models/missing.toml"], "cannot read model file"),
        (&["simulate"], "required"),
        (
            &["eval", "models/pendulum.toml", "--q", "1,2"],
            "--q has 2 values; the model has 1 variables (theta)",
        ),
        (
            &["eval", "models/pendulum.toml", "--dq", "x"],
            "--dq: `x` is not a finite number",
        ),
        (
            &["simulate", "models/pendulum.toml", "--dt", "-1"],
            "time step must be positive",
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
