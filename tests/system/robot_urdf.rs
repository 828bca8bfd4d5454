//! `microrobot robot urdf`: a robot file written as URDF and its overlay; the overlay
//! loads as the same robot (`eval model` answers the same on both, to 1e-9 relative);
//! bad input is a clear error with the documented exit code.

use crate::common::*;
use microrobot_runtime::exit_code;
use std::io::Write as _;
use std::process::{Command, Stdio};

/// `eval model --robot robot` on one line of input; the output object.
fn eval(robot: &std::path::Path, line: &str) -> serde_json::Value {
    let mut child = Command::new(bin())
        .args(["eval", "model", "--robot", robot.to_str().expect("utf-8")])
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .spawn()
        .expect("spawn eval");
    child
        .stdin
        .take()
        .expect("stdin")
        .write_all(format!("{line}\n").as_bytes())
        .expect("write");
    let out = child.wait_with_output().expect("eval output");
    assert!(out.status.success(), "eval failed");
    serde_json::from_slice(&out.stdout).expect("one JSON object")
}

/// Every number of `a` and `b`, in the same order, within 1e-9 relative (1e-12 absolute).
fn same_numbers(a: &serde_json::Value, b: &serde_json::Value, path: &str) {
    match (a, b) {
        (serde_json::Value::Number(x), serde_json::Value::Number(y)) => {
            let (x, y) = (x.as_f64().expect("f64"), y.as_f64().expect("f64"));
            assert!(
                (x - y).abs() <= 1e-12 + 1e-9 * x.abs().max(y.abs()),
                "{path}: {x} vs {y}"
            );
        }
        (serde_json::Value::Array(x), serde_json::Value::Array(y)) => {
            assert_eq!(x.len(), y.len(), "{path}");
            for (i, (p, q)) in x.iter().zip(y).enumerate() {
                same_numbers(p, q, &format!("{path}[{i}]"));
            }
        }
        (serde_json::Value::Object(x), serde_json::Value::Object(y)) => {
            assert_eq!(
                x.keys().collect::<Vec<_>>(),
                y.keys().collect::<Vec<_>>(),
                "{path}"
            );
            for (k, p) in x {
                same_numbers(p, &y[k], &format!("{path}.{k}"));
            }
        }
        (x, y) => assert_eq!(x, y, "{path}"),
    }
}

#[test]
fn the_seed_arm_as_urdf_and_overlay_answers_as_the_seed_arm() {
    let dir = tempfile::tempdir().expect("tempdir");
    let urdf = dir.path().join("seed.urdf");
    let done = run(
        &[
            "robot",
            "urdf",
            seed_arm().to_str().expect("utf-8"),
            "-o",
            urdf.to_str().expect("utf-8"),
        ],
        30.0,
    );
    assert_eq!(done.code(), Some(0), "{}", done.stderr);
    let overlay = dir.path().join("seed.overlay.toml");
    assert!(done.stdout.contains("seed.overlay.toml"), "{}", done.stdout);
    let text = std::fs::read_to_string(&urdf).expect("urdf written");
    assert!(text.starts_with("<?xml") && text.contains("<robot name=\"seed-arm\">"));
    for line in [
        r#"{"q":[0.1,0.2,0.3,0.4,0.5,0.6],"qd":[0.3,-0.2,0.1,0.5,-0.4,0.2],"qdd":[1,2,-1,0.5,0,-2]}"#,
        r#"{"q":[-2,0.9,1.5,-3,-1.2,2.5],"qd":[0,0,0,0,0,0],"qdd":[0,0,0,0,0,0]}"#,
    ] {
        same_numbers(&eval(&seed_arm(), line), &eval(&overlay, line), "eval");
    }
}

#[test]
fn without_out_the_urdf_goes_to_stdout_and_bad_input_is_named() {
    let done = run(
        &["robot", "urdf", seed_arm().to_str().expect("utf-8")],
        30.0,
    );
    assert_eq!(done.code(), Some(0), "{}", done.stderr);
    assert!(
        done.stdout
            .contains("<joint name=\"j6\" type=\"revolute\">")
    );
    let missing = run(&["robot", "urdf", "/nonexistent/arm.toml"], 30.0);
    assert_eq!(missing.code(), Some(i32::from(exit_code::BAD_CONFIG)));
    assert!(
        missing.stderr.contains("/nonexistent/arm.toml"),
        "{}",
        missing.stderr
    );
    let unwritable = run(
        &[
            "robot",
            "urdf",
            seed_arm().to_str().expect("utf-8"),
            "-o",
            "/nonexistent-dir/arm.urdf",
        ],
        30.0,
    );
    assert_eq!(unwritable.code(), Some(i32::from(exit_code::FAILURE)));
    assert!(
        unwritable
            .stderr
            .contains("cannot write /nonexistent-dir/arm.urdf"),
        "{}",
        unwritable.stderr
    );
}
