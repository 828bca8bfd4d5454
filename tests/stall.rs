//! A frozen actuator (SIGSTOP mid-move, then SIGCONT) must not lurch when it wakes: the
//! missed plant periods are not replayed under the newest torque, no torque command
//! older than `stale_ms` is applied, and the stall is flagged (`STALLED`; longer than
//! `fault_ms` it also latches the safe state). Checked from the recorded streams of a
//! free-running pipeline: 0.3 s and 2 s stalls, each followed by a reset and a move.
//!
//! The simulated arm is frozen with its process (simulated time only advances in a
//! plant step), so on waking it is where it was, moving as it was; the actuator then
//! holds it with its own law from there. Guards are generous; no wall-clock speed is
//! asserted.

mod common;

use std::time::Duration;

use common::*;
use microrobot_messages::{JointState, LifecycleState, ServiceRole, monotonic_ns, state_flags};

const STALE_MS: u64 = 50;
const FAULT_MS: u64 = 200;
/// The recorded state velocity may exceed a joint's limit by the tracking error's rate.
const VELOCITY_FACTOR: f64 = 1.1;

/// Freezes process `pid` for `ms`; returns the CLOCK_MONOTONIC ns just before SIGCONT.
fn freeze(pid: i32, ms: u64) -> u64 {
    // SAFETY: kill(2) on a child of the pipeline this test started.
    unsafe { libc::kill(pid, libc::SIGSTOP) };
    std::thread::sleep(Duration::from_millis(ms));
    let woke = monotonic_ns();
    // SAFETY: as above.
    unsafe { libc::kill(pid, libc::SIGCONT) };
    woke
}

fn moving(s: &JointState, dof: usize) -> bool {
    (0..dof).any(|j| s.qd[j].abs() > 1e-2)
}

#[test]
fn a_frozen_actuator_wakes_holding_without_a_lurch_and_flags_the_stall() {
    let dir = tempfile::tempdir().expect("tempdir");
    let inst = instance("stall");
    // What is under test is the actuator's own wake-up after the freeze; the supervisor's
    // hung-service detection (which would end this run at 500 ms) is tested in verdicts.rs.
    let cfg = write_config(
        dir.path(),
        &inst,
        "",
        &format!(
            "[watchdog]\nstale_ms = {STALE_MS}.0\nfault_ms = {FAULT_MS}.0\nramp_ms = 20.0\nsafe_state = \"hold\"\nauto_resume = false\n\n\
             [supervisor]\nhung_ms = 60000.0"
        ),
    );
    let summary_path = dir.path().join("summary.json");
    let rec = Recorder::start(&inst);
    let proc = start_holding(&inst, &cfg, 90, Some(&summary_path));
    let actuator = pid_of(&inst, ServiceRole::Actuator).expect("actuator's pid");
    let lim = seed_arm_limits();

    let mut wakes = Vec::new();
    for (stall_ms, target) in [(300, "40,40,40,40,40,40"), (2000, "-20,-20,10,-20,-20,-20")] {
        let mv = send(&inst, &cfg, &["move", "--deg", "--joints", target]);
        assert_eq!(mv.code(), Some(0), "move: {}", mv.stderr);
        // Mid-motion: the time-optimal 40-60° moves of the slow joints take 3 s or more.
        std::thread::sleep(Duration::from_millis(900));
        let stopped = monotonic_ns();
        let woke = freeze(actuator, stall_ms);
        wakes.push((stall_ms, stopped, woke));
        // Let it settle in its hold, then reset and let the planner bring it to rest.
        std::thread::sleep(Duration::from_millis(800));
        let reset = send(&inst, &cfg, &["reset"]);
        assert_eq!(reset.code(), Some(0), "reset: {}", reset.stderr);
        std::thread::sleep(Duration::from_millis(1500));
    }
    proc.signal(libc::SIGINT);
    let out = proc.finish(60.0);
    assert_eq!(out.code(), Some(0), "run; stderr:\n{}", out.stderr);
    let streams = rec.finish();
    let st = &streams.states;
    assert!(st.len() > 3000, "recorded {} states", st.len());

    // 1. No lurch: every recorded velocity within 1.1x the joint's limit.
    let mut worst = vec![0.0f64; lim.dof];
    for s in st {
        for (j, w) in worst.iter_mut().enumerate() {
            *w = w.max(s.qd[j].abs() / lim.vel[j]);
        }
    }
    eprintln!("largest |qd| / velocity limit per joint: {worst:.3?}");
    for (j, w) in worst.iter().enumerate() {
        assert!(
            *w <= VELOCITY_FACTOR,
            "joint {}: |qd| reached {w:.2}x its velocity limit",
            j + 1
        );
    }

    for (stall_ms, stopped, woke) in &wakes {
        // The arm was moving when it froze (else the test checks nothing).
        let before = st
            .iter()
            .rev()
            .find(|s| s.header.stamp_ns < *stopped)
            .expect("a state before the stall");
        assert!(moving(before, lim.dof), "{stall_ms} ms: froze at rest");
        // 2. Flagged: the first state after waking says STALLED, and the stall was
        // longer than fault_ms, so the safe state is latched.
        let first = st
            .iter()
            .find(|s| s.header.stamp_ns > *woke)
            .expect("a state after waking");
        assert_ne!(
            first.flags & state_flags::STALLED,
            0,
            "{stall_ms} ms: first state after waking not flagged STALLED: flags {:#x}",
            first.flags
        );
        assert_ne!(first.flags & state_flags::SAFE_STATE, 0, "{stall_ms} ms");
        assert_eq!(first.lifecycle, LifecycleState::Fault as u32);
        // No burst of catch-up states: nothing recorded as a state of the stall.
        let during = st
            .iter()
            .filter(|s| s.header.stamp_ns > *stopped + 20_000_000 && s.header.stamp_ns < *woke)
            .count();
        assert_eq!(during, 0, "{stall_ms} ms: states stamped during the stall");
    }

    // 3. No torque command older than stale_ms applied: a state that follows commands
    // (no hold flag) answers a command stamped less than stale_ms before it.
    let torque_stamp: std::collections::HashMap<u64, u64> = streams
        .torques
        .iter()
        .map(|t| (t.header.seq, t.header.stamp_ns))
        .collect();
    let mut followed = 0;
    for s in st.iter().filter(|s| {
        s.lifecycle == LifecycleState::Active as u32
            && s.flags
                & (state_flags::COMMAND_STALE
                    | state_flags::SAFE_STATE
                    | state_flags::STALLED
                    | state_flags::FINAL)
                == 0
    }) {
        if let Some(stamp) = torque_stamp.get(&s.torque_seq) {
            followed += 1;
            let age = s.header.stamp_ns.saturating_sub(*stamp);
            assert!(
                age < STALE_MS * 1_000_000,
                "state {} applied torque {} stamped {:.1} ms before",
                s.header.seq,
                s.torque_seq,
                age as f64 * 1e-6
            );
        }
    }
    assert!(followed > 1000, "only {followed} states followed commands");

    let s = summary(&summary_path);
    assert!(
        s["services"]["actuator"]["faults"].as_u64().unwrap_or(0) >= 2,
        "{s}"
    );
}
