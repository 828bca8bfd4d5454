//! Kill each service in turn mid-motion (`kill -9`, real binaries, `on_failure =
//! "restart"`) and check from the recorded streams: the others notice (stale and safe
//! state flags, no earlier than `stale_ms` / `fault_ms` after the last input), the
//! actuator holds without a torque step, the supervisor restarts the service, and after
//! `microrobot send reset` the motion resumes bumplessly from the measured state.
//!
//! Stamps are all CLOCK_MONOTONIC (the test's and the services'), so "after the last
//! torque" is a comparison of stamps, not a timing claim. Guards are generous.

use std::time::Duration;

use crate::common::*;
use microrobot_bus_tools::invariants::{
    segments, setpoint_jumps, state_at, torque_peak, torque_slew, torque_step_bound, torque_steps,
};
use microrobot_messages::{
    LifecycleState, ServiceRole, monotonic_ns, setpoint_flags, state_flags, torque_flags,
};

const STALE_MS: f64 = 50.0;
const FAULT_MS: f64 = 200.0;
const RAMP_MS: f64 = 20.0;
/// The default of `actuator.torque_slope_ms` (full effort in this long): the largest
/// applied-torque change per plant step that either torque limit lets through (the
/// dynamics' slew limit, `torque_slew_ms` = 20 ms, is half of it per tick).
const TORQUE_SLOPE_MS: f64 = 10.0;
const PERIOD_S: f64 = 1e-3;
/// How long the victim is silent before it dies: longer than `fault_ms`, and than the
/// planner's stop from the move's speed (about 1.1 s).
const DEAD_MS: u64 = 1500;
/// Slack for a stamp comparison that involves one delivery (e.g. "every state published
/// later than the last torque + stale_ms is flagged"): a generous guard for host stalls.
const DELIVERY_GUARD_NS: u64 = 150_000_000;

/// Everything one kill case produced.
struct Case {
    streams: Streams,
    summary: serde_json::Value,
    stderr: String,
    /// CLOCK_MONOTONIC just before the kill.
    kill_ns: u64,
    /// CLOCK_MONOTONIC just before `send reset`.
    reset_ns: u64,
}

fn kill_mid_motion(test: &str, victim: ServiceRole) -> Case {
    let dir = tempfile::tempdir().expect("tempdir");
    let inst = instance(test);
    let cfg = write_config(
        dir.path(),
        &inst,
        "",
        &format!(
            "[watchdog]\nstale_ms = {STALE_MS}\nfault_ms = {FAULT_MS}\nramp_ms = {RAMP_MS}\nsafe_state = \"hold\"\n\n[supervisor]\non_failure = \"restart\"\nmax_restarts = 2"
        ),
    );
    let summary_path = dir.path().join("summary.json");
    let rec = Recorder::start(&inst);
    let proc = start_holding(&inst, &cfg, 90, Some(&summary_path));
    let mv = send(
        &inst,
        &cfg,
        &["move", "--deg", "--joints", "40,40,40,40,40,40"],
    );
    assert_eq!(mv.code(), Some(0), "first move: {}", mv.stderr);
    // Mid-motion: the time-optimal 40° move of the slow joints takes about 3 s.
    std::thread::sleep(Duration::from_millis(900));
    let old = pid_of(&inst, victim).expect("victim's pid");
    let kill_ns = monotonic_ns();
    // The victim hangs first (SIGSTOP), then dies (SIGKILL): its output stops at a known
    // time and stays away longer than `fault_ms` (and than the planner's stop) however
    // fast the supervisor restarts it.
    // SAFETY: kill(2) on a process of this test.
    unsafe { libc::kill(old, libc::SIGSTOP) };
    std::thread::sleep(Duration::from_millis(DEAD_MS));
    // SAFETY: as above.
    unsafe { libc::kill(old, libc::SIGKILL) };
    let new = wait_restarted(&inst, victim, old, 60.0);
    assert!(!alive(old), "the killed process is gone");
    assert_ne!(new, old);
    // Let the actuator's safe state latch and the planner follow it.
    std::thread::sleep(Duration::from_millis(600));
    let reset_ns = monotonic_ns();
    let reset = send(&inst, &cfg, &["reset"]);
    assert_eq!(reset.code(), Some(0), "reset: {}", reset.stderr);
    std::thread::sleep(Duration::from_millis(400));
    // Motion is accepted again and runs to its end.
    let back = send(
        &inst,
        &cfg,
        &["move", "--deg", "--joints", "10,10,10,10,10,10"],
    );
    assert_eq!(back.code(), Some(0), "move after reset: {}", back.stderr);
    std::thread::sleep(Duration::from_millis(6000));
    proc.signal(libc::SIGINT);
    let out = proc.finish(60.0);
    // The pipeline recovered and ran on, but a service died: the run's verdict says so.
    assert_eq!(
        out.code(),
        Some(microrobot_runtime::exit_code::SERVICE_FAILED as i32),
        "run; stderr:\n{}",
        out.stderr
    );
    // Frozen for DEAD_MS before its kill: the supervisor finds it hung (`hung_ms`) and
    // kills it first, unless the kill comes sooner; either way the verdict names it.
    let (died, hung) = (
        format!("the {} service died", victim.name()),
        format!("the {} service hung", victim.name()),
    );
    assert!(
        out.stderr.contains(&died) || out.stderr.contains(&hung),
        "the verdict names the death; stderr:\n{}",
        out.stderr
    );
    Case {
        streams: rec.finish(),
        summary: summary(&summary_path),
        stderr: out.stderr,
        kill_ns,
        reset_ns,
    }
}

/// The checks every kill case shares: restart counted, no setpoint jump (re-syncs to the
/// measured state allowed), no torque step, resumed from the measured state, the resumed
/// motion completed and tracked.
fn common_checks(c: &Case, victim: ServiceRole) {
    let lim = seed_arm_limits();
    let s = &c.summary;
    assert_eq!(s["services"][victim.name()]["restarts"], 1, "{s}");
    assert!(
        c.stderr.contains("restarting"),
        "the supervisor says it restarts: {}",
        c.stderr
    );

    let sp = &c.streams.setpoints;
    let st = &c.streams.states;
    assert!(
        sp.len() > 3000 && st.len() > 3000,
        "recorded {} setpoints, {} states",
        sp.len(),
        st.len()
    );
    let rep = setpoint_jumps(sp, st, &lim, PERIOD_S);
    assert!(
        rep.jumps.is_empty(),
        "setpoint jumps:\n{}",
        rep.jumps.join("\n")
    );
    assert!(
        rep.beyond_position_limits < 1e-6,
        "{}",
        rep.beyond_position_limits
    );

    // Torque: the slew of healthy motion before the kill, and the bound a blended switch
    // stays within; an unblended switch would step by up to 2·peak at once.
    let healthy = torque_slew(st, lim.dof, |x| {
        x.header.stamp_ns < c.kill_ns
            && x.flags & (state_flags::COMMAND_STALE | state_flags::SAFE_STATE) == 0
    });
    let peak = torque_peak(st, lim.dof);
    let bound = torque_step_bound(&healthy, &peak, RAMP_MS * 1e-3 / PERIOD_S);
    // The backend's activation (Inactive → Active: the drive takes the load over from
    // its brake) is the one unblended change; it is reported, not bounded.
    let running =
        |x: &microrobot_messages::JointState| x.lifecycle != LifecycleState::Inactive as u32;
    let slew = torque_slew(st, lim.dof, running);
    let activation = torque_slew(st, lim.dof, |_| true);
    eprintln!(
        "{}: torque change at activation (whole run, incl. Inactive → Active) {activation:.3?}",
        victim.name()
    );
    eprintln!(
        "{}: torque slew healthy {healthy:.3?}, whole run {slew:.3?}, bound {bound:.3?}, peak {peak:.3?}",
        victim.name()
    );
    // Beyond the bound only within the limits and after an event the streams show (a
    // host stall lets the free-running arm drift under a held torque; feedback then
    // corrects a real error: CI saw 2.5 N·m per step on joints 1 and 2, the slew limit,
    // and once 1.25 N·m in one step 1.8 s after a restart, with no flag).
    let cap = lim.torque_step_cap(PERIOD_S, TORQUE_SLOPE_MS);
    let ramp_steps = (RAMP_MS * 1e-3 / PERIOD_S).round() as usize;
    let steps = torque_steps(st, &c.streams.torques, &bound, &cap, ramp_steps, running);
    eprintln!(
        "{}: applied-torque steps beyond the bound {} (after a flag {}, after a late command {})",
        victim.name(),
        steps.beyond_bound,
        steps.after_flag,
        steps.after_late_command
    );
    assert!(
        steps.violations.is_empty(),
        "torque steps (healthy {healthy:?}, peak {peak:?}):\n{}",
        steps.violations.join("\n")
    );

    // Resumed from the measured state: the first moving setpoint after the reset starts
    // where the arm is.
    let first = sp
        .iter()
        .find(|x| {
            x.header.stamp_ns > c.reset_ns && x.flags & setpoint_flags::HOLD_FOR_SAFE_STATE == 0
        })
        .expect("setpoints after the reset");
    let at = state_at(st, first.header.stamp_ns).expect("a state before it");
    for j in 0..lim.dof {
        assert!(
            (first.q[j] - at.q[j]).abs() < 5e-3,
            "joint {}: resumed at setpoint {} while the arm is at {}",
            j + 1,
            first.q[j],
            at.q[j]
        );
    }
    // The move after the reset ran to its end, and the arm followed.
    let last = sp.last().expect("setpoints");
    let last_state = st.last().expect("states");
    for j in 0..lim.dof {
        let target = 10f64.to_radians();
        assert!(
            (last.q[j] - target).abs() < 1e-6 && last.qd[j].abs() < 1e-9,
            "joint {} ends at rest at 10°: q {} qd {}",
            j + 1,
            last.q[j],
            last.qd[j]
        );
        assert!(
            (last_state.q[j] - target).abs() < 2e-3,
            "joint {}: the arm is at {} at the end",
            j + 1,
            last_state.q[j]
        );
    }
    assert!(
        last_state.flags & state_flags::SAFE_STATE == 0,
        "the safe state was left"
    );
}

/// Torque commands stopped at the kill (planner or dynamics died): the actuator flags
/// stale commands no earlier than `stale_ms` after the last torque and latches its safe
/// state no earlier than `fault_ms`; every state later than that (+ a delivery guard)
/// up to the reset carries the flag.
fn actuator_noticed_missing_torque(c: &Case) {
    let tq = &c.streams.torques;
    let st = &c.streams.states;
    let last_torque = tq
        .iter()
        .filter(|t| t.header.stamp_ns <= c.kill_ns + 5_000_000)
        .map(|t| t.header.stamp_ns)
        .max()
        .expect("torques before the kill");
    let stale_ns = (STALE_MS * 1e6) as u64;
    let fault_ns = (FAULT_MS * 1e6) as u64;
    let flagged = |s: &microrobot_messages::JointState, bits: u32| s.flags & bits != 0;
    let window: Vec<_> = st
        .iter()
        .filter(|s| s.header.stamp_ns > last_torque && s.header.stamp_ns < c.reset_ns)
        .collect();
    let first_stale = window
        .iter()
        .find(|s| flagged(s, state_flags::COMMAND_STALE | state_flags::SAFE_STATE))
        .expect("the actuator flagged the stale commands");
    let first_safe = window
        .iter()
        .find(|s| flagged(s, state_flags::SAFE_STATE))
        .expect("the actuator latched its safe state");
    let d_stale = first_stale.header.stamp_ns - last_torque;
    let d_safe = first_safe.header.stamp_ns - last_torque;
    eprintln!(
        "actuator: stale flagged {:.1} ms, safe state {:.1} ms after the last torque",
        d_stale as f64 / 1e6,
        d_safe as f64 / 1e6
    );
    assert!(d_stale >= stale_ns, "flagged stale early: {d_stale} ns");
    assert!(d_safe >= fault_ns, "latched early: {d_safe} ns");
    for s in &window {
        let age = s.header.stamp_ns - last_torque;
        if age > stale_ns + DELIVERY_GUARD_NS {
            assert!(
                flagged(s, state_flags::COMMAND_STALE | state_flags::SAFE_STATE),
                "state {} ms after the last torque is not flagged stale",
                age / 1_000_000
            );
        }
        if age > fault_ns + DELIVERY_GUARD_NS {
            assert!(
                flagged(s, state_flags::SAFE_STATE),
                "state {} ms after the last torque: safe state not latched",
                age / 1_000_000
            );
        }
    }
    // Latched until the reset, not by itself: the restarted service's torques alone do
    // not unlatch it (auto_resume = false).
    let before_reset = st
        .iter()
        .rev()
        .find(|s| s.header.stamp_ns < c.reset_ns)
        .expect("states before the reset");
    assert!(
        flagged(before_reset, state_flags::SAFE_STATE),
        "still latched at the reset"
    );
    let act = c
        .streams
        .statuses
        .iter()
        .filter(|s| s.role == ServiceRole::Actuator as u32)
        .map(|s| (s.faults, s.stale_cycles))
        .max()
        .expect("actuator statuses");
    assert!(
        act.0 >= 1 && act.1 > 0,
        "actuator faults / stale cycles counted: {act:?}"
    );
    // The planner followed the measured state while the actuator held.
    assert!(
        c.streams
            .setpoints
            .iter()
            .any(|s| s.flags & setpoint_flags::HOLD_FOR_SAFE_STATE != 0),
        "the planner followed the safe state"
    );
}

#[test]
fn killed_planner_is_noticed_held_restarted_and_resumed_bumplessly() {
    let c = kill_mid_motion("kill-planner", ServiceRole::Planner);
    common_checks(&c, ServiceRole::Planner);
    actuator_noticed_missing_torque(&c);
    // The dynamics counted its missing input.
    let dyn_stale = c
        .streams
        .statuses
        .iter()
        .filter(|s| s.role == ServiceRole::Dynamics as u32)
        .map(|s| s.stale_cycles)
        .max()
        .unwrap_or(0);
    assert!(dyn_stale > 0, "dynamics counted stale input periods");
    // A second planner process published.
    assert!(segments(&c.streams.setpoints, |s| s.header.seq).len() >= 2);
}

#[test]
fn killed_dynamics_is_noticed_held_restarted_and_resumed_bumplessly() {
    let c = kill_mid_motion("kill-dynamics", ServiceRole::Dynamics);
    common_checks(&c, ServiceRole::Dynamics);
    actuator_noticed_missing_torque(&c);
    assert!(segments(&c.streams.torques, |s| s.header.seq).len() >= 2);
}

/// The actuator died: the planner sees its measured state go stale and brakes; the
/// dynamics goes feed-forward (flag STATE_STALE). The restarted actuator resumes the arm
/// where the planner's last setpoint is (what exists; branch `soak` moves this to the
/// dead actuator's last published state), and the motion resumes after the reset.
#[test]
fn killed_actuator_is_noticed_restarted_and_resumed_bumplessly() {
    let c = kill_mid_motion("kill-actuator", ServiceRole::Actuator);
    common_checks(&c, ServiceRole::Actuator);
    let st = &c.streams.states;
    let last_state = st
        .iter()
        .filter(|s| s.header.stamp_ns <= c.kill_ns + 5_000_000)
        .map(|s| s.header.stamp_ns)
        .max()
        .expect("states before the kill");
    let stale_ns = (STALE_MS * 1e6) as u64;
    let ff = c
        .streams
        .torques
        .iter()
        .find(|t| t.header.stamp_ns > last_state && t.flags & torque_flags::STATE_STALE != 0)
        .expect("the dynamics went feed-forward on the stale state");
    let braking = c
        .streams
        .setpoints
        .iter()
        .find(|s| s.header.stamp_ns > last_state && s.flags & setpoint_flags::STOPPING != 0)
        .expect("the planner braked on the stale state");
    eprintln!(
        "actuator killed: dynamics feed-forward {:.1} ms, planner braking {:.1} ms after the last state",
        (ff.header.stamp_ns - last_state) as f64 / 1e6,
        (braking.header.stamp_ns - last_state) as f64 / 1e6
    );
    assert!(ff.header.stamp_ns - last_state >= stale_ns);
    assert!(braking.header.stamp_ns - last_state >= stale_ns);
    let planner_stale = c
        .streams
        .statuses
        .iter()
        .filter(|s| s.role == ServiceRole::Planner as u32)
        .map(|s| s.stale_cycles)
        .max()
        .unwrap_or(0);
    assert!(planner_stale > 0, "planner counted stale state cycles");
    assert!(
        segments(st, |s| s.header.seq).len() >= 2,
        "a second actuator published"
    );
}

/// The supervisor itself is killed (-9) mid-motion: every service gets SIGTERM from the
/// kernel (PR_SET_PDEATHSIG), stops cleanly (a final status each) and the actuator goes
/// safe on the way out (backend inactive: drives disabled, brakes on — its last state
/// says so). The next start cleans what is left and leaves nothing behind.
#[test]
fn a_killed_supervisor_stops_every_service_and_the_actuator_goes_safe() {
    let dir = tempfile::tempdir().expect("tempdir");
    let inst = instance("kill-supervisor");
    let cfg = write_config(dir.path(), &inst, "", "");
    let rec = Recorder::start(&inst);
    let proc = start_holding(&inst, &cfg, 120, None);
    let mv = send(
        &inst,
        &cfg,
        &["move", "--deg", "--joints", "40,40,40,40,40,40"],
    );
    assert_eq!(mv.code(), Some(0), "move: {}", mv.stderr);
    std::thread::sleep(Duration::from_millis(800));
    let roles = [
        ServiceRole::Planner,
        ServiceRole::Dynamics,
        ServiceRole::Actuator,
    ];
    let pids: Vec<i32> = roles
        .iter()
        .map(|r| pid_of(&inst, *r).expect("pid"))
        .collect();
    proc.signal(libc::SIGKILL);
    let _ = proc.finish(30.0);
    let t0 = std::time::Instant::now();
    while pids.iter().any(|p| alive(*p)) {
        assert!(
            t0.elapsed() < Duration::from_secs(30),
            "services still alive after the supervisor died: {pids:?}"
        );
        std::thread::sleep(Duration::from_millis(50));
    }
    let streams = rec.finish();
    for (role, pid) in roles.iter().zip(&pids) {
        assert!(
            streams
                .statuses
                .iter()
                .any(|s| s.pid == *pid as u32 && s.lifecycle == LifecycleState::Finalized as u32),
            "{} stopped cleanly (a final status)",
            role.name()
        );
    }
    let last = streams.states.last().expect("states");
    assert_eq!(
        last.lifecycle,
        LifecycleState::Inactive as u32,
        "the actuator's last state: backend inactive (brakes on)"
    );
    assert!(
        last.qd[..6].iter().all(|v| *v == 0.0),
        "at rest: {:?}",
        last.qd
    );

    let summary_path = dir.path().join("summary.json");
    let out = run(
        &[
            "run",
            "--config",
            cfg.to_str().expect("utf-8"),
            "--no-program",
            "--duration",
            "2",
            "--summary-json",
            summary_path.to_str().expect("utf-8"),
        ],
        90.0,
    );
    assert_eq!(out.code(), Some(0), "second run; stderr:\n{}", out.stderr);
    assert_eq!(summary(&summary_path)["exit_ok"], true);
    assert_eq!(remaining_services(&inst), Vec::<String>::new());
    assert_eq!(remaining_nodes(&inst), Vec::<String>::new());
}
