//! `microrobot view`: the live Foxglove WebSocket view of a running pipeline. A real
//! Foxglove client (the official `@foxglove/ws-protocol` client under Node, pinned in
//! `tools/view/client/`) subscribes and receives the recording's channels with their
//! schema names, transforms that are the model's forward kinematics of the measured
//! joints, and finite values; a second client that subscribes and then stops reading
//! leaves the pipeline's lost-message count at 0; Ctrl-C stops the view cleanly. Bad
//! arguments and an instance that is not running are errors naming the problem.
//!
//! Without `node` the client tests are skipped with a printed reason, unless
//! `MICROROBOT_REQUIRE_NODE=1`, which makes a missing `node` a failure.

use std::io::{BufRead as _, BufReader};
use std::path::PathBuf;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use crate::common::*;
use microrobot_model::{JointVector, ModelData, Robot, tool_pose};
use serde_json::Value;

/// The directory of the pinned Node client.
fn client_dir() -> PathBuf {
    repo().join("tools/view/client")
}

/// Whether the Node client can run: `node` present and the pinned packages installed
/// (`npm ci` from the lock file when they are not). `false` (with the reason printed)
/// only when `node` is absent and `MICROROBOT_REQUIRE_NODE` is not `1`.
fn node_client_ready() -> bool {
    let require = std::env::var("MICROROBOT_REQUIRE_NODE").is_ok_and(|v| v == "1");
    let node = Command::new("node")
        .arg("--version")
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .status();
    if !node.is_ok_and(|s| s.success()) {
        assert!(!require, "MICROROBOT_REQUIRE_NODE=1 but `node` cannot run");
        eprintln!("skipped: `node` is not installed (the Foxglove client runs under Node)");
        return false;
    }
    let dir = client_dir();
    if !dir.join("node_modules/@foxglove/ws-protocol").is_dir() {
        let out = Command::new("npm")
            .args(["ci", "--no-audit", "--no-fund"])
            .current_dir(&dir)
            .stdin(Stdio::null())
            .output()
            .expect("run npm ci (node is installed, npm should be too)");
        assert!(
            out.status.success(),
            "npm ci in {}: {}",
            dir.display(),
            String::from_utf8_lossy(&out.stderr)
        );
    }
    true
}

/// Runs the Node client (`mode`: collect or stall) against `url` for `seconds`.
fn client(url: &str, mode: &str, seconds: u32) -> Proc {
    let child = Command::new("node")
        .arg(client_dir().join("client.js"))
        .args([url, mode, &seconds.to_string()])
        .current_dir(client_dir())
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("start node");
    Proc::from_child(child)
}

/// Starts `microrobot view ARGS` and waits for its ready line; returns the process and
/// the URL it serves.
fn start_view(args: &[&str]) -> (Proc, String) {
    let mut proc = start(&[&["view"], args].concat());
    let stdout = proc.child.stdout.take().expect("stdout");
    let mut lines = BufReader::new(stdout).lines();
    let line = lines
        .next()
        .and_then(Result::ok)
        .unwrap_or_else(|| panic!("microrobot view printed no ready line"));
    let url = line
        .strip_prefix("serving ")
        .and_then(|r| r.split_whitespace().next())
        .unwrap_or_else(|| panic!("unexpected ready line {line:?}"))
        .to_string();
    // Keep draining stdout so the view never blocks on it.
    std::thread::spawn(move || for _ in lines {});
    (proc, url)
}

fn finite(v: &Value) -> f64 {
    let x = v.as_f64().unwrap_or_else(|| panic!("not a number: {v}"));
    assert!(x.is_finite(), "{v}");
    x
}

/// The client's record of `topic`, checked to be advertised with `schema` as JSON.
fn channel<'a>(seen: &'a Value, topic: &str, schema: &str) -> &'a Value {
    let ch = &seen["channels"][topic];
    assert_eq!(ch["schemaName"], schema, "{topic}: {ch}");
    assert_eq!(ch["schemaEncoding"], "jsonschema", "{topic}");
    assert_eq!(ch["encoding"], "json", "{topic}");
    ch
}

#[test]
fn a_foxglove_client_sees_the_live_arm_and_a_stalled_one_costs_the_pipeline_nothing() {
    if !node_client_ready() {
        return;
    }
    // Build (under cargo) and find microrobot-view first, so its build time is not taken
    // from the pipeline's run below.
    let help = run(&["view", "--help"], 1200.0);
    assert!(help.status.success(), "{}", help.stderr);
    assert!(help.stdout.contains("--transforms-hz"), "{}", help.stdout);

    let dir = tempfile::tempdir().expect("tempdir");
    let inst = instance("view");
    let cfg = write_config(dir.path(), &inst, "", "");
    let summary_path = dir.path().join("summary.json");
    let pipeline = start_holding(&inst, &cfg, 14, Some(&summary_path));
    let (view, url) = start_view(&[
        "--instance",
        &inst,
        "--bind",
        "127.0.0.1:0",
        "--transforms-hz",
        "200",
        "--joints-hz",
        "200",
    ]);
    assert!(url.starts_with("ws://127.0.0.1:"), "{url}");

    let seen = client(&url, "collect", 3).finish(30.0);
    assert!(seen.status.success(), "client: {}", seen.stderr);
    let seen: Value = serde_json::from_str(seen.stdout.trim()).unwrap_or_else(|e| {
        let head: String = seen.stdout.chars().take(2000).collect();
        panic!(
            "client output ({} bytes) {head:?}...: {e}",
            seen.stdout.len()
        )
    });
    assert_eq!(seen["server"], format!("microrobot {inst}"));
    for (topic, schema) in [
        ("setpoint", "microrobot::v2::JointSetpoint"),
        ("torque", "microrobot::v2::TorqueCommand"),
        ("state", "microrobot::v2::JointState"),
        ("command", "microrobot::v2::MotionCommand"),
        ("status", "microrobot::v2::ServiceStatus"),
        ("scene", "foxglove.SceneUpdate"),
        ("log", "foxglove.Log"),
    ] {
        channel(&seen, topic, schema);
    }
    let transforms = channel(&seen, "transforms", "foxglove.FrameTransforms");
    let joints = channel(&seen, "joints", "microrobot.JointStates");
    // 3 s at 200 Hz: ~600 of each (transforms twice: measured and commanded).
    for (topic, ch) in [("transforms", transforms), ("joints", joints)] {
        let n = ch["count"].as_u64().expect("count");
        assert!(n >= 100, "{topic}: {n} messages in 3 s at 200 Hz");
    }
    assert!(channel(&seen, "state", "microrobot::v2::JointState")["count"].as_u64() >= Some(30));

    // Every transform: a named frame under base_link with finite values and a unit
    // quaternion; the measured tool frame is the model's FK of the joints message sent
    // with it (the same state: same log time).
    let robot = Robot::from_file(&seed_arm()).expect("seed arm");
    let mut data = ModelData::new(&robot);
    let joints_at: Vec<(&str, &Value)> = joints["last"]
        .as_array()
        .expect("joints")
        .iter()
        .map(|m| (m["log_time"].as_str().expect("log_time"), &m["value"]))
        .collect();
    let mut compared = 0;
    let mut frames = std::collections::BTreeSet::new();
    for m in transforms["last"].as_array().expect("transforms") {
        for t in m["value"]["transforms"].as_array().expect("list") {
            assert_eq!(t["parent_frame_id"], "base_link", "{t}");
            frames.insert(t["child_frame_id"].as_str().expect("child").to_string());
            let q: Vec<f64> = ["x", "y", "z", "w"]
                .iter()
                .map(|k| finite(&t["rotation"][k]))
                .collect();
            let norm = q.iter().map(|x| x * x).sum::<f64>().sqrt();
            assert!((norm - 1.0).abs() < 1e-9, "{t}");
            for k in ["x", "y", "z"] {
                finite(&t["translation"][k]);
            }
            if t["child_frame_id"] != "tool" {
                continue;
            }
            let log_time = m["log_time"].as_str().expect("log_time");
            let Some((_, j)) = joints_at.iter().find(|(at, _)| *at == log_time) else {
                continue;
            };
            let q: Vec<f64> = j["position"]
                .as_array()
                .expect("position")
                .iter()
                .map(finite)
                .collect();
            assert_eq!(q.len(), 6);
            let mut v = JointVector::zeros();
            v.as_mut_slice()[..6].copy_from_slice(&q);
            let want = tool_pose(&robot, &mut data, &v);
            for (axis, k) in ["x", "y", "z"].iter().enumerate() {
                let got = finite(&t["translation"][k]);
                assert!(
                    (got - want.translation[axis]).abs() < 1e-9,
                    "tool {k}: {got} vs FK {}",
                    want.translation[axis]
                );
            }
            compared += 1;
        }
    }
    assert!(
        compared >= 5,
        "only {compared} tool frames matched a joints message"
    );
    for f in ["tool", "cmd/tool"] {
        assert!(frames.contains(f), "no frame {f}: {frames:?}");
    }
    let names = joints_at[0].1["name"].as_array().expect("names");
    assert_eq!(names.len(), 6);
    for n in names {
        assert!(
            frames.contains(n.as_str().expect("name")),
            "{n}: {frames:?}"
        );
    }

    // A client that subscribes to everything and then stops reading for the rest of the
    // run (~1.7 MB/s at these rates: its socket buffers, a few MB, fill within seconds):
    // the pipeline loses nothing (the SDK drops that client's oldest queued messages).
    let stalled = client(&url, "stall", 9);
    let run = pipeline.finish(60.0);
    let pipeline_ended = Instant::now();
    assert!(run.status.success(), "{}", run.stderr);
    let stalled = stalled.finish(30.0);
    assert!(
        stalled.stdout.contains("\"stalled\":true"),
        "{} {}",
        stalled.stdout,
        stalled.stderr
    );
    let s = summary(&summary_path);
    assert_eq!(s["lost_messages"], 0, "a stalled viewer cost messages: {s}");

    // The pipeline has ended: within a second and a half the view says so, and it keeps
    // serving until Ctrl-C, which stops it cleanly.
    std::thread::sleep(Duration::from_millis(1500).saturating_sub(pipeline_ended.elapsed()));
    let mut view = view;
    view.signal(libc::SIGINT);
    let t0 = Instant::now();
    let status = loop {
        if let Some(st) = view.child.try_wait().expect("try_wait") {
            break st;
        }
        if t0.elapsed() > Duration::from_secs(20) {
            let _ = view.child.kill();
            panic!("microrobot view did not stop within 20 s of SIGINT");
        }
        std::thread::sleep(Duration::from_millis(20));
    };
    let mut err = String::new();
    if let Some(mut e) = view.child.stderr.take() {
        let _ = std::io::Read::read_to_string(&mut e, &mut err);
    }
    assert!(status.success(), "view: {status:?} {err}");
    assert!(err.contains("stopped"), "{err}");
    assert!(
        err.contains("has sent no status") && err.contains("still serving"),
        "the view did not say that the pipeline stopped: {err}"
    );
}

#[test]
fn view_refuses_bad_arguments_and_an_instance_that_is_not_running() {
    // Found (and under cargo, built) first; then each error names its problem.
    let help = run(&["view", "--help"], 1200.0);
    assert!(help.status.success(), "{}", help.stderr);
    for (args, expected) in [
        (vec!["--transforms-hz", "0"], "--transforms-hz"),
        (vec!["--joints-hz", "fast"], "--joints-hz"),
        (vec!["--bind", "localhost"], "--bind"),
        (vec!["--instance", "no such"], "--instance `no such`"),
        (
            vec!["--instance", "t-view-nobody-runs-this"],
            "no pipeline instance `t-view-nobody-runs-this` is running",
        ),
    ] {
        let out = run(&[&["view"], args.as_slice()].concat(), 60.0);
        assert!(!out.status.success(), "{args:?}: {}", out.stderr);
        assert!(out.stderr.contains(expected), "{args:?}: {}", out.stderr);
    }
}

#[test]
fn view_without_its_binary_names_the_command_that_builds_it() {
    // A CLI copied alone (not in a Cargo target directory, so nothing is built for it).
    let dir = tempfile::tempdir().expect("tempdir");
    let cli = dir.path().join("microrobot");
    std::fs::copy(bin(), &cli).expect("copy microrobot");
    let out = Command::new(&cli)
        .args(["view", "--instance", "default"])
        .stdin(Stdio::null())
        .output()
        .expect("run the copied microrobot");
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "{err}");
    assert!(err.contains("microrobot-view is missing"), "{err}");
    assert!(
        err.contains("build it with `cargo build --release -p microrobot-view`"),
        "{err}"
    );
    assert_eq!(err.lines().count(), 1, "{err}");
}
