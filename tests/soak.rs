//! `microrobot soak` through the real binary: a short soak with one kill of each service
//! (planner, dynamics, actuator, in that order) and random commands. Asserts the
//! report's verdict fields, never its timing figures.

mod common;

use common::*;

/// Runs `microrobot soak` on a fresh instance with `extra` flags into `<dir>/soak`;
/// returns the process's output and the parsed report.json.
fn soak(dir: &std::path::Path, name: &str, extra: &[&str]) -> (Finished, serde_json::Value) {
    let inst = instance(name);
    let cfg = write_config(dir, &inst, "", "");
    let out = dir.join("soak");
    let cfg_s = cfg.to_str().expect("utf-8").to_string();
    let out_s = out.to_str().expect("utf-8").to_string();
    let mut args = vec!["soak", "--config", &cfg_s, "--instance", &inst];
    args.extend_from_slice(extra);
    args.extend_from_slice(&["--quiet", "--out", &out_s]);
    let done = run(&args, 240.0);
    let text = std::fs::read_to_string(out.join("report.json")).unwrap_or_else(|e| {
        panic!(
            "no report.json ({e}); exit {:?}\nstdout:\n{}\nstderr:\n{}",
            done.code(),
            done.stdout,
            done.stderr
        )
    });
    let r = serde_json::from_str(&text).expect("report is JSON");
    (done, r)
}

#[test]
fn a_short_soak_with_a_kill_of_each_service_recovers_without_jumps_or_losses() {
    let dir = tempfile::tempdir().expect("tempdir");
    let out = dir.path().join("soak");
    let (done, r) = soak(
        dir.path(),
        "soak",
        &[
            "--duration",
            "32s",
            "--kill-every",
            "5",
            "--random-commands",
        ],
    );
    let v = &r["verdict"];
    let ctx = || {
        format!(
            "verdict {v}\nfaults {}\njumps {}\nstderr:\n{}",
            r["faults"], r["jumps"], done.stderr
        )
    };
    assert_eq!(v["jumps"], 0, "{}", ctx());
    assert_eq!(v["lost_setpoints_outside_kill_windows"], 0, "{}", ctx());
    assert_eq!(v["lost_outside_kill_windows"], 0, "{}", ctx());
    assert_eq!(v["latches_without_fault"], 0, "{}", ctx());
    let injected = v["faults_injected"].as_u64().expect("faults_injected");
    assert_eq!(injected, 3, "one kill per service: {}", ctx());
    assert_eq!(v["faults_recovered"].as_u64(), Some(injected), "{}", ctx());
    let killed: Vec<&str> = r["faults"]
        .as_array()
        .expect("faults")
        .iter()
        .filter_map(|f| f["role"].as_str())
        .collect();
    assert_eq!(killed, ["planner", "dynamics", "actuator"], "{}", ctx());
    // One planner kill: the floor probe split its lateness into the planner's two
    // process lifetimes, and the planner is held against the larger window p99.
    let windows = r["floor"]["window_p99_us"]
        .as_array()
        .expect("floor windows");
    assert_eq!(windows.len(), 2, "{}", r["floor"]);
    let worst = windows
        .iter()
        .map(|w| w.as_f64().expect("p99"))
        .fold(0.0, f64::max);
    let planner_p99 = r["planner_lateness_us"]["p99"]
        .as_f64()
        .expect("planner p99");
    let ratio = r["lateness_p99_vs_floor"].as_f64().expect("ratio");
    assert!(
        (ratio - planner_p99 / worst).abs() <= 1e-9 * ratio.abs(),
        "{ratio} vs {planner_p99} / {worst}"
    );
    assert_eq!(v["pass"], true, "{}", ctx());
    assert_eq!(done.code(), Some(0), "{}", ctx());
    // The per-hop budget: every hop timed, and the chain no shorter than its first hop.
    let hops = r["hop_budget_us"].as_array().expect("hop budget");
    let hop = |name: &str| {
        hops.iter()
            .find(|h| h[0] == name)
            .map(|h| h[1].clone())
            .unwrap_or_else(|| panic!("hop {name} missing: {hops:?}"))
    };
    for name in ["setpoint_to_torque", "torque_to_state", "setpoint_to_state"] {
        assert!(
            hop(name)["count"].as_u64().expect("count") > 1000,
            "{name}: {hops:?}"
        );
    }
    let p50 = |name: &str| hop(name)["p50"].as_f64().expect("p50");
    assert!(
        p50("setpoint_to_state") >= p50("setpoint_to_torque"),
        "{hops:?}"
    );
    assert!(out.join("latency_histogram.png").is_file());
    // The markdown is rendered from the same report, and `--render` reproduces it.
    let md = std::fs::read_to_string(out.join("report.md")).expect("report.md");
    assert!(md.contains("**Verdict: PASS**"), "{md}");
    let rendered = dir.path().join("rendered.md");
    let r2 = run(
        &[
            "soak",
            "--render",
            out.join("report.json").to_str().expect("utf-8"),
            "--title",
            "Soak report",
            "--out",
            rendered.to_str().expect("utf-8"),
        ],
        30.0,
    );
    assert_eq!(r2.code(), Some(0), "{}", r2.stderr);
    assert_eq!(std::fs::read_to_string(&rendered).expect("rendered"), md);
}

/// Stalls (SIGSTOP) of each service longer than `supervisor.hung_ms`: the supervisor
/// finds each hung, kills and restarts it, and the soak reports the hung verdict's time
/// beside the stream-level detection, without jumps or losses outside the fault windows.
#[test]
fn a_soak_with_stalls_catches_each_hung_service_and_recovers() {
    let dir = tempfile::tempdir().expect("tempdir");
    let out = dir.path().join("soak");
    let (done, r) = soak(
        dir.path(),
        "soak-stall",
        &[
            "--duration",
            "36s",
            "--stall-every",
            "6",
            "--stall-for",
            "2s",
        ],
    );
    let v = &r["verdict"];
    let ctx = || {
        format!(
            "verdict {v}\nfaults {}\nstderr:\n{}",
            r["faults"], done.stderr
        )
    };
    assert_eq!(done.code(), Some(0), "{}", ctx());
    assert_eq!(v["pass"], true, "{}", ctx());
    assert_eq!(v["jumps"], 0, "{}", ctx());
    assert_eq!(v["lost_outside_kill_windows"], 0, "{}", ctx());
    assert_eq!(v["latches_without_fault"], 0, "{}", ctx());
    let faults = r["faults"].as_array().expect("faults");
    let roles: Vec<&str> = faults.iter().filter_map(|f| f["role"].as_str()).collect();
    assert_eq!(roles, ["planner", "dynamics", "actuator"], "{}", ctx());
    for f in faults {
        assert_eq!(f["kind"], "stall", "{}", ctx());
        assert_eq!(f["recovered"], true, "{}", ctx());
        // Caught as hung: the supervisor's verdict came after hung_ms of silence and
        // before the stall would have ended on its own.
        let hung = f["hung_detect_ms"]
            .as_f64()
            .unwrap_or_else(|| panic!("{}", ctx()));
        assert!(hung > 0.0 && hung < 2000.0, "{hung} ms; {}", ctx());
    }
    assert_eq!(r["hung_detect_ms"]["count"], 3, "{}", ctx());
    let md = std::fs::read_to_string(out.join("report.md")).expect("report.md");
    assert!(md.contains("| stall planner (pid "), "{md}");
}
