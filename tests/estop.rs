//! E-stop mid-motion through the real binaries: every joint comes to rest on the
//! shortest jerk-limited stop (logical time, in ticks), within the limits and without a
//! jump; motion is refused until `reset`; the planner's e-stop latency (command receipt
//! → first braking setpoint) reaches its status, `microrobot top` and the run summary.

mod common;

use std::time::Duration;

use common::continuity::{Limits, setpoint_jumps};
use common::*;
use microrobot_messages::{monotonic_ns, setpoint_flags};
use microrobot_trajectory::{JointState as Start, JointVector, KinematicLimits, stop_trajectory};

const PERIOD_S: f64 = 1e-3;

#[test]
fn estop_mid_motion_stops_every_joint_on_the_shortest_jerk_limited_stop() {
    let dir = tempfile::tempdir().expect("tempdir");
    let inst = instance("estop");
    let cfg = write_config(dir.path(), &inst, "", "");
    let summary_path = dir.path().join("summary.json");
    let rec = Recorder::start(&inst);
    let proc = start_holding(&inst, &cfg, 90, Some(&summary_path));
    let mv = send(
        &inst,
        &cfg,
        &["move", "--deg", "--joints", "50,50,50,50,50,50"],
    );
    assert_eq!(mv.code(), Some(0), "move: {}", mv.stderr);
    std::thread::sleep(Duration::from_millis(1500));
    let estop_ns = monotonic_ns();
    let e = send(&inst, &cfg, &["estop"]);
    assert_eq!(e.code(), Some(0), "estop: {}", e.stderr);
    std::thread::sleep(Duration::from_millis(4000));
    // Motion is refused during the e-stop, with a message that says why.
    let refused = send(&inst, &cfg, &["move", "--deg", "--joints", "0,0,0,0,0,0"]);
    assert_ne!(
        refused.code(),
        Some(0),
        "a move during an e-stop must be refused"
    );
    assert!(
        refused.stderr.contains("e-stop"),
        "the refusal names the e-stop: {}",
        refused.stderr
    );
    // `top` shows the planner's e-stop latency.
    let top = run(&["top", "--instance", &inst, "--once", "--json"], 60.0);
    assert_eq!(top.code(), Some(0), "top: {}", top.stderr);
    let table: serde_json::Value = serde_json::from_str(top.stdout.trim()).expect("top JSON");
    let planner = table["services"]
        .as_array()
        .expect("services")
        .iter()
        .find(|r| r["service"] == "planner")
        .expect("planner row")
        .clone();
    assert_eq!(planner["estops"], 1, "{planner}");
    assert!(
        planner["estop_latency_us"]
            .as_f64()
            .is_some_and(|v| v > 0.0),
        "{planner}"
    );
    let reset = send(&inst, &cfg, &["reset"]);
    assert_eq!(reset.code(), Some(0), "reset: {}", reset.stderr);
    let again = send(&inst, &cfg, &["move", "--deg", "--joints", "0,0,0,0,0,0"]);
    assert_eq!(again.code(), Some(0), "move after reset: {}", again.stderr);
    std::thread::sleep(Duration::from_millis(500));
    proc.signal(libc::SIGINT);
    let out = proc.finish(60.0);
    assert_eq!(out.code(), Some(0), "{}", out.stderr);
    let streams = rec.finish();
    let sp = &streams.setpoints;

    let lim = Limits::seed_arm();
    let rep = setpoint_jumps(sp, &streams.states, &lim, PERIOD_S);
    assert!(
        rep.jumps.is_empty(),
        "setpoint jumps:\n{}",
        rep.jumps.join("\n")
    );
    assert!(rep.beyond_position_limits < 1e-6);

    // The braking run: from the first ESTOP setpoint to the first one at rest.
    let first = sp
        .iter()
        .position(|s| s.flags & setpoint_flags::ESTOP != 0)
        .expect("e-stop setpoints");
    assert!(first > 0 && sp[first].header.stamp_ns > estop_ns);
    let before = &sp[first - 1];
    let rest = sp[first..]
        .iter()
        .position(|s| s.flags & setpoint_flags::STOPPING == 0)
        .map(|i| first + i)
        .expect("the e-stop came to rest");
    let at_rest = &sp[rest];
    for j in 0..lim.dof {
        assert!(
            at_rest.qd[j] == 0.0 && at_rest.qdd[j] == 0.0,
            "joint {} at rest: qd {} qdd {}",
            j + 1,
            at_rest.qd[j],
            at_rest.qdd[j]
        );
    }
    // It was moving when the e-stop came.
    let vmax = (0..lim.dof).map(|j| before.qd[j].abs()).fold(0.0, f64::max);
    assert!(vmax > 0.1, "moving at the e-stop: {vmax} rad/s");
    let braking_s = (at_rest.header.tick - before.header.tick) as f64 * PERIOD_S;
    // The shortest jerk-limited stop from the state the e-stop found (estop_limit_scale = 1).
    let mut kl = KinematicLimits::uniform(1.0, 1.0, 1.0, 0.0, 0.0);
    let mut start = Start {
        q: JointVector::zeros(),
        qd: JointVector::zeros(),
        qdd: JointVector::zeros(),
    };
    let mut lower = 0.0f64;
    for j in 0..lim.dof {
        kl.velocity[j] = lim.vel[j];
        kl.acceleration[j] = lim.acc[j];
        kl.jerk[j] = lim.jerk[j];
        kl.position_min[j] = lim.min[j];
        kl.position_max[j] = lim.max[j];
        start.q[j] = before.q[j];
        start.qd[j] = before.qd[j];
        start.qdd[j] = before.qdd[j];
        // No stop within the acceleration limit is shorter than |v| / a_max.
        lower = lower.max(before.qd[j].abs() / lim.acc[j]);
    }
    let shortest = stop_trajectory(lim.dof, &start, &kl)
        .expect("stop plan")
        .duration();
    eprintln!(
        "e-stop from {vmax:.3} rad/s: at rest after {braking_s:.3} s (shortest jerk-limited stop {shortest:.3} s, bound |v|/a_max {lower:.3} s)"
    );
    assert!(
        braking_s <= shortest + 2.0 * PERIOD_S,
        "at rest after {braking_s} s, the shortest stop takes {shortest} s"
    );
    assert!(braking_s >= lower - 2.0 * PERIOD_S, "{braking_s} < {lower}");

    let s = summary(&summary_path);
    assert_eq!(s["estops"], 1, "{s}");
    let lat = s["estop_latency_us"]
        .as_f64()
        .expect("e-stop latency in the summary");
    assert!(
        lat > 0.0 && s["estop_latency_max_us"].as_f64() >= Some(lat),
        "{s}"
    );
    eprintln!("e-stop latency (command receipt → first braking setpoint): {lat:.1} µs");
}
