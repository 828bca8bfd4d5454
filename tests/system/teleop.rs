//! Teleoperation through the real processes: `microrobot run` with `[teleop]`,
//! `microrobot teleop-source` as the master device, `microrobot teleop-report` and a
//! recorder as monitors.
//!
//! 1. Tremor and scaling, on the seed arm's geometry with teleop-grade joint limits
//!    (the seed's Table 4 limits, 40–80 °/s² and 80–160 °/s³, are for a slow
//!    program, too slow to follow a hand at 1 Hz): ≥ 20 dB at 10 Hz, ≤ 1 dB loss at
//!    1 Hz, the displacement within 1 % of hand / ratio once settled.
//! 2. Clutch, NaN samples, a stalled device and a hand far outside the workspace, on
//!    the seed arm itself: flagged, joint limits never exceeded, no jump.

use std::time::Duration;

use crate::common::*;
use microrobot_messages::{JointSetpoint, setpoint_flags};
use microrobot_model::Robot;

/// A pipeline config running teleop from the start, arm at a dexterous pose.
fn teleop_config(dir: &std::path::Path, inst: &str, robot: &std::path::Path, ratio: f64) -> String {
    let text = format!(
        "instance = \"{inst}\"\nrobot = \"{}\"\n\n[realtime]\ncpu_affinity = []\npm_qos = false\nmlockall = false\n\n[actuator.sim]\ninitial_q_deg = [0, 30, 60, 0, 30, 0]\n\n[teleop]\nenabled = true\nratio = {ratio:?}\nfilter_cutoff_hz = 4.0\n",
        robot.display()
    );
    let path = dir.join(format!("{inst}.toml"));
    std::fs::write(&path, text).expect("write config");
    path.to_str().expect("utf-8").to_string()
}

/// The seed arm with accelerations ×20 and jerks ×100 (same geometry and masses).
fn fast_seed_arm(dir: &std::path::Path) -> std::path::PathBuf {
    let text = std::fs::read_to_string(seed_arm()).expect("seed arm");
    let scale = |text: &str, key: &str, factor: f64| -> String {
        let mut out = String::new();
        let mut rest = text;
        while let Some(i) = rest.find(key) {
            let (head, tail) = rest.split_at(i + key.len());
            out.push_str(head);
            let end = tail.find([',', ' ', '}']).expect("number end");
            let v: f64 = tail[..end].trim().parse().expect("number");
            out.push_str(&format!("{:?}", v * factor));
            rest = &tail[end..];
        }
        out.push_str(rest);
        out
    };
    let text = scale(&text, "acc_deg_s2 = ", 20.0);
    let text = scale(&text, "jerk_deg_s3 = ", 100.0);
    let path = dir.join("seed-arm-teleop.toml");
    std::fs::write(&path, text).expect("write robot");
    path
}

fn report(inst: &str, cfg: &str, seconds: f64, settle: f64, extra: &[&str]) -> Proc {
    let d = seconds.to_string();
    let s = settle.to_string();
    let mut args = vec![
        "teleop-report",
        "--instance",
        inst,
        "--config",
        cfg,
        "--duration",
        &d,
        "--settle",
        &s,
        "--json",
    ];
    args.extend_from_slice(extra);
    start(&args)
}

fn source(inst: &str, args: &[&str]) -> Proc {
    let mut all = vec!["teleop-source", "--instance", inst];
    all.extend_from_slice(args);
    start(&all)
}

/// The report's JSON; its exit code must match its own verdict (0 exactly on a pass,
/// JOB_FAILED on a failed check).
fn json_of(out: &Finished) -> serde_json::Value {
    let v: serde_json::Value = serde_json::from_str(out.stdout.trim()).expect("report JSON");
    let pass = v["verdict"]["pass"].as_bool().expect("verdict.pass");
    let want = if pass {
        0
    } else {
        microrobot_runtime::exit_code::JOB_FAILED as i32
    };
    assert_eq!(out.code(), Some(want), "{}\n{v}", out.stderr);
    v
}

/// Whether the report's verdict judged check `name` (Some(pass)) or not (None).
fn check(report: &serde_json::Value, name: &str) -> Option<bool> {
    report["verdict"]["checks"]
        .as_array()
        .and_then(|c| c.iter().find(|c| c["name"] == name))
        .and_then(|c| c["pass"].as_bool())
}

#[test]
fn tremor_is_filtered_and_hand_motion_scaled_through_the_pipeline() {
    let dir = tempfile::tempdir().expect("tempdir");
    let inst = instance("teleop-tremor");
    let robot = fast_seed_arm(dir.path());
    let cfg = teleop_config(dir.path(), &inst, &robot, 3.0);
    let pipeline = start(&["run", "--config", &cfg, "--no-program", "--duration", "60"]);
    wait_ready(&inst, 60.0);

    // Voluntary 1 Hz (0.6 mm / 0.3 mm) plus 0.3 mm tremor at 10 Hz on every axis.
    let rep = report(
        &inst,
        &cfg,
        8.0,
        2.0,
        &["--voluntary-hz", "1", "--tremor-hz", "10"],
    );
    std::thread::sleep(Duration::from_millis(300));
    let src = source(
        &inst,
        &[
            "--duration",
            "8.5",
            "--voluntary-mm",
            "0.6,0.3,0",
            "--voluntary-hz",
            "1",
            "--tremor-mm",
            "0.3",
            "--tremor-hz",
            "10",
        ],
    );
    let r = json_of(&rep.finish(60.0));
    assert_eq!(src.finish(60.0).code(), Some(0));
    eprintln!("tremor run: {r}");
    let att = r["tremor_attenuation_db"].as_f64().expect("attenuation");
    assert!(att >= 20.0, "tremor attenuation at 10 Hz {att:.1} dB");
    let gain = r["voluntary"]["gain_db"].as_f64().expect("gain");
    assert!(gain.abs() <= 1.0, "voluntary 1 Hz gain {gain:+.2} dB");
    let lag = r["voluntary"]["phase_lag_deg"].as_f64().expect("lag");
    assert!(lag > 0.0 && lag < 90.0, "phase lag at 1 Hz {lag:.1} deg");
    assert!(r["latency_us"]["count"].as_u64().expect("count") > 1000);
    // The report's own verdict agrees with the figures checked above.
    assert_eq!(check(&r, "tremor attenuation"), Some(true), "{r}");
    assert_eq!(check(&r, "voluntary gain"), Some(true), "{r}");

    // Ramp 3 mm / −1.5 mm / 1.5 mm and hold, with tremor: hand / 3 within 1 %.
    let rep = report(
        &inst,
        &cfg,
        5.5,
        0.0,
        &["--voluntary-hz", "1", "--tremor-hz", "10"],
    );
    std::thread::sleep(Duration::from_millis(300));
    let src = source(
        &inst,
        &[
            "--duration",
            "6",
            "--voluntary-mm",
            "0,0,0",
            "--tremor-mm",
            "0.3",
            "--ramp-mm",
            "3,-1.5,1.5",
            "--ramp-s",
            "2",
        ],
    );
    let r = json_of(&rep.finish(60.0));
    assert_eq!(src.finish(60.0).code(), Some(0));
    eprintln!("ramp run: {r}");
    let err = r["final_displacement_error_pct"].as_f64().expect("error");
    let moved = r["final_hand_scaled_displacement_mm"]
        .as_f64()
        .expect("moved");
    // The reference is the first sample: ramp 0 plus the tremor's phase there
    // (0.3 mm · sin(2k) on axis k), so the hand moves (3, −1.5 − 0.3 sin 2, 1.5 − 0.3 sin 4) mm.
    let hand = [3.0, -1.5 - 0.3 * 2f64.sin(), 1.5 - 0.3 * 4f64.sin()];
    let want = hand.iter().map(|v| v * v).sum::<f64>().sqrt() / 3.0;
    assert!(
        (moved - want).abs() < 0.01,
        "hand/ratio {moved} mm, want {want} mm"
    );
    assert!(err <= 1.0, "scaled displacement error {err:.2} %");
    assert_eq!(check(&r, "final displacement error"), Some(true), "{r}");

    pipeline.signal(libc::SIGINT);
    let out = pipeline.finish(60.0);
    assert_eq!(out.code(), Some(0), "{}", out.stderr);
}

/// Setpoint stream checks: joint limits and no jump in q, q̇, q̈.
fn assert_within_limits_and_continuous(robot: &Robot, sp: &[JointSetpoint]) {
    let dt = 1e-3;
    for w in sp.windows(2) {
        let (a, b) = (&w[0], &w[1]);
        let ticks = b.header.tick.saturating_sub(a.header.tick);
        assert!(ticks >= 1, "ticks increase");
        let h = ticks as f64 * dt;
        for (j, joint) in robot.joints().iter().enumerate() {
            let l = &joint.limits;
            let at = || format!("joint {} at tick {}", j + 1, b.header.tick);
            assert!(
                b.q[j] >= l.min - 1e-9 && b.q[j] <= l.max + 1e-9,
                "q limit, {}",
                at()
            );
            assert!(
                b.qd[j].abs() <= l.velocity * 1.0001,
                "velocity limit, {}",
                at()
            );
            assert!(
                b.qdd[j].abs() <= l.acceleration * 1.0001,
                "acceleration limit, {}",
                at()
            );
            let dq = b.q[j] - a.q[j] - 0.5 * (a.qd[j] + b.qd[j]) * h;
            assert!(
                dq.abs() <= l.acceleration * h * h + 1e-9,
                "q jump {dq:e}, {}",
                at()
            );
            let dqd = b.qd[j] - a.qd[j];
            assert!(
                dqd.abs() <= l.acceleration * h * 1.01 + 1e-9,
                "qd jump {dqd:e}, {}",
                at()
            );
            let dqdd = b.qdd[j] - a.qdd[j];
            assert!(
                dqdd.abs() <= l.jerk * h * 1.01 + 1e-9,
                "qdd jump {dqdd:e}, {}",
                at()
            );
        }
    }
}

fn seen(sp: &[JointSetpoint], bit: u32) -> usize {
    sp.iter().filter(|s| s.flags & bit != 0).count()
}

#[test]
fn clutch_nan_stalls_and_the_workspace_edge_never_make_the_arm_jump() {
    let dir = tempfile::tempdir().expect("tempdir");
    let inst = instance("teleop-safety");
    let robot_path = seed_arm();
    let robot = Robot::from_file(&robot_path).expect("seed arm");
    let cfg = teleop_config(dir.path(), &inst, &robot_path, 3.0);
    let rec = Recorder::start(&inst);
    let pipeline = start(&["run", "--config", &cfg, "--no-program", "--duration", "60"]);
    wait_ready(&inst, 60.0);

    // Hand moving at 0.5 Hz; clutch open 2–3.5 s (the hand keeps moving), NaN samples
    // 4.5–4.7 s, the device silent 5.2–5.6 s.
    let src = source(
        &inst,
        &[
            "--duration",
            "6.5",
            "--voluntary-mm",
            "3,3,0",
            "--voluntary-hz",
            "0.5",
            "--tremor-mm",
            "0.3",
            "--clutch-open",
            "2-3.5",
            "--nan",
            "4.5-4.7",
            "--silent",
            "5.2-5.6",
        ],
    );
    assert_eq!(src.finish(60.0).code(), Some(0));
    // Then far outside the workspace: 0.3 m of tool motion outwards and up.
    let src = source(
        &inst,
        &[
            "--duration",
            "6",
            "--voluntary-mm",
            "0,0,0",
            "--tremor-mm",
            "0",
            "--ramp-mm",
            "900,0,900",
            "--ramp-s",
            "3",
        ],
    );
    assert_eq!(src.finish(60.0).code(), Some(0));
    std::thread::sleep(Duration::from_millis(500));
    pipeline.signal(libc::SIGINT);
    let out = pipeline.finish(60.0);
    assert_eq!(out.code(), Some(0), "{}", out.stderr);
    let sp = rec.finish().setpoints;
    assert!(sp.len() > 5000, "setpoints recorded: {}", sp.len());
    assert!(sp.iter().all(|s| s.flags & setpoint_flags::TELEOP != 0));
    assert_within_limits_and_continuous(&robot, &sp);
    let moving = sp
        .iter()
        .filter(|s| s.flags & setpoint_flags::MOVING != 0)
        .count();
    assert!(moving > 1000, "the arm moved ({moving} moving setpoints)");
    for (bit, name) in [
        (setpoint_flags::TELEOP_CLUTCH_OPEN, "clutch open"),
        (setpoint_flags::TELEOP_INPUT_REFUSED, "input refused (NaN)"),
        (setpoint_flags::TELEOP_MASTER_STALE, "master stale"),
    ] {
        assert!(seen(&sp, bit) > 0, "{name} never flagged");
    }
    let edge = seen(
        &sp,
        setpoint_flags::TELEOP_WORKSPACE_EDGE | setpoint_flags::TELEOP_FLIP_REFUSED,
    );
    assert!(edge > 100, "workspace edge flagged on {edge} setpoints");
    // Held while the clutch was open: at rest for the last part of it.
    let open: Vec<&JointSetpoint> = sp
        .iter()
        .filter(|s| s.flags & setpoint_flags::TELEOP_CLUTCH_OPEN != 0)
        .collect();
    let speed = |s: &&JointSetpoint| s.qd.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    let head = open[..open.len() / 8].iter().map(speed).fold(0.0, f64::max);
    let tail = open[open.len() * 3 / 4..]
        .iter()
        .map(speed)
        .fold(0.0, f64::max);
    eprintln!(
        "clutch open: max |qd| {head:e} rad/s at release, {tail:e} rad/s in the last quarter"
    );
    assert!(
        tail < 0.1 * head.max(1e-6),
        "the arm slows to rest while the clutch is open"
    );
    // At the end (master gone): at rest.
    let last = sp.last().expect("setpoints");
    assert!(
        last.qd.iter().all(|v| v.abs() < 1e-9),
        "at rest at the end: {:?}",
        last.qd
    );
}
