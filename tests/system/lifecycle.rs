//! The supervisor's lifecycle: Ctrl-C stops everything cleanly and leaves nothing
//! behind, a run after `kill -9` starts cleanly, instances are separate and unique.

use std::collections::BTreeSet;
use std::time::{Duration, Instant};

use crate::common::*;
use microrobot_messages::ServiceRole;

fn cfg_arg(path: &std::path::Path) -> String {
    path.to_str().expect("utf-8 path").to_string()
}

#[test]
fn ctrl_c_mid_run_stops_every_process_with_exit_0_and_leaves_no_resources() {
    let dir = tempfile::tempdir().expect("tempdir");
    let inst = instance("ctrlc");
    let cfg = write_config(dir.path(), &inst, "", "");
    let summary_path = dir.path().join("summary.json");
    let proc = start(&[
        "run",
        "--config",
        &cfg_arg(&cfg),
        "--no-program",
        "--duration",
        "120",
        "--summary-json",
        &cfg_arg(&summary_path),
    ]);
    let rec = Recorder::start_statuses(&inst);
    wait_ready(&inst, 60.0);
    std::thread::sleep(Duration::from_millis(500));
    proc.signal(libc::SIGINT);
    let out = proc.finish(60.0);
    let statuses = rec.finish().statuses;
    assert_eq!(
        out.code(),
        Some(0),
        "supervisor exit; stderr:\n{}",
        out.stderr
    );

    let s = summary(&summary_path);
    assert_eq!(s["exit_ok"], true, "{s}");
    assert_eq!(s["stop_reason"], "interrupted");
    for svc in ["planner", "dynamics", "actuator"] {
        assert_eq!(s["services"][svc]["exit"], "exit code 0", "{svc}: {s}");
        assert_eq!(
            s["services"][svc]["last_lifecycle"], "finalized",
            "{svc}: {s}"
        );
    }
    let pids: BTreeSet<u32> = statuses.iter().map(|st| st.pid).collect();
    assert_eq!(pids.len(), 3, "three service processes: {pids:?}");
    for pid in pids {
        assert!(!alive(pid as i32), "service pid {pid} still alive");
    }
    assert_eq!(
        remaining_services(&inst),
        Vec::<String>::new(),
        "iceoryx2 services left"
    );
    assert_eq!(
        remaining_nodes(&inst),
        Vec::<String>::new(),
        "iceoryx2 nodes left"
    );
}

#[test]
fn a_run_after_kill_9_of_supervisor_and_actuator_starts_cleanly() {
    let dir = tempfile::tempdir().expect("tempdir");
    let inst = instance("kill9");
    let cfg = write_config(dir.path(), &inst, "", "");
    let proc = start(&[
        "run",
        "--config",
        &cfg_arg(&cfg),
        "--no-program",
        "--duration",
        "120",
    ]);
    let rec = Recorder::start_statuses(&inst);
    wait_ready(&inst, 60.0);
    let statuses = rec.finish().statuses;
    let pid_of = |role: ServiceRole| {
        statuses
            .iter()
            .rev()
            .find(|s| s.role == role as u32)
            .map(|s| s.pid as i32)
            .expect("a status of every role")
    };
    let pids = [
        pid_of(ServiceRole::Planner),
        pid_of(ServiceRole::Dynamics),
        pid_of(ServiceRole::Actuator),
    ];
    // SAFETY: kill(2) on processes of this test.
    unsafe { libc::kill(pids[2], libc::SIGKILL) };
    proc.signal(libc::SIGKILL);
    let _ = proc.finish(30.0);
    // The others stop by themselves: their parent died (PR_SET_PDEATHSIG).
    let t0 = Instant::now();
    while pids.iter().any(|p| alive(*p)) {
        assert!(
            t0.elapsed() < Duration::from_secs(30),
            "services still alive after the supervisor died: {pids:?}"
        );
        std::thread::sleep(Duration::from_millis(50));
    }

    let summary_path = dir.path().join("summary.json");
    let out = run(
        &[
            "run",
            "--config",
            &cfg_arg(&cfg),
            "--no-program",
            "--duration",
            "2",
            "--summary-json",
            &cfg_arg(&summary_path),
        ],
        90.0,
    );
    assert_eq!(out.code(), Some(0), "second run; stderr:\n{}", out.stderr);
    let s = summary(&summary_path);
    assert_eq!(s["exit_ok"], true, "{s}");
    assert!(s["cycles"]["planner"].as_u64().unwrap_or(0) > 0, "{s}");
    assert_eq!(remaining_services(&inst), Vec::<String>::new());
    assert_eq!(remaining_nodes(&inst), Vec::<String>::new());
}

#[test]
fn two_instances_run_side_by_side_without_crosstalk_and_a_duplicate_is_refused() {
    let dir = tempfile::tempdir().expect("tempdir");
    let (ia, ib) = (instance("side-a"), instance("side-b"));
    let (ca, cb) = (
        write_config(dir.path(), &ia, "", ""),
        write_config(dir.path(), &ib, "", ""),
    );
    let (sa, sb) = (dir.path().join("a.json"), dir.path().join("b.json"));
    let (ra, rb) = (Recorder::start_statuses(&ia), Recorder::start_statuses(&ib));
    let a = start(&[
        "run",
        "--config",
        &cfg_arg(&ca),
        "--no-program",
        "--duration",
        "4",
        "--summary-json",
        &cfg_arg(&sa),
    ]);
    let b = start(&[
        "run",
        "--config",
        &cfg_arg(&cb),
        "--no-program",
        "--duration",
        "4",
        "--summary-json",
        &cfg_arg(&sb),
    ]);
    wait_ready(&ia, 60.0);
    let dup = run(
        &[
            "run",
            "--config",
            &cfg_arg(&ca),
            "--no-program",
            "--duration",
            "1",
        ],
        60.0,
    );
    assert_eq!(
        dup.code(),
        Some(5),
        "INSTANCE_IN_USE; stderr:\n{}",
        dup.stderr
    );
    assert!(dup.stderr.contains("already in use"), "{}", dup.stderr);

    let (oa, ob) = (a.finish(90.0), b.finish(90.0));
    assert_eq!(oa.code(), Some(0), "{}", oa.stderr);
    assert_eq!(ob.code(), Some(0), "{}", ob.stderr);
    let (pa, pb): (BTreeSet<u32>, BTreeSet<u32>) = (
        ra.finish().statuses.iter().map(|s| s.pid).collect(),
        rb.finish().statuses.iter().map(|s| s.pid).collect(),
    );
    assert_eq!(
        pa.len(),
        3,
        "instance a's status stream carries its 3 services only: {pa:?}"
    );
    assert_eq!(
        pb.len(),
        3,
        "instance b's status stream carries its 3 services only: {pb:?}"
    );
    assert!(pa.is_disjoint(&pb), "{pa:?} vs {pb:?}");
    for path in [&sa, &sb] {
        let s = summary(path);
        assert_eq!(s["exit_ok"], true, "{s}");
        for svc in ["planner", "dynamics", "actuator"] {
            let v = &s["services"][svc];
            assert_eq!(v["refused_messages"], 0, "{svc}: {s}");
            assert_eq!(v["lost_messages"], 0, "{svc}: {s}");
        }
    }
}
