//! E-stop mid-motion through the real binaries: every joint comes to rest on the
//! shortest jerk-limited stop (logical time, in ticks), within the limits and without a
//! jump; motion is refused until `reset`; the planner's e-stop latency (command receipt
//! → first braking setpoint) reaches its status, `microrobot top` and the run summary.
//! A reset during the brake, alone or in a flood of random commands, never steps the
//! setpoint stream.

use std::time::Duration;

use crate::common::*;
use microrobot_bus_tools::invariants::setpoint_jumps;
use microrobot_messages::{CommandKind, LifecycleState, ServiceRole, monotonic_ns, setpoint_flags};
use microrobot_trajectory::{JointVector, KinematicLimits, MotionState as Start, stop_trajectory};

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

    let lim = seed_arm_limits();
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

/// The last setpoint the planner published before a command sent at `t_ns` could reach it.
fn last_before(
    sp: &[microrobot_messages::JointSetpoint],
    t_ns: u64,
) -> Option<&microrobot_messages::JointSetpoint> {
    sp.iter().take_while(|s| s.header.stamp_ns < t_ns).last()
}

fn braking(s: &microrobot_messages::JointSetpoint) -> bool {
    s.flags & setpoint_flags::ESTOP != 0
        && s.flags & setpoint_flags::STOPPING != 0
        && s.qd.iter().any(|v| v.abs() > 1e-3)
}

/// A reset 0.3 s into an e-stop that brakes a fast move: the brake runs on to rest (no
/// velocity or acceleration step, bounds from the limits and the period), then the
/// e-stop lifts and a move is accepted.
#[test]
fn a_reset_during_the_estop_brake_does_not_step_the_setpoint() {
    let dir = tempfile::tempdir().expect("tempdir");
    let inst = instance("estop-reset");
    let cfg = write_config(dir.path(), &inst, "", "");
    let rec = Recorder::start(&inst);
    let proc = start_holding(&inst, &cfg, 120, None);
    let mut cmds = CommandSender::open(&inst);
    cmds.send(joint_move(&[50f64.to_radians(); 6]));
    std::thread::sleep(Duration::from_millis(1500));
    cmds.send(command(CommandKind::EStop));
    std::thread::sleep(Duration::from_millis(300));
    let reset_ns = monotonic_ns();
    cmds.send(command(CommandKind::Reset));
    // The planner leaves its e-stop (lifecycle Fault) once the brake is at rest.
    let st = wait_status(
        &inst,
        ServiceRole::Planner,
        "the e-stop lifted",
        60.0,
        |s| s.commands_accepted >= 3 && s.lifecycle == LifecycleState::Active as u32,
    );
    assert_eq!(st.commands_refused, 0, "{st:?}");
    let again = send(&inst, &cfg, &["move", "--deg", "--joints", "0,0,0,0,0,0"]);
    assert_eq!(
        again.code(),
        Some(0),
        "move after the brake: {}",
        again.stderr
    );
    std::thread::sleep(Duration::from_millis(300));
    proc.signal(libc::SIGINT);
    let out = proc.finish(60.0);
    assert_eq!(out.code(), Some(0), "{}", out.stderr);
    let streams = rec.finish();
    let sp = &streams.setpoints;

    let before = last_before(sp, reset_ns).expect("setpoints before the reset");
    assert!(
        braking(before),
        "the reset must arrive while the e-stop brakes (flags {:#x}, qd {:?})",
        before.flags,
        before.qd
    );
    let rep = setpoint_jumps(sp, &streams.states, &seed_arm_limits(), PERIOD_S);
    assert!(
        rep.jumps.is_empty(),
        "setpoint jumps:\n{}",
        rep.jumps.join("\n")
    );
}

/// A flood of random commands (moves, stops, e-stops, resets, 0–80 ms apart, from a
/// fixed seed) into a running pipeline: the setpoint stream stays continuous in q, q̇
/// and q̈ throughout, and resets did arrive while e-stops braked.
#[test]
fn a_flood_of_random_commands_keeps_the_setpoints_continuous() {
    let dir = tempfile::tempdir().expect("tempdir");
    let inst = instance("estop-flood");
    let cfg = write_config(dir.path(), &inst, "", "");
    let lim = seed_arm_limits();
    let rec = Recorder::start(&inst);
    let proc = start_holding(&inst, &cfg, 120, None);
    let mut cmds = CommandSender::open(&inst);
    // xorshift64*: reproducible without a dependency.
    let mut x = 0x2545_F491_4F6C_DD1Du64;
    let mut next = move || {
        x ^= x >> 12;
        x ^= x << 25;
        x ^= x >> 27;
        x.wrapping_mul(0x2545_F491_4F6C_DD1D)
    };
    let mut resets_ns = Vec::new();
    for _ in 0..200 {
        let c = match next() % 8 {
            0..=2 => {
                let q: Vec<f64> = (0..lim.dof)
                    .map(|j| {
                        let u = (next() >> 11) as f64 / (1u64 << 53) as f64;
                        let margin = 0.1 * (lim.max[j] - lim.min[j]);
                        lim.min[j] + margin + u * (lim.max[j] - lim.min[j] - 2.0 * margin)
                    })
                    .collect();
                joint_move(&q)
            }
            3 => command(CommandKind::Stop),
            4 | 5 => command(CommandKind::EStop),
            _ => {
                resets_ns.push(monotonic_ns());
                command(CommandKind::Reset)
            }
        };
        cmds.send(c);
        std::thread::sleep(Duration::from_millis(next() % 80));
    }
    cmds.send(command(CommandKind::EStop));
    std::thread::sleep(Duration::from_millis(200));
    proc.signal(libc::SIGINT);
    let out = proc.finish(60.0);
    assert_eq!(out.code(), Some(0), "{}", out.stderr);
    let streams = rec.finish();
    let sp = &streams.setpoints;
    let planner = streams
        .statuses
        .iter()
        .rev()
        .find(|s| s.role == ServiceRole::Planner as u32)
        .expect("planner status");
    assert_eq!(
        planner.commands_accepted + planner.commands_refused,
        201,
        "every command reached the planner: {planner:?}"
    );
    let resets_while_braking = resets_ns
        .iter()
        .filter(|t| last_before(sp, **t).is_some_and(braking))
        .count();
    eprintln!(
        "{} commands accepted, {} refused; {resets_while_braking} of {} resets sent while an e-stop braked",
        planner.commands_accepted,
        planner.commands_refused,
        resets_ns.len()
    );
    assert!(
        resets_while_braking >= 3,
        "only {resets_while_braking} resets arrived while braking"
    );
    let rep = setpoint_jumps(sp, &streams.states, &lim, PERIOD_S);
    assert!(
        rep.jumps.is_empty(),
        "setpoint jumps:\n{}",
        rep.jumps.join("\n")
    );
}
