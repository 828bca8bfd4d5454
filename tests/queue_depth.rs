//! The bus queues are deep enough in time that a host stall of a service loses nothing:
//! at 4 kHz, a 20 ms SIGSTOP of the dynamics (80 setpoints queue up, then a burst of 80
//! torques) and then of all three services at once, mid-move, lose no setpoint, torque
//! or state, and the setpoint stream stays jerk-limited across both.

mod common;

use std::time::Duration;

use common::*;
use microrobot_bus_tools::invariants::setpoint_jumps;
use microrobot_messages::ServiceRole;

const RATE_HZ: f64 = 4000.0;
const STALL_MS: u64 = 20;

fn stop_all(pids: &[i32], sig: libc::c_int) {
    for &pid in pids {
        // SAFETY: kill(2) on a child of the pipeline this test started.
        unsafe { libc::kill(pid, sig) };
    }
}

fn freeze(pids: &[i32], ms: u64) {
    stop_all(pids, libc::SIGSTOP);
    std::thread::sleep(Duration::from_millis(ms));
    stop_all(pids, libc::SIGCONT);
}

#[test]
fn a_20_ms_stall_at_4_khz_loses_nothing_and_moves_nothing_abruptly() {
    let dir = tempfile::tempdir().expect("tempdir");
    let inst = instance("queue-depth");
    // The supervisor's hung detection stays out of a 20 ms stall anyway; the watchdogs
    // keep their defaults (stale_ms 50 > the stall).
    let cfg = write_config(
        dir.path(),
        &inst,
        &format!("rate_hz = {RATE_HZ}"),
        "[supervisor]\nhung_ms = 60000.0",
    );
    let summary_path = dir.path().join("summary.json");
    let rec = Recorder::start_spinning(&inst);
    let proc = start_holding(&inst, &cfg, 60, Some(&summary_path));
    let pid = |r| pid_of(&inst, r).expect("service pid");
    let (planner, dynamics, actuator) = (
        pid(ServiceRole::Planner),
        pid(ServiceRole::Dynamics),
        pid(ServiceRole::Actuator),
    );

    let mv = send(
        &inst,
        &cfg,
        &["move", "--deg", "--joints", "30,30,60,30,30,30"],
    );
    assert_eq!(mv.code(), Some(0), "move: {}", mv.stderr);
    std::thread::sleep(Duration::from_millis(600));
    freeze(&[dynamics], STALL_MS);
    std::thread::sleep(Duration::from_millis(600));
    freeze(&[planner, dynamics, actuator], STALL_MS);
    std::thread::sleep(Duration::from_millis(1500));

    proc.signal(libc::SIGINT);
    let out = proc.finish(60.0);
    assert_eq!(out.code(), Some(0), "run; stderr:\n{}", out.stderr);
    let summary = summary(&summary_path);
    assert_eq!(
        summary["lost_messages"].as_u64(),
        Some(0),
        "the services lost messages: {}",
        out.stdout
    );
    let streams = rec.finish();
    assert!(
        streams.setpoints.len() > 8000,
        "recorded {} setpoints",
        streams.setpoints.len()
    );
    assert_no_gaps("setpoint", streams.setpoints.iter().map(|s| s.header.seq));
    assert_no_gaps("torque", streams.torques.iter().map(|t| t.header.seq));
    let report = setpoint_jumps(
        &streams.setpoints,
        &streams.states,
        &seed_arm_limits(),
        1.0 / RATE_HZ,
    );
    assert!(report.jumps.is_empty(), "{:#?}", report.jumps);
}
