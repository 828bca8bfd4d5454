//! Silence alone does not hand the torque stream over: while the pipeline's dynamics is
//! frozen (SIGSTOP 0.8 s), a hostile process on the same machine publishes well-formed,
//! fresh torque commands on the instance's torque stream. They are refused as an
//! outsider's (the hostile process is not one the supervisor started), never applied,
//! and latch the safe state; once the dynamics wakes, its own stream is taken again (no
//! lock-out), a reset resumes the arm, and the run ends cleanly.

mod common;

use std::time::Duration;

use common::*;
use microrobot_messages::{
    CommandKind, Header, LifecycleState, RefusalReason, ServiceKind, ServiceRole, TorqueCommand,
    monotonic_ns, open_event, open_publish_subscribe,
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

    // The hostile publisher: a node and ports of this (unsupervised) test process.
    let node = iceoryx2::prelude::NodeBuilder::new()
        .signal_handling_mode(iceoryx2::prelude::SignalHandlingMode::Disabled)
        .create::<iceoryx2::service::ipc::Service>()
        .expect("node");
    let publisher = open_publish_subscribe::<TorqueCommand>(&node, &inst, ServiceKind::Torque)
        .expect("torque service")
        .publisher_builder()
        .create()
        .expect("publisher");
    let notifier = open_event(&node, &inst, ServiceKind::Torque)
        .expect("torque event")
        .notifier_builder()
        .create()
        .expect("notifier");
    std::thread::sleep(Duration::from_millis(300));

    // SAFETY: kill(2) on a child of the pipeline this test started.
    unsafe { libc::kill(dynamics, libc::SIGSTOP) };
    // Past stale_ms of silence: the stream's own publisher counts as gone.
    std::thread::sleep(Duration::from_millis(100));
    let injected_from = monotonic_ns();
    for k in 0..500u64 {
        let now = monotonic_ns();
        let mut tau = [0.0; 8];
        tau[0] = 30.0; // would drive joint 1 into its limit within a fraction of a second
        publisher
            .send_copy(TorqueCommand {
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
            })
            .expect("send");
        let _ = notifier.notify();
        std::thread::sleep(Duration::from_millis(1));
    }
    let injected_to = monotonic_ns();
    // SAFETY: as above.
    unsafe { libc::kill(dynamics, libc::SIGCONT) };

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
