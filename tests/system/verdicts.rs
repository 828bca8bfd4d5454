//! A run's verdict is a promise: `run` exits 0 with `exit_ok: true` only when the job
//! asked for ran to its end. A program refused before start, abandoned mid-run or never
//! run, and a safe state latched and left so, each end FAILED with the reason on stderr,
//! a non-zero exit and `exit_ok: false`.

use std::path::Path;
use std::time::Duration;

use crate::common::*;
use microrobot_messages::ServiceRole;
use microrobot_runtime::exit_code;

fn s(p: &Path) -> String {
    p.to_str().expect("utf-8 path").to_string()
}

/// A one-segment program to `q_deg` (soft motion), written into `dir`.
fn program(dir: &Path, name: &str, q_deg: [f64; 6]) -> std::path::PathBuf {
    let q: Vec<String> = q_deg.iter().map(|v| format!("{v:.1}")).collect();
    let path = dir.join(format!("{name}.toml"));
    std::fs::write(
        &path,
        format!(
            "[program]\nname = \"{name}\"\ndof = 6\n[[segment]]\nname = \"{name}\"\nq_deg = [{}]\nprofile = \"soft\"\n",
            q.join(", ")
        ),
    )
    .expect("write program");
    path
}

#[test]
fn a_program_target_outside_a_joint_range_is_refused_before_anything_starts() {
    let dir = tempfile::tempdir().expect("tempdir");
    let inst = instance("verdict-range");
    let cfg = write_config(dir.path(), &inst, "", "");
    // j5's range is [-90°, 90°].
    let prog = program(dir.path(), "too-far", [0.0, 0.0, 20.0, 0.0, 120.0, 0.0]);
    let sum = dir.path().join("summary.json");
    let out = run(
        &[
            "run",
            "--config",
            &s(&cfg),
            "--program",
            &s(&prog),
            "--summary-json",
            &s(&sum),
        ],
        60.0,
    );
    assert_eq!(
        out.code(),
        Some(exit_code::BAD_CONFIG as i32),
        "stderr:\n{}",
        out.stderr
    );
    for needle in ["j5", "120", "outside its range", "too-far"] {
        assert!(
            out.stderr.contains(needle),
            "`{needle}` in stderr:\n{}",
            out.stderr
        );
    }
    assert!(
        !out.stderr.contains("ready"),
        "no service was started:\n{}",
        out.stderr
    );
    assert!(!sum.exists(), "no summary of a run that never started");
    assert_eq!(remaining_nodes(&inst), Vec::<String>::new());

    // `check` finds the same error, with the same exit code.
    let check = run(
        &["check", "--config", &s(&cfg), "--program", &s(&prog), "-q"],
        60.0,
    );
    assert_eq!(check.code(), Some(exit_code::BAD_CONFIG as i32));
    assert!(check.stdout.contains("j5 target 120"), "{}", check.stdout);
    assert!(check.stdout.contains("check: FAILED"), "{}", check.stdout);
    // And passes the shipped program.
    let ok = run(
        &[
            "check",
            "--config",
            &s(&cfg),
            "-q",
            "--program",
            &s(&table4_program()),
        ],
        60.0,
    );
    assert_eq!(ok.code(), Some(0), "{}{}", ok.stdout, ok.stderr);
    assert!(ok.stdout.contains("check: ok"), "{}", ok.stdout);
}

/// Starts the Table 4 program (8.5 s) with the config `tables`, freezes `victim` with
/// SIGSTOP for `freeze` 1 s into the motion, resumes it, and waits for the run's end.
fn freeze_mid_program(
    tag: &str,
    victim: ServiceRole,
    freeze: Duration,
    tables: &str,
) -> (Finished, serde_json::Value) {
    let dir = tempfile::tempdir().expect("tempdir");
    let inst = instance(tag);
    let cfg = write_config(
        dir.path(),
        &inst,
        &format!("program = \"{}\"", table4_program().display()),
        tables,
    );
    let sum = dir.path().join("summary.json");
    let proc = start(&["run", "--config", &s(&cfg), "--summary-json", &s(&sum)]);
    wait_ready(&inst, 60.0);
    std::thread::sleep(Duration::from_millis(1000));
    let pid = pid_of(&inst, victim).expect("victim pid");
    // SAFETY: kill(2) on a child of the pipeline this test started.
    unsafe { libc::kill(pid, libc::SIGSTOP) };
    std::thread::sleep(freeze);
    // SAFETY: as above.
    unsafe { libc::kill(pid, libc::SIGCONT) };
    let out = proc.finish(120.0);
    (out, summary(&sum))
}

/// The frozen service is not taken for hung (to see what the rest of the pipeline does).
const NO_HUNG_KILL: &str = "[supervisor]\nhung_ms = 60000.0";

#[test]
fn a_hung_service_is_found_killed_and_named_in_the_verdict() {
    // Frozen for good: the supervisor must find it hung and stop the pipeline
    // (`on_failure = "stop_all"`), or restart it (`"restart"`).
    for (tag, policy, restarted) in [
        ("verdict-hung-stop", "stop_all", false),
        ("verdict-hung-restart", "restart", true),
    ] {
        let dir = tempfile::tempdir().expect("tempdir");
        let inst = instance(tag);
        let cfg = write_config(
            dir.path(),
            &inst,
            "",
            &format!("[supervisor]\non_failure = \"{policy}\"\nhung_ms = 400.0"),
        );
        let sum = dir.path().join("summary.json");
        let proc = start(&[
            "run",
            "--config",
            &s(&cfg),
            "--no-program",
            "--duration",
            "6",
            "--summary-json",
            &s(&sum),
        ]);
        wait_ready(&inst, 60.0);
        let pid = pid_of(&inst, ServiceRole::Dynamics).expect("dynamics pid");
        // SAFETY: kill(2) on a child of the pipeline this test started.
        unsafe { libc::kill(pid, libc::SIGSTOP) };
        let out = proc.finish(120.0);
        assert!(!alive(pid), "{policy}: the hung process was killed");
        assert_eq!(
            out.code(),
            Some(exit_code::SERVICE_FAILED as i32),
            "{policy}: stderr:\n{}",
            out.stderr
        );
        assert!(
            out.stderr.contains("the dynamics service hung"),
            "{policy}: stderr:\n{}",
            out.stderr
        );
        let sum = summary(&sum);
        assert_eq!(sum["exit_ok"], false, "{sum}");
        assert_eq!(
            sum["services"]["dynamics"]["restarts"],
            u32::from(restarted),
            "{policy}: {sum}"
        );
    }
}

#[test]
fn a_forged_status_stream_does_not_keep_a_hung_service_alive() {
    use microrobot_messages::{
        LifecycleHook, LifecycleState, ServiceKind, ServiceStatus, monotonic_ns,
        open_publish_subscribe,
    };
    let dir = tempfile::tempdir().expect("tempdir");
    let inst = instance("verdict-forged-status");
    let cfg = write_config(
        dir.path(),
        &inst,
        "",
        "[supervisor]\non_failure = \"stop_all\"\nhung_ms = 400.0",
    );
    let proc = start(&[
        "run",
        "--config",
        &s(&cfg),
        "--no-program",
        "--duration",
        "30",
    ]);
    wait_ready(&inst, 60.0);
    let pid = pid_of(&inst, ServiceRole::Dynamics).expect("dynamics pid");
    let node = iceoryx2::prelude::NodeBuilder::new()
        .signal_handling_mode(iceoryx2::prelude::SignalHandlingMode::Disabled)
        .create::<iceoryx2::service::ipc::Service>()
        .expect("node");
    let publisher = open_publish_subscribe::<ServiceStatus>(&node, &inst, ServiceKind::Status)
        .expect("status service")
        .publisher_builder()
        .create()
        .expect("publisher");
    // SAFETY: kill(2) on a child of the pipeline this test started.
    unsafe { libc::kill(pid, libc::SIGSTOP) };
    // Statuses in the frozen dynamics' name, announcing a hook of 600 s: were they
    // taken, the supervisor would wait that long (the run would end at --duration).
    let end = std::time::Instant::now() + Duration::from_secs(20);
    let mut seq = 1_000_000;
    while alive(pid) && std::time::Instant::now() < end {
        seq += 1;
        let forged = ServiceStatus {
            seq,
            stamp_ns: monotonic_ns(),
            role: ServiceRole::Dynamics as u32,
            lifecycle: LifecycleState::Active as u32,
            pid: pid as u32,
            ready: 1,
            hook: LifecycleHook::Reset as u32,
            hook_budget_ms: 600_000,
            ..Default::default()
        };
        publisher.send_copy(forged).expect("send");
        std::thread::sleep(Duration::from_millis(50));
    }
    let out = proc.finish(120.0);
    assert!(!alive(pid), "the hung process was killed");
    assert_eq!(
        out.code(),
        Some(exit_code::SERVICE_FAILED as i32),
        "stderr:\n{}",
        out.stderr
    );
    assert!(
        out.stderr
            .contains("the dynamics service hung (its process lived but sent no status"),
        "stderr:\n{}",
        out.stderr
    );
    let warning = format!(
        "ignoring dynamics statuses that claim pid {pid} (published by pid {})",
        std::process::id()
    );
    assert_eq!(
        out.stderr.matches(&warning).count(),
        1,
        "named once; stderr:\n{}",
        out.stderr
    );
}

#[test]
fn a_program_abandoned_because_the_measured_state_went_stale_fails_the_run() {
    let (out, sum) = freeze_mid_program(
        "verdict-stale",
        ServiceRole::Actuator,
        Duration::from_millis(1000),
        NO_HUNG_KILL,
    );
    assert_eq!(
        out.code(),
        Some(exit_code::JOB_FAILED as i32),
        "stderr:\n{}",
        out.stderr
    );
    assert_eq!(sum["exit_ok"], false, "{sum}");
    assert_eq!(sum["program"]["state"], "abandoned", "{sum}");
    assert!(out.stderr.contains("abandoned"), "{}", out.stderr);
    assert!(out.stderr.contains("stale"), "{}", out.stderr);
    assert!(out.stdout.contains("result: FAILED"), "{}", out.stdout);
}

#[test]
fn a_safe_state_latched_by_a_frozen_dynamics_fails_the_run() {
    let (out, sum) = freeze_mid_program(
        "verdict-latch",
        ServiceRole::Dynamics,
        Duration::from_millis(2000),
        NO_HUNG_KILL,
    );
    assert_eq!(
        out.code(),
        Some(exit_code::JOB_FAILED as i32),
        "stderr:\n{}",
        out.stderr
    );
    assert_eq!(sum["exit_ok"], false, "{sum}");
    assert_eq!(sum["program"]["state"], "abandoned", "{sum}");
    let failures = sum["failures"].to_string();
    assert!(failures.contains("safe state"), "{failures}");
    assert!(out.stderr.contains("safe state latched"), "{}", out.stderr);
}

#[test]
fn a_finished_program_passes() {
    let dir = tempfile::tempdir().expect("tempdir");
    let inst = instance("verdict-ok");
    let prog = program(dir.path(), "short", [10.0, 5.0, 20.0, 0.0, 5.0, 0.0]);
    let cfg = write_config(
        dir.path(),
        &inst,
        &format!("program = \"{}\"", prog.display()),
        "",
    );
    let sum = dir.path().join("summary.json");
    let out = run(
        &["run", "--config", &s(&cfg), "--summary-json", &s(&sum)],
        120.0,
    );
    assert_eq!(out.code(), Some(0), "stderr:\n{}", out.stderr);
    let sum = summary(&sum);
    assert_eq!(sum["exit_ok"], true, "{sum}");
    assert_eq!(sum["program"]["state"], "finished", "{sum}");
    assert_eq!(sum["failures"], serde_json::json!([]), "{sum}");
}
