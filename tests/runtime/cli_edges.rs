//! The command line at its edges (issue 43): outputs that are links, devices or FIFOs, a
//! standard output that takes nothing, and Ctrl-C in the middle of a run or a solve.

use std::io::{BufRead, BufReader, Read};
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use super::cli::{scratch, shipped_task, tree_mech};

fn spawn(args: &[&str]) -> Child {
    Command::new(env!("CARGO_BIN_EXE_tree-mech"))
        .args(args)
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap()
}

/// Sends SIGINT to `child`, as Ctrl-C in its terminal would.
fn interrupt(child: &Child) {
    let status = Command::new("kill")
        .args(["-INT", &child.id().to_string()])
        .status()
        .unwrap();
    assert!(status.success());
}

/// Waits (at most a minute) until `what` holds.
fn wait_until(what: &str, mut done: impl FnMut() -> bool) {
    let start = Instant::now();
    while !done() {
        assert!(start.elapsed() < Duration::from_secs(60), "never: {what}");
        std::thread::sleep(Duration::from_millis(20));
    }
}

fn partials(dir: &Path) -> Vec<String> {
    std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.contains(".partial-"))
        .collect()
}

#[test]
fn an_output_through_a_symbolic_link_writes_its_target_and_keeps_the_link() {
    let dir = scratch("link");
    let (target, link) = (dir.join("target.csv"), dir.join("link.csv"));
    std::fs::write(&target, "old").unwrap();
    std::os::unix::fs::symlink("target.csv", &link).unwrap();
    let (ok, _, stderr) = tree_mech(&[
        "simulate",
        "models/pendulum.toml",
        "--duration",
        "0.5",
        "--out",
        link.to_str().unwrap(),
    ]);
    assert!(ok, "{stderr}");
    assert!(std::fs::symlink_metadata(&link)
        .unwrap()
        .file_type()
        .is_symlink());
    let text = std::fs::read_to_string(&target).unwrap();
    assert!(text.starts_with("t,theta,dtheta"), "{text}");
    // A link to a file not there yet makes that file.
    std::os::unix::fs::symlink("new.csv", dir.join("dangling.csv")).unwrap();
    let dangling = dir.join("dangling.csv");
    let (ok, _, stderr) = tree_mech(&[
        "simulate",
        "models/pendulum.toml",
        "--duration",
        "0.5",
        "--out",
        dangling.to_str().unwrap(),
    ]);
    assert!(ok, "{stderr}");
    assert!(dir.join("new.csv").is_file());
    assert!(partials(&dir).is_empty());
}

#[test]
fn a_device_is_written_through_and_never_replaced() {
    use std::os::unix::fs::FileTypeExt;
    let (ok, stdout, stderr) = tree_mech(&[
        "simulate",
        "models/pendulum.toml",
        "--duration",
        "0.5",
        "--out",
        "/dev/null",
    ]);
    assert!(ok, "{stderr}");
    assert!(stdout.contains("Trajectory: /dev/null."), "{stdout}");
    let kind = std::fs::metadata("/dev/null").unwrap().file_type();
    assert!(kind.is_char_device());
    // A full device: the write's error, as a sentence, and a failing exit.
    let (ok, _, stderr) = tree_mech(&[
        "simulate",
        "models/pendulum.toml",
        "--duration",
        "0.5",
        "--out",
        "/dev/full",
    ]);
    assert!(
        !ok && stderr.contains("cannot write the trajectory"),
        "{stderr}"
    );
    assert!(std::fs::metadata("/dev/full")
        .unwrap()
        .file_type()
        .is_char_device());
}

#[test]
fn a_fifo_is_written_through_to_its_reader() {
    use std::os::unix::fs::FileTypeExt;
    let dir = scratch("fifo");
    let fifo = dir.join("pipe.csv");
    assert!(Command::new("mkfifo")
        .arg(&fifo)
        .status()
        .unwrap()
        .success());
    let reader = {
        let fifo = fifo.clone();
        std::thread::spawn(move || std::fs::read_to_string(fifo).unwrap())
    };
    let (ok, _, stderr) = tree_mech(&[
        "simulate",
        "models/pendulum.toml",
        "--duration",
        "0.5",
        "--out",
        fifo.to_str().unwrap(),
    ]);
    assert!(ok, "{stderr}");
    let text = reader.join().unwrap();
    assert_eq!(text.lines().count(), 52, "a header and 51 samples");
    assert!(std::fs::metadata(&fifo).unwrap().file_type().is_fifo());
}

#[test]
fn a_standard_output_that_takes_nothing_is_an_error_not_a_panic() {
    for args in [
        &["check", "models/pendulum.toml"][..],
        &["simulate", "models/pendulum.toml", "--duration", "0.1"],
        &["eval", "models/pendulum.toml"],
    ] {
        let out = Command::new(env!("CARGO_BIN_EXE_tree-mech"))
            .args(args)
            .current_dir(env!("CARGO_MANIFEST_DIR"))
            .stdout(std::fs::File::create("/dev/full").unwrap())
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(1), "{args:?}: {stderr}");
        assert!(
            stderr.contains("cannot write to standard output") && !stderr.contains("panicked"),
            "{args:?}: {stderr}"
        );
    }
}

#[test]
fn ctrl_c_stops_a_run_and_leaves_no_half_file() {
    let dir = scratch("sigint-run");
    let out = dir.join("run.csv");
    let mut child = spawn(&[
        "simulate",
        "models/marionette.toml",
        "--duration",
        "100000",
        "--out",
        out.to_str().unwrap(),
    ]);
    wait_until("the partial file grows", || {
        std::fs::read_dir(&dir).unwrap().any(|e| {
            let e = e.unwrap();
            e.file_name().to_string_lossy().contains(".partial-")
                && e.metadata().unwrap().len() > 1_000_000
        })
    });
    interrupt(&child);
    let status = child.wait().unwrap();
    let mut stderr = String::new();
    child
        .stderr
        .take()
        .unwrap()
        .read_to_string(&mut stderr)
        .unwrap();
    assert_eq!(status.code(), Some(130), "{stderr}");
    assert!(stderr.contains("interrupted"), "{stderr}");
    assert!(
        partials(&dir).is_empty() && !out.exists(),
        "{:?}",
        partials(&dir)
    );
}

#[test]
fn ctrl_c_stops_a_solve_and_writes_its_best_plan() {
    let dir = scratch("sigint-solve");
    // The marionette's wave over ten times the knots: long enough to interrupt.
    let task = dir.join("long.toml");
    let text = shipped_task("marionette-wave").replace("knots = 150", "knots = 3000");
    std::fs::write(&task, text).unwrap();
    let plan = dir.join("plan.csv");
    let mut child = spawn(&[
        "optimize",
        task.to_str().unwrap(),
        "--out",
        plan.to_str().unwrap(),
        "--max-iterations",
        "400",
    ]);
    let mut stdout = BufReader::new(child.stdout.take().unwrap());
    let mut seen = String::new();
    // The first iteration's line, then Ctrl-C.
    while !seen.lines().any(|l| l.trim_start().starts_with("1 ")) {
        assert!(stdout.read_line(&mut seen).unwrap() > 0, "{seen}");
    }
    interrupt(&child);
    stdout.read_to_string(&mut seen).unwrap();
    let status = child.wait().unwrap();
    assert_eq!(status.code(), Some(130), "{seen}");
    assert!(
        seen.contains("The solve was interrupted; the best trajectory found is written."),
        "{seen}"
    );
    let written = std::fs::read_to_string(&plan).unwrap();
    assert_eq!(written.lines().count(), 3002, "a header and 3001 knots");
    assert!(partials(&dir).is_empty());
}

#[test]
fn a_newton_tolerance_too_loose_to_solve_the_step_is_refused() {
    // At 1e-3 Newton accepted its predictor and the pendulum gained 40 J over 100 s.
    let (ok, _, stderr) = tree_mech(&["simulate", "models/pendulum.toml", "--newton-tol", "1e-3"]);
    assert!(!ok, "accepted");
    assert!(
        stderr.contains("Newton tolerance 1e-3 is looser than 1e-6"),
        "{stderr}"
    );
    // The loosest accepted keeps the energy the exact solve keeps.
    let energy_at = |tol: &str| {
        let (ok, stdout, stderr) = tree_mech(&[
            "simulate",
            "models/pendulum.toml",
            "--duration",
            "100",
            "--newton-tol",
            tol,
        ]);
        assert!(ok, "{stderr}");
        let end = stdout.split(" to ").nth(1).unwrap();
        end.split(' ').next().unwrap().parse::<f64>().unwrap()
    };
    let (loose, tight) = (energy_at("1e-6"), energy_at("1e-12"));
    assert!(
        (loose - tight).abs() < 1e-6 * tight.abs(),
        "{loose} vs {tight}"
    );
}

/// A model of one pendulum whose variable is `var` and, with `input`, an input on it.
fn pendulum_named(dir: &Path, var: &str, input: Option<&str>) -> String {
    let mut text = format!(
        "[[frame]]\nname = \"arm\"\nrx = \"{var}\"\n\n[[frame]]\nname = \"bob\"\nparent = \"arm\"\ntz = -1.0\nmass = 1.0\n"
    );
    if let Some(u) = input {
        text += &format!("\n[[input]]\nname = \"{u}\"\nvariable = \"{var}\"\n");
    }
    let path = dir.join(format!("{var}.toml"));
    std::fs::write(&path, text).unwrap();
    path.to_str().unwrap().to_string()
}

#[test]
fn trajectory_columns_that_would_share_a_name_are_refused_before_the_run() {
    let dir = scratch("columns");
    let out = dir.join("run.csv");
    let out = out.to_str().unwrap();
    // A variable `t`: its column would be the time's.
    let model = pendulum_named(&dir, "t", None);
    let (ok, _, stderr) = tree_mech(&["simulate", &model, "--out", out]);
    assert!(!ok);
    assert!(
        stderr.contains("the time and variable `t` would both be named `t`"),
        "{stderr}"
    );
    // Variables `theta` and `dtheta`: `dtheta` twice.
    let two = dir.join("two.toml");
    std::fs::write(
        &two,
        "[[frame]]\nname = \"a\"\nrx = \"theta\"\n\n[[frame]]\nname = \"b\"\nparent = \"a\"\nrx = \"dtheta\"\n\n[[frame]]\nname = \"bob\"\nparent = \"b\"\ntz = -1.0\nmass = 1.0\n",
    )
    .unwrap();
    let (ok, _, stderr) = tree_mech(&["simulate", two.to_str().unwrap(), "--out", out]);
    assert!(!ok);
    assert!(
        stderr
            .contains("variable `dtheta` and the velocity of `theta` would both be named `dtheta`"),
        "{stderr}"
    );
    assert!(!Path::new(out).exists() && partials(&dir).is_empty());
}

#[test]
fn an_input_file_is_read_for_what_it_says_or_refused() {
    let dir = scratch("input-file");
    let model = pendulum_named(&dir, "theta", Some("t"));
    let schedule = |name: &str, text: &str| {
        let path = dir.join(name);
        std::fs::write(&path, text).unwrap();
        path.to_str().unwrap().to_string()
    };
    let run = |file: &str| tree_mech(&["simulate", &model, "--duration", "0.5", "--inputs", file]);
    // An input named `t`: the time column is not the input.
    let (ok, _, stderr) = run(&schedule("a.csv", "t\n0,1\n"));
    assert!(
        !ok && stderr.contains("no column `u_t` for input `t`"),
        "{stderr}"
    );
    // A column twice.
    let (ok, _, stderr) = run(&schedule("b.csv", "t,t\n0,1\n"));
    assert!(
        !ok && stderr.contains("column `t` appears twice (columns 1 and 2)"),
        "{stderr}"
    );
    // A schedule that starts after the run.
    let (ok, _, stderr) = run(&schedule("c.csv", "t,u_t\n0.2,1\n0.4,2\n"));
    assert!(!ok && stderr.contains("after the run's start"), "{stderr}");
    // A byte-order mark before the header, as spreadsheets write: read.
    let (ok, _, stderr) = run(&schedule("d.csv", "\u{feff}t,u_t\n0,1\n"));
    assert!(ok, "{stderr}");
    // A file that never ends is read no further than a bound.
    let (ok, _, stderr) = run("/dev/zero");
    assert!(!ok && stderr.contains("is larger than 256 MB"), "{stderr}");
}

/// A robot of `n` links, each on a revolute joint to one base.
fn star_urdf(dir: &Path, n: usize) -> String {
    let mut text = String::from("<robot name=\"star\">\n<link name=\"base\"/>\n");
    for i in 0..n {
        text += &format!(
            "<link name=\"l{i}\"><inertial><mass value=\"1\"/><inertia ixx=\"0.01\" ixy=\"0\" ixz=\"0\" iyy=\"0.01\" iyz=\"0\" izz=\"0.01\"/></inertial></link>\n<joint name=\"j{i}\" type=\"revolute\"><parent link=\"base\"/><child link=\"l{i}\"/><axis xyz=\"0 0 1\"/><limit lower=\"-1\" upper=\"1\" effort=\"1\" velocity=\"1\"/></joint>\n"
        );
    }
    text += "</robot>\n";
    let path = dir.join("star.urdf");
    std::fs::write(&path, text).unwrap();
    path.to_str().unwrap().to_string()
}

#[test]
fn what_would_not_fit_in_memory_is_refused_in_a_sentence_before_it_is_asked_for() {
    let dir = scratch("memory");
    // 40 000 joints and no elements: checked without the elements' n × n scratch (12.8 GB).
    let star = star_urdf(&dir, 40_000);
    let (ok, stdout, stderr) = tree_mech(&["check", &star]);
    assert!(ok, "{stderr}");
    assert!(stdout.contains("40000 variables"), "{stdout}");
    // Its dense matrices (about 200 GB) are refused, not an abort.
    let (ok, _, stderr) = tree_mech(&["eval", &star]);
    assert!(!ok);
    assert!(
        stderr.contains("40000 variables would need about") && stderr.contains("GB of memory"),
        "{stderr}"
    );
    // A million knots of the marionette: about 100 GB.
    let task = dir.join("long.toml");
    let text = shipped_task("marionette-wave").replace("knots = 150", "knots = 1000000");
    std::fs::write(&task, text).unwrap();
    let (ok, _, stderr) = tree_mech(&["optimize", task.to_str().unwrap()]);
    assert!(!ok);
    assert!(
        stderr.contains("the task's 1000000 knots would need about"),
        "{stderr}"
    );
    // An iteration bound is not an allocation.
    let (ok, _, stderr) = tree_mech(&[
        "optimize",
        "tasks/ur5-reach.toml",
        "--max-iterations",
        "4294967296",
    ]);
    assert!(ok, "{stderr}");
}

#[test]
fn options_that_would_be_ignored_are_refused_and_messages_say_the_cause() {
    let refused = |args: &[&str], expected: &str| {
        let (ok, _, stderr) = tree_mech(args);
        assert!(!ok && stderr.contains(expected), "{args:?}: {stderr}");
    };
    refused(
        &["linearize", "tests/models/cart.toml", "--p", "0.1"],
        "--p is the VI step's momentum at its start: give --dt",
    );
    refused(
        &[
            "linearize",
            "tests/models/cart.toml",
            "--p",
            "0.1",
            "--dt",
            "0.01",
            "--integrator",
            "rk4",
        ],
        "--p is the VI step's momentum",
    );
    refused(
        &["simulate", "models/pendulum.toml", "--baumgarte", "1,1"],
        "Baumgarte stabilisation is for the explicit integrators",
    );
    // A run shorter than its step, and a step of 0: refused by the options' check, with no
    // note of a CSV growing to "inf GB" before it.
    refused(
        &[
            "simulate",
            "models/pendulum.toml",
            "--duration",
            "1",
            "--dt",
            "2",
        ],
        "shorter than one step",
    );
    let dir = scratch("ignored-options");
    let out = dir.join("o.csv");
    let (ok, _, stderr) = tree_mech(&[
        "simulate",
        "models/pendulum.toml",
        "--dt",
        "0",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(
        !ok && stderr.contains("time step must be a positive"),
        "{stderr}"
    );
    assert!(!stderr.contains("GB"), "{stderr}");
    // Numbers as given, never as hundreds of digits.
    let (ok, _, stderr) = tree_mech(&[
        "simulate",
        "models/pendulum.toml",
        "--rtol",
        "-1e300",
        "--integrator",
        "rk45",
    ]);
    assert!(!ok && stderr.contains("got -1e300"), "{stderr}");
}

#[test]
fn a_urdf_saved_as_xml_is_read_as_urdf() {
    let dir = scratch("urdf-as-xml");
    let xml = dir.join("solo12.xml");
    std::fs::copy(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("models/solo12.urdf"),
        &xml,
    )
    .unwrap();
    let (ok, stdout, stderr) = tree_mech(&["check", xml.to_str().unwrap(), "--floating-base"]);
    assert!(ok, "{stderr}");
    assert!(stdout.contains("18 variables"), "{stdout}");
}
