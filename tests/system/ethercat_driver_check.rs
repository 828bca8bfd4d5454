//! `microrobot driver-check` holds the EtherCAT CiA 402 driver to the driver contract,
//! free-running and in lockstep, against the emulated six-drive seed arm over a veth
//! pair in the test thread's own network namespace (`ethercat_rig`).
//!
//! Every clause passes, `torque applied` with the drives' torque resolution from the
//! drive file (`--torque-resolution-nm`: 1 ‰ of each axis's rated torque, joint side):
//! the driver reports the target torque it sent for the command the state names, after
//! its clamp and quantisation, so each state's `tau_applied` is within half a step of
//! that command.

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

/// The drive file's torque step per joint (N·m, joint side): one per mille of each
/// axis's rated torque, in the seed arm's joint order.
fn torque_resolution(rig: &Rig) -> String {
    let file = microrobot_ethercat_cia402::drive_file::DriveFile::load(&rig.drive_file())
        .expect("the rig's drive file");
    let robot = microrobot_model::Robot::from_file(
        &std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("config/robots/seed-arm.toml"),
    )
    .expect("seed arm");
    let steps: Vec<String> = robot
        .joints()
        .iter()
        .map(|j| {
            let axis = file
                .axes
                .iter()
                .find(|a| a.joint == j.name)
                .unwrap_or_else(|| panic!("no axis drives joint {}", j.name));
            let step = axis.scaling.effort_from_torque_actual(1);
            assert!(step > 0.0 && step.is_finite(), "{step}");
            format!("{step}")
        })
        .collect();
    steps.join(",")
}

/// Runs driver-check on the driver against the rig with the drive file's torque
/// resolution; asserts a full PASS with the `expected` clauses among the passed.
fn check(test: &str, opts: RigOptions, lockstep: bool, expected: &[&str]) {
    let t0 = std::time::Instant::now();
    let Some(rig) = Rig::start(opts) else {
        return;
    };
    let config = rig.pipeline_config(&instance(test), false, "", "");
    let resolution = torque_resolution(&rig);
    let drive_file = rig.drive_file();
    let driver = rig.driver.display().to_string();
    let config = config.display().to_string();
    let drive_file = drive_file.display().to_string();
    let mut args = vec![
        "driver-check",
        "--config",
        &config,
        "--torque-resolution-nm",
        &resolution,
    ];
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
    assert_eq!(out.code(), Some(0), "{report}");
    let seen = clauses(&report);
    let failed: Vec<&str> = seen
        .iter()
        .filter(|(_, pass)| !*pass)
        .map(|(n, _)| n.as_str())
        .collect();
    assert!(failed.is_empty(), "{report}");
    // The clause names the tolerance it used: half the drive file's steps.
    let line = report
        .lines()
        .find(|l| l.trim_start().starts_with("torque applied"))
        .unwrap_or_default();
    assert!(
        line.contains("0 states whose tau_applied differs")
            && line.contains("half the torque resolution"),
        "{line}"
    );
    for name in expected.iter().chain(&["torque applied"]) {
        assert!(
            seen.iter().any(|(n, pass)| n == name && *pass),
            "clause `{name}` missing or failed:\n{report}"
        );
    }
}

#[test]
fn ethercat_driver_passes_driver_check_free_running() {
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
fn ethercat_driver_passes_driver_check_in_lockstep() {
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
