//! `microrobot driver-check` holds the EtherCAT CiA 402 driver to the driver contract,
//! free-running and in lockstep, against the emulated six-drive seed arm over a veth
//! pair in the test thread's own network namespace (`ethercat_rig`).
//!
//! Every clause passes but one: `torque applied` wants each state's `tau_applied`
//! equal (to 1e-6) to the torque command it names. This driver reports what the drive
//! measures, torque actual 0x6077: in steps of 1 ‰ of the rated torque (0.127 N·m on
//! joints 1-3, 0.032 N·m on 4-6) and sampled by the drive at the exchange before the
//! command it names reached it. No real drive reporting its measured torque meets that
//! clause; the test holds the driver to every other clause and to failing that one for
//! exactly that reason, so a change on either side shows here.

use crate::common::*;
use crate::ethercat_rig::{MASTER_IF, Rig, RigOptions};

/// The clause lines of driver-check's report: (name, passed).
fn clauses(stdout: &str) -> Vec<(String, bool)> {
    stdout
        .lines()
        .filter_map(|l| {
            let (name, rest) = l.trim_start().split_once("  ")?;
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

/// The clause the driver fails, and why (see the module).
const MEASURED_TORQUE: &str = "torque applied";

/// Runs driver-check on the driver against the rig; asserts that the `expected` clauses
/// pass and the only failure is [`MEASURED_TORQUE`], for the reason in the module.
fn check(test: &str, opts: RigOptions, lockstep: bool, expected: &[&str]) {
    let t0 = std::time::Instant::now();
    let Some(rig) = Rig::start(opts) else {
        return;
    };
    let config = rig.pipeline_config(&instance(test), false, "", "");
    let drive_file = rig.drive_file();
    let driver = rig.driver.display().to_string();
    let config = config.display().to_string();
    let drive_file = drive_file.display().to_string();
    let mut args = vec!["driver-check", "--config", &config];
    if lockstep {
        args.push("--lockstep");
    }
    args.extend([
        "--",
        &driver,
        "--instance",
        "{instance}",
        "--rate-hz",
        "{rate_hz}",
        "--drive-file",
        &drive_file,
        "--interface",
        MASTER_IF,
    ]);
    let out = run(&args, 180.0);
    eprintln!(
        "{test}: driver-check exit {:?} in {:.1} s\n{}{}",
        out.code(),
        t0.elapsed().as_secs_f64(),
        out.stdout,
        out.stderr
    );
    let report = format!("{}{}", out.stdout, out.stderr);
    assert_eq!(
        out.code(),
        Some(microrobot_runtime::exit_code::JOB_FAILED as i32),
        "{report}"
    );
    assert!(
        report.contains(&format!("driver-check: FAILED: {MEASURED_TORQUE}\n"))
            || report
                .trim_end()
                .ends_with(&format!("driver-check: FAILED: {MEASURED_TORQUE}")),
        "{report}"
    );
    let seen = clauses(&report);
    let failed: Vec<&str> = seen
        .iter()
        .filter(|(_, pass)| !*pass)
        .map(|(n, _)| n.as_str())
        .collect();
    assert_eq!(failed, vec![MEASURED_TORQUE], "{report}");
    // Every state differs (the torque is measured, not echoed); the arm held still.
    let line = report
        .lines()
        .find(|l| l.trim_start().starts_with(MEASURED_TORQUE))
        .unwrap_or_default();
    assert!(
        line.contains("states whose tau_applied differs") && line.contains("within"),
        "{line}"
    );
    for name in expected {
        assert!(
            seen.iter().any(|(n, pass)| n == name && *pass),
            "clause `{name}` missing or failed:\n{report}"
        );
    }
}

#[test]
fn ethercat_driver_passes_driver_check_free_running_but_for_the_measured_torque() {
    check(
        "ecat-drvcheck-free",
        RigOptions::free_running(4000),
        false,
        &[
            "ready status",
            "initial state",
            "state rate",
            "state sequence",
            "tick and stamp copied",
            "lifecycle active",
            "status",
            "stale torques",
            "safe state",
            "reset",
            "SIGTERM",
            "kill -9 and restart",
        ],
    );
}

#[test]
fn ethercat_driver_passes_driver_check_in_lockstep_but_for_the_measured_torque() {
    check(
        "ecat-drvcheck-lockstep",
        RigOptions::lockstep(),
        true,
        &[
            "ready status",
            "initial state",
            "one state per torque",
            "lifecycle active",
            "safe state",
            "reset",
            "SIGTERM",
        ],
    );
}
