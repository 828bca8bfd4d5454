//! Crash and restart: with `supervisor.on_failure = "restart"` a `kill -9`ed service is
//! started again and the run ends cleanly; with `stop_all` the run stops with
//! SERVICE_FAILED.

use std::collections::BTreeSet;
use std::time::{Duration, Instant};

use crate::common::*;
use microrobot_messages::ServiceRole;

fn dynamics_pid(statuses: &[microrobot_messages::ServiceStatus]) -> Option<i32> {
    statuses
        .iter()
        .rev()
        .find(|s| s.role == ServiceRole::Dynamics as u32 && s.ready == 1)
        .map(|s| s.pid as i32)
}

fn kill_dynamics_mid_run(test: &str, policy: &str) -> (Finished, serde_json::Value, BTreeSet<u32>) {
    let dir = tempfile::tempdir().expect("tempdir");
    let inst = instance(test);
    let cfg = write_config(
        dir.path(),
        &inst,
        "",
        &format!("[supervisor]\non_failure = \"{policy}\"\nmax_restarts = 2"),
    );
    let summary_path = dir.path().join("summary.json");
    let rec = Recorder::start_statuses(&inst);
    let proc = start(&[
        "run",
        "--config",
        cfg.to_str().expect("utf-8"),
        "--no-program",
        "--duration",
        "6",
        "--summary-json",
        summary_path.to_str().expect("utf-8"),
    ]);
    wait_ready(&inst, 60.0);
    // The recorder has seen the dynamics' statuses by now (10 Hz).
    let t0 = Instant::now();
    let victim = loop {
        std::thread::sleep(Duration::from_millis(200));
        if let Some(pid) = find_dynamics(&inst) {
            break pid;
        }
        assert!(t0.elapsed() < Duration::from_secs(30), "no dynamics status");
    };
    // SAFETY: kill(2) on a process of this test.
    unsafe { libc::kill(victim, libc::SIGKILL) };
    let out = proc.finish(120.0);
    let statuses = rec.finish().statuses;
    let pids = statuses
        .iter()
        .filter(|s| s.role == ServiceRole::Dynamics as u32)
        .map(|s| s.pid)
        .collect();
    assert!(!alive(victim));
    (out, summary(&summary_path), pids)
}

/// The pid of the dynamics service of `instance`, from a short look at the status stream.
fn find_dynamics(instance: &str) -> Option<i32> {
    let rec = Recorder::start_statuses(instance);
    std::thread::sleep(Duration::from_millis(300));
    dynamics_pid(&rec.finish().statuses)
}

#[test]
fn a_killed_service_is_restarted_under_the_restart_policy() {
    let (out, s, pids) = kill_dynamics_mid_run("restart", "restart");
    // The pipeline ran on, but a service died: the run's verdict says so.
    assert_eq!(
        out.code(),
        Some(3),
        "SERVICE_FAILED; stderr:\n{}",
        out.stderr
    );
    assert_eq!(s["exit_ok"], false, "{s}");
    assert!(
        s["failures"].to_string().contains("dynamics service died"),
        "{s}"
    );
    assert_eq!(s["services"]["dynamics"]["restarts"], 1, "{s}");
    assert_eq!(s["services"]["dynamics"]["exit"], "exit code 0", "{s}");
    assert_eq!(
        pids.len(),
        2,
        "a second dynamics process reported: {pids:?}"
    );
    assert!(out.stderr.contains("restarting"), "{}", out.stderr);
}

#[test]
fn a_killed_service_stops_the_pipeline_under_stop_all() {
    let (out, s, _) = kill_dynamics_mid_run("stopall", "stop_all");
    assert_eq!(
        out.code(),
        Some(3),
        "SERVICE_FAILED; stderr:\n{}",
        out.stderr
    );
    assert_eq!(s["exit_ok"], false, "{s}");
    assert_eq!(s["stop_reason"], "service_failed", "{s}");
    assert!(
        out.stderr.contains("dynamics service died"),
        "{}",
        out.stderr
    );
}
