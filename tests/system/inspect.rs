//! Looking at a running arm like a ros2 system: `list`, `echo`, `hz`, `logs`; one
//! duration syntax; printing commands end quietly when their reader goes away.

use std::process::Command;

use crate::common::*;
use microrobot_runtime::exit_code;

fn s(p: &std::path::Path) -> String {
    p.to_str().expect("utf-8 path").to_string()
}

#[test]
fn a_running_instance_can_be_listed_echoed_measured_and_its_logs_read() {
    let dir = tempfile::tempdir().expect("tempdir");
    let inst = instance("inspect");
    let cfg = write_config(dir.path(), &inst, "", "");
    let proc = start_holding(&inst, &cfg, 30, None);

    let list = run(&["list", "--json"], 60.0);
    assert_eq!(list.code(), Some(0), "{}", list.stderr);
    let row: serde_json::Value = list
        .stdout
        .lines()
        .filter_map(|l| serde_json::from_str::<serde_json::Value>(l).ok())
        .find(|v| v["instance"] == inst.as_str())
        .unwrap_or_else(|| panic!("`{inst}` listed:\n{}", list.stdout));
    assert_eq!(row["state"], "running", "{row}");
    assert_eq!(row["robot"], "seed-arm.toml", "{row}");
    assert_eq!(row["rate_hz"], 1000.0, "{row}");
    assert!(row["processes"].as_u64().unwrap_or(0) >= 3, "{row}");

    let echo = run(&["echo", "state", "--instance", &inst, "-n", "3"], 60.0);
    assert_eq!(echo.code(), Some(0), "{}", echo.stderr);
    let seqs: Vec<u64> = echo
        .stdout
        .lines()
        .map(|l| {
            let v: serde_json::Value = serde_json::from_str(l).expect("one JSON object per line");
            v["header"]["seq"].as_u64().expect("header.seq")
        })
        .collect();
    assert_eq!(seqs.len(), 3, "{}", echo.stdout);
    assert!(seqs.windows(2).all(|w| w[1] > w[0]), "{seqs:?}");

    let hz = run(
        &[
            "hz",
            "setpoint",
            "--instance",
            &inst,
            "--duration",
            "2500ms",
        ],
        60.0,
    );
    assert_eq!(hz.code(), Some(0), "{}", hz.stderr);
    let rates: Vec<f64> = hz
        .stdout
        .lines()
        .filter_map(|l| l.strip_prefix("average rate: "))
        .filter_map(|r| r.split_whitespace().next()?.parse().ok())
        .collect();
    assert!(!rates.is_empty(), "{}", hz.stdout);
    // The planner's 1 kHz stream (a sanity range, not a timing claim).
    assert!(
        rates.iter().all(|r| (100.0..10_000.0).contains(r)),
        "{rates:?}"
    );

    let logs = run(&["logs", "planner", "--instance", &inst, "-n", "2"], 60.0);
    assert_eq!(logs.code(), Some(0), "{}", logs.stderr);
    assert_eq!(logs.stdout.lines().count(), 2, "{}", logs.stdout);
    assert!(
        !logs.stdout.contains('\u{1b}'),
        "log files are plain text, no ANSI escapes:\n{:?}",
        logs.stdout
    );
    proc.signal(libc::SIGINT);
    let end = proc.finish(60.0);
    assert_eq!(end.code(), Some(0), "{}", end.stderr);
}

#[test]
fn inspecting_an_instance_that_is_not_running_says_so_and_creates_nothing() {
    let inst = instance("inspect-absent");
    for args in [
        vec!["echo", "setpoint", "--instance", &inst, "-n", "1"],
        vec!["hz", "state", "--instance", &inst, "--duration", "1s"],
    ] {
        let out = run(&args, 60.0);
        assert_eq!(out.code(), Some(exit_code::FAILURE as i32), "{args:?}");
        assert!(
            out.stderr.contains("is running"),
            "{args:?}: {}",
            out.stderr
        );
    }
    assert_eq!(remaining_services(&inst), Vec::<String>::new());
}

#[test]
fn every_duration_flag_takes_the_same_forms() {
    let dir = tempfile::tempdir().expect("tempdir");
    let inst = instance("durations");
    let cfg = write_config(dir.path(), &inst, "", "");
    let sum = dir.path().join("summary.json");
    let out = run(
        &[
            "run",
            "--config",
            &s(&cfg),
            "--no-program",
            "--duration",
            "1500ms",
            "--summary-json",
            &s(&sum),
        ],
        120.0,
    );
    assert_eq!(out.code(), Some(0), "{}", out.stderr);
    let wall = summary(&sum)["wall_time_s"].as_f64().expect("wall_time_s");
    assert!(wall >= 1.5, "ran at least 1500 ms: {wall}");
    for bad in ["10x", "-1", "0"] {
        let out = run(&["run", "--config", &s(&cfg), "--duration", bad], 60.0);
        assert_eq!(
            out.code(),
            Some(exit_code::USAGE as i32),
            "`--duration {bad}`: {}",
            out.stderr
        );
        assert!(out.stderr.contains(bad), "{bad}: {}", out.stderr);
    }
}

#[test]
fn a_printing_command_ends_quietly_when_its_reader_closes() {
    // Megabytes of output (far beyond a pipe's buffer) into a reader that stops after
    // one line: the writer meets a closed pipe and must end without a panic.
    let model = format!(
        "yes '{{\"q\":[0,0,0,0,0,0],\"qd\":[0,0,0,0,0,0],\"qdd\":[0,0,0,0,0,0]}}' | head -n 20000 | '{}' eval model --robot '{}' | head -n 1",
        bin(),
        seed_arm().display()
    );
    let out = Command::new("sh")
        .arg("-c")
        .arg(&model)
        .output()
        .expect("sh");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stderr}");
    assert!(!stderr.contains("panicked"), "{stderr}");
    assert_eq!(String::from_utf8_lossy(&out.stdout).lines().count(), 1);
}

#[test]
fn shell_completions_cover_every_command() {
    let out = run(&["completions", "bash"], 60.0);
    assert_eq!(out.code(), Some(0), "{}", out.stderr);
    for cmd in [
        "run", "check", "send", "list", "echo", "hz", "logs", "top", "soak",
    ] {
        assert!(
            out.stdout.contains(&format!("microrobot__subcmd__{cmd}")),
            "`{cmd}` completes"
        );
    }
}
