//! One pipeline-level test per EtherCAT fault: `microrobot run` holding the seed arm
//! with the EtherCAT driver as the actuator, the emulated six-drive chain on the other
//! end of a veth pair in the test thread's own network namespace (`ethercat_rig`), a
//! fault injected through the emulator's control channel. Each checks from the
//! recorded streams that the safe state latches and that every applied-torque step is
//! explained (a flag or a late command within the ramp window, as in `faults.rs`), that
//! the fault's code and axis are in the actuator's status and log, and then either that
//! `microrobot send reset` recovers once the fault has cleared, or (killed driver,
//! wrong identity) that the run ends with a verdict that says why.
//!
//! 250 Hz (bus cycle 4 ms) with the default `stale_ms`, `fault_ms` and
//! `supervisor.hung_ms`: the reset after a bus fault blocks the actuator while the bus
//! comes up again (~0.4 s), which the framework does not count as a stall and announces
//! in its status, so the supervisor gives it its budget (`actuator.hook_budget_ms`). The
//! recoverable faults run free-running on the wall clock, as on hardware, and in
//! lockstep; the killed driver free-running; the wrong identity, refused before the
//! cycle starts, in lockstep. A reset blocking beyond its budget is caught as hung.

use std::collections::HashMap;
use std::time::{Duration, Instant};

use microrobot_messages::{
    JointState, LifecycleHook, LifecycleState, ServiceRole, ServiceStatus, TorqueCommand,
    monotonic_ns, state_flags,
};

use crate::common::*;
use crate::ethercat_rig::{DriveStatus, Rig, RigOptions};
use microrobot_bus_tools::invariants::segments;

/// The driver's own fault codes (`master::codes` of the driver).
const BUS_LOST: u32 = 0x00EC_0001;
const LEFT_OP: u32 = 0x00ED_0000;
const WRONG_IDENTITY: u32 = 0x00EC_0008;
/// What a drive latches when its process data watchdog expires while enabled (0x603F).
const ERROR_COMMUNICATION: u16 = 0x8130;
/// `watchdog.ramp_ms` of these runs, and the blend window in states at 250 Hz.
const RAMP_MS: f64 = 20.0;
const PERIOD_S: f64 = 4e-3;

/// What one fault case produced.
struct Case {
    rig: Rig,
    instance: String,
    config: std::path::PathBuf,
    proc: Proc,
    rec: Recorder,
    /// CLOCK_MONOTONIC just before the fault was injected.
    inject_ns: u64,
}

/// A holding pipeline on the rig, recorded, with `inject` sent to the emulator after
/// the pipeline has held the arm for a moment. `None` without the privileges.
fn start_case(test: &str, opts: RigOptions, lockstep: bool, inject: &[&str]) -> Option<Case> {
    let mut rig = Rig::start(opts)?;
    let instance = instance(test);
    let config = rig.pipeline_config(
        &instance,
        lockstep,
        "",
        // The defaults of stale_ms, fault_ms and supervisor.hung_ms: a reset blocks the
        // actuator's loop while the bus comes up again (~0.4 s here, then the
        // activation); it says so in its status first (`hook`, `hook_budget_ms`).
        &format!("[watchdog]\nramp_ms = {RAMP_MS}\n"),
    );
    let rec = if lockstep {
        Recorder::start_spinning(&instance)
    } else {
        Recorder::start(&instance)
    };
    let proc = start_holding(&instance, &config, 120, None);
    // The arm held under gravity for a moment first: torque is applied.
    std::thread::sleep(Duration::from_millis(300));
    let enabled = rig.drives();
    assert!(
        enabled
            .iter()
            .all(|d| d.state == "Operation enabled" && d.al_state == 8),
        "enabled before the fault: {enabled:#?}"
    );
    let inject_ns = monotonic_ns();
    for line in inject {
        rig.emulator(line);
    }
    Some(Case {
        rig,
        instance,
        config,
        proc,
        rec,
        inject_ns,
    })
}

/// Waits for the actuator's status to carry `code` (and `joint`, 1-based, 0 = none);
/// checks the actuator's log names them too.
fn fault_reported(c: &Case, code: u32, joint: u32) -> ServiceStatus {
    let st = wait_status(
        &c.instance,
        ServiceRole::Actuator,
        &format!("fault code {code:#x}"),
        20.0,
        |s| s.fault_code != 0 && s.stamp_ns > c.inject_ns,
    );
    if st.fault_code != code {
        let log = run(&["logs", "actuator", "--instance", &c.instance], 30.0);
        panic!(
            "fault code {:#x} (joint {}) in the status, not {code:#x}; actuator log:\n{}",
            st.fault_code, st.fault_joint, log.stdout
        );
    }
    assert_eq!(st.fault_joint, joint, "fault axis in the status: {st:?}");
    assert!(st.faults >= 1, "{st:?}");
    let log = run(&["logs", "actuator", "--instance", &c.instance], 30.0);
    let code_text = format!("(code {code:#06x})");
    let line = log
        .stdout
        .lines()
        .find(|l| l.contains("backend fault") && l.contains(&code_text))
        .unwrap_or_else(|| panic!("no log line with {code_text}:\n{}", log.stdout));
    if joint > 0 {
        assert!(line.contains(&format!("joint {joint}:")), "{line}");
    }
    st
}

/// The fault cleared (`clear` sent to the emulator first), `microrobot send reset`:
/// the actuator is Active again with every drive enabled. Returns the reset's stamp.
fn reset_recovers(c: &mut Case, clear: &[&str]) -> u64 {
    for line in clear {
        c.rig.emulator(line);
    }
    let reset_ns = monotonic_ns();
    let r = send(&c.instance, &c.config, &["reset"]);
    assert_eq!(r.code(), Some(0), "reset: {}", r.stderr);
    wait_status(
        &c.instance,
        ServiceRole::Actuator,
        "Active after the reset",
        20.0,
        |s| s.lifecycle == LifecycleState::Active as u32 && s.stamp_ns > reset_ns,
    );
    // Held on the commands again for a moment.
    std::thread::sleep(Duration::from_millis(300));

    let drives = c.rig.drives();
    assert!(
        drives
            .iter()
            .all(|d| d.state == "Operation enabled" && d.al_state == 8 && !d.al_error),
        "enabled again after the reset: {drives:#?}"
    );
    reset_ns
}

/// What a stopped case left.
struct Stopped {
    out: Finished,
    /// The actuator's log just before the stop.
    log: String,
    streams: Streams,
    inject_ns: u64,
    /// CLOCK_MONOTONIC just before the SIGINT that stopped the run.
    stop_ns: u64,
}

/// The run stopped (SIGINT) and its streams.
fn stop(c: Case) -> Stopped {
    let log = run(&["logs", "actuator", "--instance", &c.instance], 30.0).stdout;
    let stop_ns = monotonic_ns();
    c.proc.signal(libc::SIGINT);
    let out = c.proc.finish(60.0);
    Stopped {
        out,
        log,
        streams: c.rec.finish(),
        inject_ns: c.inject_ns,
        stop_ns,
    }
}

/// The safe state latched after the fault (the backend in Fault: drives quick-stopped,
/// torque commands not followed; or the watchdog's safe state) and held until
/// `reset_ns` (if any); after it, the last states before the stop follow the commands
/// again.
fn latched(states: &[JointState], inject_ns: u64, reset_ns: Option<u64>, stop_ns: u64) {
    let flagged = |s: &JointState| {
        s.flags & state_flags::SAFE_STATE != 0 || s.lifecycle == LifecycleState::Fault as u32
    };
    let first = states
        .iter()
        .position(|s| s.header.stamp_ns > inject_ns && flagged(s))
        .expect("the safe state latched after the fault");
    let until = reset_ns.unwrap_or(u64::MAX);
    let unlatched = states[first..]
        .iter()
        .filter(|s| s.header.stamp_ns < until && !flagged(s))
        .count();
    assert_eq!(unlatched, 0, "latched until the reset");
    // A state's stamp is its step's start; the step's bus exchange, which may already
    // see the fault, ends after it (within the period): a state stamped less than a
    // period before the injection may show it.
    let period_ns = (PERIOD_S * 1e9) as u64;
    if let Some(s) = states[..first]
        .iter()
        .find(|s| s.header.stamp_ns + period_ns <= inject_ns && flagged(s))
    {
        panic!(
            "not latched before the fault: state seq {} {:.1} ms before it, lifecycle {}, flags {:#x}",
            s.header.seq,
            (inject_ns - s.header.stamp_ns) as f64 * 1e-6,
            s.lifecycle,
            s.flags
        );
    }
    if reset_ns.is_some() {
        let last = states
            .iter()
            .rev()
            .find(|s| s.header.stamp_ns < stop_ns)
            .expect("states");
        assert!(!flagged(last), "unlatched after the reset: {last:?}");
        assert_eq!(last.lifecycle, LifecycleState::Active as u32);
    }
}

/// Every applied-torque step beyond the healthy bound (twice the largest step while
/// holding before the fault, at least two torque quanta) is explained by the streams:
/// * an event within the ramp window before it (as in `faults.rs`): a flag (safe state,
///   stale commands, slope limit), the backend out of Active (a drive fault takes its
///   torque off at once; the state showing it is in Fault), or a late command (a
///   skipped or repeated `torque_seq`); or
/// * the drive applied what it was commanded: the applied torque (the target torque
///   the driver sent, quantised) is within half a torque quantum of the command this
///   state names. The dynamics bounds its commands' steps (slew limit); here that is
///   the feedback pulling the arm back after a reset.
fn steps_explained(streams: &Streams, inject_ns: u64) {
    let st = &streams.states;
    let dof = 6;
    let running = |s: &JointState| s.lifecycle != LifecycleState::Inactive as u32;
    let calm = |s: &JointState| {
        s.lifecycle == LifecycleState::Active as u32
            && s.flags
                & (state_flags::SAFE_STATE
                    | state_flags::COMMAND_STALE
                    | state_flags::SLOPE_LIMITED)
                == 0
    };
    let ramp = (RAMP_MS * 1e-3 / PERIOD_S).ceil() as usize + 1;
    let mut healthy = vec![0.0f64; dof];
    for seg in segments(st, |s| s.header.seq) {
        // Not the activation (the drives take the load over from their brakes).
        let active = seg
            .iter()
            .position(|s| s.lifecycle == LifecycleState::Active as u32)
            .unwrap_or(seg.len());
        for w in seg.windows(2).skip(active + ramp) {
            if w[1].header.stamp_ns < inject_ns && w.iter().all(calm) {
                for (j, h) in healthy.iter_mut().enumerate() {
                    *h = h.max((w[1].tau_applied[j] - w[0].tau_applied[j]).abs());
                }
            }
        }
    }
    // The drives quantise torque to 1 ‰ of rated: 0.127 N·m (joints 1-3), 0.032 N·m.
    let quantum = [0.127, 0.127, 0.127, 0.032, 0.032, 0.032];
    let bound: Vec<f64> = healthy
        .iter()
        .zip(quantum)
        .map(|(h, q)| 2.0 * h.max(q) + 1e-9)
        .collect();
    let by_seq: HashMap<u64, &TorqueCommand> =
        streams.torques.iter().map(|t| (t.header.seq, t)).collect();
    let (mut beyond, mut after_event, mut followed) = (0, 0, 0);
    let mut unexplained = Vec::new();
    for seg in segments(st, |s| s.header.seq) {
        for i in 2..seg.len() {
            let (a, b) = (&seg[i - 1], &seg[i]);
            if !running(a) || !running(b) {
                continue;
            }
            let event = (i.saturating_sub(ramp)..=i).any(|k| {
                !calm(&seg[k])
                    || (k > 0 && seg[k].torque_seq != seg[k - 1].torque_seq.wrapping_add(1))
            });
            for j in 0..dof {
                if (b.tau_applied[j] - a.tau_applied[j]).abs() <= bound[j] {
                    continue;
                }
                beyond += 1;
                let near = |seq: u64| {
                    by_seq.get(&seq).is_some_and(|t| {
                        (t.tau[j] - b.tau_applied[j]).abs() <= quantum[j] / 2.0 + 1e-6
                    })
                };
                if event {
                    after_event += 1;
                } else if near(b.torque_seq) {
                    followed += 1;
                } else {
                    unexplained.push(format!(
                        "joint {}: {:.4} -> {:.4} N·m at state seq {} (lifecycle {}, flags {:#x}, torque_seq {}; commands {:?} / {:?})",
                        j + 1,
                        a.tau_applied[j],
                        b.tau_applied[j],
                        b.header.seq,
                        b.lifecycle,
                        b.flags,
                        b.torque_seq,
                        by_seq.get(&a.torque_seq).map(|t| t.tau[j]),
                        by_seq.get(&b.torque_seq).map(|t| t.tau[j]),
                    ));
                }
            }
        }
    }
    eprintln!(
        "torque: healthy {healthy:.3?}; steps beyond the bound {beyond}: after an event {after_event}, the drive following its command {followed}, unexplained {}",
        unexplained.len()
    );
    assert!(
        unexplained.is_empty(),
        "unexplained torque steps:\n{}",
        unexplained.join("\n")
    );
}

fn drives_enabled(d: &[DriveStatus]) -> bool {
    d.iter().all(|d| d.state == "Operation enabled")
}

/// How a case's pipeline is clocked.
#[derive(Clone, Copy, PartialEq)]
enum Clock {
    /// Free-running on the wall clock, as on hardware.
    FreeRunning,
    /// Lockstep: one plant step per torque command, one exchange per step.
    Lockstep,
}

/// Runs a recoverable fault case to the end.
fn recoverable(test: &str, clock: Clock, inject: &[&str], code: u32, joint: u32, clear: &[&str]) {
    let t0 = Instant::now();
    let (opts, lockstep) = match clock {
        Clock::FreeRunning => (RigOptions::free_running(4000), false),
        Clock::Lockstep => (RigOptions::lockstep(), true),
    };
    let Some(mut c) = start_case(test, opts, lockstep, inject) else {
        return;
    };
    fault_reported(&c, code, joint);
    let reset_ns = reset_recovers(&mut c, clear);
    let s = stop(c);
    eprintln!(
        "{test}: run exit {:?}, {} states, {:.1} s; verdict:\n{}",
        s.out.code(),
        s.streams.states.len(),
        t0.elapsed().as_secs_f64(),
        s.out.stderr
    );
    assert_eq!(
        s.out.code(),
        Some(0),
        "the run's verdict after the reset:\n{}\nactuator log:\n{}",
        s.out.stderr,
        s.log
    );
    latched(&s.streams.states, s.inject_ns, Some(reset_ns), s.stop_ns);
    steps_explained(&s.streams, s.inject_ns);
}

#[test]
fn ethercat_drive_fault_latches_names_axis_and_code_and_a_reset_recovers() {
    drive_fault(Clock::FreeRunning, "ecat-drive-fault");
}

#[test]
fn ethercat_drive_fault_latches_names_axis_and_code_and_a_reset_recovers_in_lockstep() {
    drive_fault(Clock::Lockstep, "ecat-drive-fault-ls");
}

/// Drive 2 (joint 3) reports overcurrent (0x2310) in 0x603F.
fn drive_fault(clock: Clock, test: &str) {
    recoverable(test, clock, &["drive-fault 2 0x2310"], 0x2310, 3, &[]);
}

#[test]
fn ethercat_drive_leaving_op_latches_names_axis_and_al_code_and_a_reset_recovers() {
    drop_op(Clock::FreeRunning, "ecat-drop-op");
}

#[test]
fn ethercat_drive_leaving_op_latches_names_axis_and_al_code_and_a_reset_recovers_in_lockstep() {
    drop_op(Clock::Lockstep, "ecat-drop-op-ls");
}

/// Drive 4 (joint 5) drops to SAFE-OP with AL status code 0x001B.
fn drop_op(clock: Clock, test: &str) {
    recoverable(test, clock, &["drop-op 4 0x001B"], LEFT_OP | 0x001B, 5, &[]);
}

#[test]
fn ethercat_lost_frames_beyond_max_lost_cycles_latch_and_a_reset_recovers() {
    lost_frames(Clock::FreeRunning, "ecat-lost-frames");
}

#[test]
fn ethercat_lost_frames_beyond_max_lost_cycles_latch_and_a_reset_recovers_in_lockstep() {
    lost_frames(Clock::Lockstep, "ecat-lost-frames-ls");
}

/// 40 exchanges in a row unanswered: more than max_lost_cycles (25); the frames after
/// them are answered again.
fn lost_frames(clock: Clock, test: &str) {
    recoverable(test, clock, &["lose 40"], BUS_LOST, 0, &[]);
}

#[test]
fn ethercat_link_down_latches_and_a_reset_after_link_up_recovers() {
    link_down(Clock::FreeRunning, "ecat-link-down");
}

#[test]
fn ethercat_link_down_latches_and_a_reset_after_link_up_recovers_in_lockstep() {
    link_down(Clock::Lockstep, "ecat-link-down-ls");
}

/// The link goes down; the reset comes after it is up again.
fn link_down(clock: Clock, test: &str) {
    recoverable(test, clock, &["link-down 0"], BUS_LOST, 0, &["link-up"]);
}

/// The driver process killed (-9) while the drives are enabled and loaded: nothing
/// sends process data any more, so each drive's own watchdog (the drive file's
/// `drive_watchdog_ms`, armed in the ESC by the driver) takes the torque off and
/// faults with 0x8130, leaving OP with 0x001B. The pipeline's verdict names the dead
/// actuator.
#[test]
fn ethercat_killed_driver_trips_every_drives_watchdog_and_the_run_fails_naming_it() {
    let t0 = Instant::now();
    let mut opts = RigOptions::free_running(4000);
    // Shorter than the rig's 1 s (the test waits it out), long enough for a start-up
    // gap on a loaded machine.
    opts.drive_watchdog_ms = 500;
    let Some(mut c) = start_case("ecat-kill-driver", opts, false, &[]) else {
        return;
    };
    let before = c.rig.drives();
    assert!(drives_enabled(&before), "{before:#?}");
    assert!(
        before.iter().any(|d| d.torque_nm.abs() > 1.0),
        "holding against gravity: {before:#?}"
    );
    let pid = pid_of(&c.instance, ServiceRole::Actuator).expect("the driver's pid");
    let kill_at = Instant::now();
    // SAFETY: kill(2) on a process this test's pipeline started.
    unsafe { libc::kill(pid, libc::SIGKILL) };
    let mut after = c.rig.drives();
    while !after.iter().all(|d| d.al_error) {
        assert!(
            kill_at.elapsed() < Duration::from_secs(10),
            "the drives' watchdog did not expire: {after:#?}"
        );
        std::thread::sleep(Duration::from_millis(20));
        after = c.rig.drives();
    }
    let tripped = kill_at.elapsed();
    for d in &after {
        assert_eq!(d.state, "Fault", "{}", d.line);
        assert_eq!(d.error_code, ERROR_COMMUNICATION, "{}", d.line);
        assert_eq!((d.al_state, d.al_status_code), (4, 0x001B), "{}", d.line);
        assert_eq!(d.torque_nm, 0.0, "torque off: {}", d.line);
    }
    // Not before the watchdog time (less the cycle between the last frame and the
    // kill): the kill is the only thing that stopped the frames.
    assert!(tripped >= Duration::from_millis(490), "{tripped:?}");
    let Stopped { out, streams, .. } = stop(c);
    eprintln!(
        "killed driver: drives tripped {:.0} ms after the kill; run exit {:?}; {:.1} s",
        tripped.as_secs_f64() * 1e3,
        out.code(),
        t0.elapsed().as_secs_f64()
    );
    assert_eq!(
        out.code(),
        Some(microrobot_runtime::exit_code::SERVICE_FAILED as i32),
        "{}",
        out.stderr
    );
    assert!(
        out.stderr.contains("the actuator service died"),
        "the verdict names the dead driver:\n{}",
        out.stderr
    );
    // Up to the kill, every torque step is explained.
    steps_explained(&streams, u64::MAX);
}

/// A drive with another identity at start: the driver refuses the bus before anything
/// is enabled, and the run fails with a verdict naming the axis and both identities.
#[test]
fn ethercat_wrong_identity_is_refused_before_enabling_and_the_run_fails_naming_it() {
    let t0 = Instant::now();
    let Some(mut rig) = Rig::start(RigOptions::lockstep()) else {
        return;
    };
    rig.emulator("identity 3 0x00000002 0x0BAD0BAD");
    let inst = instance("ecat-identity");
    let cfg = rig.pipeline_config(&inst, true, "", "");
    let out = run(
        &[
            "run",
            "--config",
            cfg.to_str().expect("utf-8"),
            "--no-program",
            "--duration",
            "5",
        ],
        120.0,
    );
    eprintln!(
        "wrong identity: run exit {:?} in {:.1} s",
        out.code(),
        t0.elapsed().as_secs_f64()
    );
    assert_ne!(out.code(), Some(0), "{}", out.stderr);
    let code = format!("(code {WRONG_IDENTITY:#06x})");
    for s in [
        "joint 4:",
        "j4",
        "0x00000002",
        "0x0bad0bad",
        "0x0000009a",
        "0x00030924",
        code.as_str(),
    ] {
        assert!(
            out.stderr.contains(s),
            "`{s}` in the verdict:\n{}",
            out.stderr
        );
    }
    let drives = rig.drives();
    for d in &drives {
        assert_eq!(d.state, "Switch on disabled", "nothing enabled: {}", d.line);
        assert_ne!(d.al_state, 8, "no drive in OP: {}", d.line);
    }
}

/// A reset that blocks inside `on_reset` for longer than its budget: after a link fault
/// every frame of the bus's bring-up is delayed 90 ms (each still answered within the
/// driver's PDU timeout), so bringing the bus up again takes many seconds, and
/// `actuator.hook_budget_ms` is 1 s. The actuator says in its status that it entered
/// `on_reset` with that budget; the supervisor waits the budget out (not
/// `supervisor.hung_ms`, 500 ms), then kills it as hung, and the verdict names the hook
/// and the budget.
#[test]
fn ethercat_a_reset_blocking_beyond_its_budget_is_caught_as_hung_naming_the_hook() {
    let t0 = Instant::now();
    let Some(mut rig) = Rig::start(RigOptions::free_running(4000)) else {
        return;
    };
    let inst = instance("ecat-hook-hung");
    let cfg = rig.pipeline_config(
        &inst,
        false,
        "",
        &format!("hook_budget_ms = 1000\n\n[watchdog]\nramp_ms = {RAMP_MS}\n"),
    );
    let rec = Recorder::start_statuses(&inst);
    let proc = start_holding(&inst, &cfg, 120, None);
    std::thread::sleep(Duration::from_millis(300));
    let inject_ns = monotonic_ns();
    rig.emulator("link-down 0");
    wait_status(&inst, ServiceRole::Actuator, "the bus fault", 20.0, |s| {
        s.fault_code == BUS_LOST && s.stamp_ns > inject_ns
    });
    rig.emulator("link-up");
    rig.emulator("delay 90 100000");
    let reset_at = Instant::now();
    let r = send(&inst, &cfg, &["reset"]);
    assert_eq!(r.code(), Some(0), "reset: {}", r.stderr);
    let out = proc.finish(60.0);
    let ended = reset_at.elapsed();
    let statuses = rec.finish().statuses;
    eprintln!(
        "hook beyond its budget: run exit {:?} {:.2} s after the reset; {:.1} s; verdict:\n{}",
        out.code(),
        ended.as_secs_f64(),
        t0.elapsed().as_secs_f64(),
        out.stderr
    );
    assert_eq!(
        out.code(),
        Some(microrobot_runtime::exit_code::SERVICE_FAILED as i32),
        "{}",
        out.stderr
    );
    for s in [
        "the actuator service hung",
        "inside its on_reset hook",
        "budget of 1000 ms",
    ] {
        assert!(out.stderr.contains(s), "`{s}` in:\n{}", out.stderr);
    }
    // The budget, not hung_ms, was waited for.
    assert!(ended >= Duration::from_millis(1000), "{ended:?}");
    assert!(
        statuses
            .iter()
            .any(|s| s.role == ServiceRole::Actuator as u32
                && s.hook == LifecycleHook::Reset as u32
                && s.hook_budget_ms == 1000),
        "a status announced the hook"
    );
}
