//! `microrobot driver-check` holds a driver to the contract clause by clause: the
//! simulated arm (through the actuator framework every Rust driver uses) passes every
//! clause free-running and in lockstep; a driver that never reports ready, or one that
//! is no driver at all, fails on the first clause, naming it.

use crate::common::*;

fn clauses(stdout: &str) -> Vec<(String, bool)> {
    stdout
        .lines()
        .filter_map(|l| {
            let l = l.trim_start();
            let (name, rest) = l.split_once("  ")?;
            let verdict = rest.trim_start();
            if verdict.starts_with("pass") {
                Some((name.trim().to_string(), true))
            } else if verdict.starts_with("FAIL") {
                Some((name.trim().to_string(), false))
            } else {
                None
            }
        })
        .collect()
}

fn sim_arm(config: &std::path::Path, lockstep: bool) -> Finished {
    let config = config.display().to_string();
    let mut args = vec!["driver-check", "--config", &config];
    if lockstep {
        args.push("--lockstep");
    }
    args.extend(["--", actuator_bin(), "--config", "{config}"]);
    run(&args, 120.0)
}

#[test]
fn the_simulated_arm_passes_every_clause_free_running_and_in_lockstep() {
    let dir = tempfile::tempdir().expect("tempdir");
    let cfg = write_config(dir.path(), &instance("drvcheck-sim"), "", "");

    let free = sim_arm(&cfg, false);
    assert_eq!(free.code(), Some(0), "{}{}", free.stdout, free.stderr);
    let seen = clauses(&free.stdout);
    for name in [
        "ready status",
        "initial state",
        "state rate",
        "state sequence",
        "tick and stamp copied",
        "lifecycle active",
        "torque applied",
        "status",
        "stale torques",
        "safe state",
        "reset",
        "SIGTERM",
        "kill -9 and restart",
    ] {
        assert!(
            seen.iter().any(|(n, pass)| n == name && *pass),
            "clause `{name}` missing or failed:\n{}",
            free.stdout
        );
    }
    assert!(
        free.stdout.contains("driver-check: PASS"),
        "{}",
        free.stdout
    );

    let lock = sim_arm(&cfg, true);
    assert_eq!(lock.code(), Some(0), "{}{}", lock.stdout, lock.stderr);
    let seen = clauses(&lock.stdout);
    assert!(
        seen.iter()
            .any(|(n, pass)| n == "one state per torque" && *pass),
        "{}",
        lock.stdout
    );
    // Lockstep has no stale window: torques stop only with the planner.
    assert!(
        !seen.iter().any(|(n, _)| n == "stale torques"),
        "{}",
        lock.stdout
    );
    assert!(seen.iter().all(|(_, pass)| *pass), "{}", lock.stdout);
}

#[test]
fn a_driver_that_never_reports_ready_or_exits_fails_the_first_clause() {
    let dir = tempfile::tempdir().expect("tempdir");
    let cfg = write_config(
        dir.path(),
        &instance("drvcheck-bad"),
        "",
        "[supervisor]\nready_timeout_ms = 1500.0",
    );
    let cfg = cfg.display().to_string();

    // A process that runs but never speaks the contract.
    let silent = run(
        &["driver-check", "--config", &cfg, "--", "sleep", "30"],
        120.0,
    );
    assert_eq!(
        silent.code(),
        Some(microrobot_runtime::exit_code::JOB_FAILED as i32),
        "{}{}",
        silent.stdout,
        silent.stderr
    );
    assert_eq!(
        clauses(&silent.stdout),
        vec![("ready status".to_string(), false)],
        "{}",
        silent.stdout
    );
    assert!(
        silent.stdout.contains("no ready status within 1.5 s"),
        "{}",
        silent.stdout
    );
    assert!(
        silent.stdout.contains("driver-check: FAILED: ready status"),
        "{}",
        silent.stdout
    );

    // A driver that exits at once: said so, with its exit code.
    let gone = run(&["driver-check", "--config", &cfg, "--", "false"], 120.0);
    assert_eq!(
        gone.code(),
        Some(microrobot_runtime::exit_code::JOB_FAILED as i32),
        "{}{}",
        gone.stdout,
        gone.stderr
    );
    assert!(
        gone.stdout
            .contains("the driver exited before it was ready (exit code 1)"),
        "{}",
        gone.stdout
    );

    // No command at all is a usage error, not a pass.
    let none = run(&["driver-check", "--config", &cfg], 60.0);
    assert_eq!(none.code(), Some(2), "{}{}", none.stdout, none.stderr);
}
