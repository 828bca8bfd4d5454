//! Silence alone does not hand the torque stream over: while the pipeline's dynamics is
//! frozen (SIGSTOP 0.8 s), a hostile process on the same machine publishes well-formed,
//! fresh torque commands on the instance's torque stream. They are refused as an
//! outsider's (the hostile process is not one the supervisor started), never applied,
//! and latch the safe state; once the dynamics wakes, its own stream is taken again (no
//! lock-out), a reset resumes the arm, and the run ends cleanly. The same for the other
//! cyclic streams: setpoints injected while the planner is frozen are refused by the
//! dynamics (no torque is computed from them), and states injected while the actuator is
//! frozen are refused by the planner and the dynamics.

use std::time::Duration;

use crate::common::*;
use iceoryx2::prelude::ZeroCopySend;
use microrobot_messages::{
    CommandKind, Header, JointSetpoint, JointState, LifecycleState, RefusalReason, ServiceKind,
    ServiceRole, TorqueCommand, monotonic_ns, open_event, open_publish_subscribe,
};

/// Marks the hostile commands, so their (absent) effect can be looked for.
const MARK: u64 = 1 << 41;

#[test]
fn a_hostile_torque_stream_during_a_dynamics_stall_is_refused_and_latches_the_safe_state() {
    let dir = tempfile::tempdir().expect("tempdir");
    let inst = instance("takeover");
    // The frozen dynamics is what the test needs: the supervisor's hung detection off.
    let cfg = write_config(dir.path(), &inst, "", "[supervisor]\nhung_ms = 60000.0");
    let rec = Recorder::start(&inst);
    let proc = start_holding(&inst, &cfg, 90, None);
    let dynamics = pid_of(&inst, ServiceRole::Dynamics).expect("dynamics pid");

    // The hostile publisher: this (unsupervised) test process.
    let (injected_from, injected_to) =
        inject_while_frozen(&inst, ServiceKind::Torque, dynamics, 500, |k, now| {
            let mut tau = [0.0; 8];
            tau[0] = 30.0; // would drive joint 1 into its limit within a fraction of a second
            TorqueCommand {
                header: Header {
                    seq: k + 1,
                    tick: MARK + k,
                    stamp_ns: now,
                    source_stamp_ns: now,
                },
                tau,
                setpoint_seq: MARK + k,
                state_seq: u64::MAX,
                dof: 6,
                ..Default::default()
            }
        });

    let refused = wait_status(
        &inst,
        ServiceRole::Actuator,
        "the outsider refused",
        30.0,
        |s| s.lifecycle == LifecycleState::Fault as u32,
    );
    assert_eq!(
        RefusalReason::from_wire(refused.last_input_refusal),
        Some(RefusalReason::Outsider),
        "{refused:?}"
    );
    assert!(
        refused.refused_messages >= 400,
        "{} refused",
        refused.refused_messages
    );
    // The dynamics' own stream is taken again, and a reset resumes the arm.
    std::thread::sleep(Duration::from_millis(300));
    let mut commands = CommandSender::open(&inst);
    commands.send(command(CommandKind::Reset));
    let active = wait_status(
        &inst,
        ServiceRole::Actuator,
        "active after the reset",
        30.0,
        |s| s.lifecycle == LifecycleState::Active as u32,
    );
    std::thread::sleep(Duration::from_millis(500));
    let later = wait_status(&inst, ServiceRole::Actuator, "a later status", 30.0, |_| {
        true
    });
    assert_eq!(
        later.refused_messages, active.refused_messages,
        "the pipeline's own dynamics was refused after it woke"
    );

    proc.signal(libc::SIGINT);
    let out = proc.finish(60.0);
    assert_eq!(out.code(), Some(0), "{}", out.stderr);
    let streams = rec.finish();
    // Never applied: no state answers a hostile command, and the arm held still.
    assert!(
        streams.states.iter().all(|s| s.header.tick < MARK),
        "a state applied a hostile torque"
    );
    let during: Vec<_> = streams
        .states
        .iter()
        .filter(|s| s.header.stamp_ns >= injected_from && s.header.stamp_ns <= injected_to)
        .collect();
    assert!(
        during.len() > 100,
        "{} states during the injection",
        during.len()
    );
    let worst_qd = during
        .iter()
        .flat_map(|s| (0..6).map(move |j| s.qd[j].abs()))
        .fold(0.0, f64::max);
    assert!(worst_qd < 0.05, "the arm moved at {worst_qd} rad/s");
}

/// Publishes `n` messages `make(k, now)` on stream `kind` of `inst` from this (unsupervised)
/// test process, one per ms, while `victim` is frozen (SIGSTOP, then SIGCONT); returns
/// the injection's start and end.
fn inject_while_frozen<T: std::fmt::Debug + ZeroCopySend + Copy + 'static>(
    inst: &str,
    kind: ServiceKind,
    victim: i32,
    n: u64,
    make: impl Fn(u64, u64) -> T,
) -> (u64, u64) {
    let node = iceoryx2::prelude::NodeBuilder::new()
        .signal_handling_mode(iceoryx2::prelude::SignalHandlingMode::Disabled)
        .create::<iceoryx2::service::ipc::Service>()
        .expect("node");
    let publisher = open_publish_subscribe::<T>(&node, inst, kind)
        .expect("service")
        .publisher_builder()
        .create()
        .expect("publisher");
    let notifier = open_event(&node, inst, kind)
        .expect("event")
        .notifier_builder()
        .create()
        .expect("notifier");
    std::thread::sleep(Duration::from_millis(300));
    // SAFETY: kill(2) on a child of the pipeline this test started.
    unsafe { libc::kill(victim, libc::SIGSTOP) };
    // Past stale_ms of silence: the stream's own publisher counts as gone.
    std::thread::sleep(Duration::from_millis(100));
    let from = monotonic_ns();
    for k in 0..n {
        publisher.send_copy(make(k, monotonic_ns())).expect("send");
        let _ = notifier.notify();
        std::thread::sleep(Duration::from_millis(1));
    }
    let to = monotonic_ns();
    // SAFETY: as above.
    unsafe { libc::kill(victim, libc::SIGCONT) };
    (from, to)
}

/// Waits for `role`'s status to report `n` or more messages refused as an outsider's.
fn refused_as_outsider(inst: &str, role: ServiceRole, n: u64) {
    let s = wait_status(inst, role, "outsiders refused", 30.0, |s| {
        s.refused_messages >= n
            && RefusalReason::from_wire(s.last_input_refusal) == Some(RefusalReason::Outsider)
    });
    assert!(s.refused_messages >= n, "{role:?}: {s:?}");
}

#[test]
fn hostile_setpoints_and_states_during_stalls_are_refused_as_outsiders() {
    let dir = tempfile::tempdir().expect("tempdir");
    let inst = instance("takeover-sp-st");
    let cfg = write_config(dir.path(), &inst, "", "[supervisor]\nhung_ms = 60000.0");
    let rec = Recorder::start(&inst);
    let proc = start_holding(&inst, &cfg, 90, None);
    let planner = pid_of(&inst, ServiceRole::Planner).expect("planner pid");
    let actuator = pid_of(&inst, ServiceRole::Actuator).expect("actuator pid");

    // Setpoints towards j1 = +90°, while the planner is frozen.
    let (sp_from, sp_to) =
        inject_while_frozen(&inst, ServiceKind::Setpoint, planner, 400, |k, now| {
            let mut m = JointSetpoint {
                header: Header {
                    seq: k + 1,
                    tick: MARK + k,
                    stamp_ns: now,
                    source_stamp_ns: now,
                },
                dof: 6,
                ..Default::default()
            };
            m.q[0] = 1.5;
            m.q[2] = 0.5;
            m
        });
    refused_as_outsider(&inst, ServiceRole::Dynamics, 300);
    // The planner froze past fault_ms: the actuator latched; reset once the planner is back.
    std::thread::sleep(Duration::from_millis(300));
    let mut commands = CommandSender::open(&inst);
    commands.send(command(CommandKind::Reset));
    wait_status(&inst, ServiceRole::Actuator, "active again", 30.0, |s| {
        s.lifecycle == LifecycleState::Active as u32
    });

    // States claiming the arm far away, while the actuator is frozen.
    let (st_from, st_to) =
        inject_while_frozen(&inst, ServiceKind::State, actuator, 400, |k, now| {
            let mut m = JointState {
                header: Header {
                    seq: MARK + k + 1, // a torque fed back from it would carry state_seq >= MARK
                    tick: MARK + k,
                    stamp_ns: now,
                    source_stamp_ns: now,
                },
                torque_seq: u64::MAX,
                dof: 6,
                lifecycle: LifecycleState::Active as u32,
                ..Default::default()
            };
            m.q[1] = -1.2;
            m.q[2] = 1.0;
            m
        });
    refused_as_outsider(&inst, ServiceRole::Planner, 300);
    refused_as_outsider(&inst, ServiceRole::Dynamics, 600);
    std::thread::sleep(Duration::from_millis(300));
    commands.send(command(CommandKind::Reset));
    std::thread::sleep(Duration::from_millis(300));

    proc.signal(libc::SIGINT);
    let out = proc.finish(60.0);
    let streams = rec.finish();
    // No torque was computed from a hostile setpoint or state, and no setpoint planned
    // from a hostile state.
    assert!(
        streams.torques.iter().all(|t| t.header.tick < MARK),
        "a torque derived from a hostile setpoint"
    );
    assert!(
        streams
            .torques
            .iter()
            .filter(|t| t.header.stamp_ns >= st_from && t.header.stamp_ns <= st_to + 100_000_000)
            .all(|t| t.state_seq == u64::MAX || t.state_seq < MARK),
        "a torque fed back a hostile state"
    );
    let worst_qd = streams
        .states
        .iter()
        .filter(|s| s.header.stamp_ns >= sp_from && s.header.stamp_ns <= st_to)
        .flat_map(|s| (0..6).map(move |j| s.qd[j].abs()))
        .fold(0.0, f64::max);
    assert!(worst_qd < 0.05, "the arm moved at {worst_qd} rad/s");
    let during_setpoints = streams
        .states
        .iter()
        .filter(|s| s.header.stamp_ns >= sp_from && s.header.stamp_ns <= sp_to)
        .count();
    assert!(
        during_setpoints > 100,
        "{during_setpoints} states while hostile setpoints came"
    );
    assert_eq!(out.code(), Some(0), "{}", out.stderr);
}
