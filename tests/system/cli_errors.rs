//! Bad input at the command line is refused with a clear message and a distinct exit
//! code, before anything starts.

use crate::common::*;
use microrobot_runtime::exit_code;

#[test]
fn bad_config_value_is_refused_with_bad_config_exit_and_names_the_key() {
    let dir = tempfile::tempdir().expect("tempdir");
    let inst = instance("badcfg");
    let cfg = write_config(dir.path(), &inst, "rate_hz = -5.0", "");
    let out = run(&["run", "--config", cfg.to_str().expect("utf-8")], 30.0);
    assert_eq!(
        out.code(),
        Some(exit_code::BAD_CONFIG as i32),
        "exit code BAD_CONFIG; stderr:\n{}",
        out.stderr
    );
    assert!(
        out.stderr.contains("rate_hz"),
        "names the key:\n{}",
        out.stderr
    );
    assert!(
        out.stderr.contains(&format!("{inst}.toml")),
        "names the file:\n{}",
        out.stderr
    );
}

#[test]
fn unknown_config_key_is_refused_with_bad_config_exit() {
    let dir = tempfile::tempdir().expect("tempdir");
    let inst = instance("unknownkey");
    let cfg = write_config(dir.path(), &inst, "", "[watchdog]\nstale_msec = 10.0");
    let out = run(&["run", "--config", cfg.to_str().expect("utf-8")], 30.0);
    assert_eq!(
        out.code(),
        Some(exit_code::BAD_CONFIG as i32),
        "stderr:\n{}",
        out.stderr
    );
    assert!(out.stderr.contains("watchdog.stale_msec"), "{}", out.stderr);
}

#[test]
fn bad_command_line_override_is_refused_like_a_config_key() {
    let dir = tempfile::tempdir().expect("tempdir");
    let inst = instance("badoverride");
    let cfg = write_config(dir.path(), &inst, "", "");
    let out = run(
        &[
            "run",
            "--config",
            cfg.to_str().expect("utf-8"),
            "--rate-hz",
            "NaN",
        ],
        30.0,
    );
    assert_eq!(
        out.code(),
        Some(exit_code::BAD_CONFIG as i32),
        "stderr:\n{}",
        out.stderr
    );
    assert!(
        out.stderr.contains("--rate-hz: NaN"),
        "names the flag as typed: {}",
        out.stderr
    );
}

#[test]
fn send_refuses_a_non_finite_target_locally() {
    let out = run(
        &[
            "send",
            "--instance",
            &instance("nopipe"),
            "move",
            "--joints",
            "0.1,NaN,0,0,0,0",
        ],
        30.0,
    );
    assert_ne!(out.code(), Some(0));
    assert!(out.stderr.contains("--joints"), "{}", out.stderr);
}

#[test]
fn send_refuses_a_target_outside_the_joint_limits_locally() {
    let out = run(
        &[
            "send",
            "--instance",
            &instance("limits"),
            "move",
            "--deg",
            "--joints",
            "0,0,0,0,0,400",
        ],
        30.0,
    );
    assert_ne!(out.code(), Some(0));
    assert!(
        out.stderr
            .contains("j6 target 400° is outside its range [-180°, 180°]"),
        "in the units typed: {}",
        out.stderr
    );
}

#[test]
fn send_to_an_instance_that_is_not_running_says_so() {
    let inst = instance("absent");
    let out = run(
        &["send", "--instance", &inst, "--timeout", "2", "stop"],
        30.0,
    );
    assert_ne!(out.code(), Some(0));
    assert!(out.stderr.contains("is running"), "{}", out.stderr);
}
