//! Bad input on the bus of a running pipeline, one class at a time, from a test
//! publisher on the instance's own services: motion commands (the planner) and setpoint,
//! torque and state payloads (dynamics, actuator, planner). Each one is refused, counted
//! in the receiving stage's `refused_messages`, named in its status
//! (`last_command_refusal` / `last_input_refusal`), produces no output of its own, and
//! the arm does not move (measured q unchanged).
//!
//! Sequence numbers: a stage follows one publisher per stream, so duplicates and
//! reordering are refused within its stream (unit-tested in `microrobot_runtime::validate`);
//! an injected message is refused on its content before its publisher and sequence number
//! are looked at. A well-formed, fresh message from the test's own (second) publisher is
//! refused as such while the pipeline's publisher of that stream is live; on the torque
//! stream it is refused as an outsider's (the test is not a process the supervisor
//! started) and latches the actuator's safe state.

use std::time::{Duration, Instant};

use crate::common::*;
use iceoryx2::prelude::*;
use microrobot_messages::{
    CommandKind, Header, JointSetpoint, JointState, MotionCommand, ProfileKind, RefusalReason,
    ServiceKind, ServiceRole, ServiceStatus, TargetSpace, TorqueCommand, monotonic_ns, open_event,
    open_publish_subscribe,
};

/// A distinctive tick and sequence number for injected messages, so their (absent)
/// consequences can be looked for in the recorded streams.
const MARK: u64 = 1 << 40;

fn node() -> Node<ipc::Service> {
    NodeBuilder::new()
        .name(
            &NodeName::new(&format!("microrobot-test-injector-{}", std::process::id()))
                .expect("name"),
        )
        .signal_handling_mode(SignalHandlingMode::Disabled)
        .create::<ipc::Service>()
        .expect("node")
}

/// The newest status of each role, from a subscriber of the test.
struct Statuses {
    sub: iceoryx2::port::subscriber::Subscriber<ipc::Service, ServiceStatus, ()>,
    latest: [Option<ServiceStatus>; 3],
}

impl Statuses {
    fn open(node: &Node<ipc::Service>, inst: &str) -> Self {
        let sub = open_publish_subscribe::<ServiceStatus>(node, inst, ServiceKind::Status)
            .expect("status service")
            .subscriber_builder()
            .create()
            .expect("status subscriber");
        Self {
            sub,
            latest: [None; 3],
        }
    }

    fn poll(&mut self) {
        while let Ok(Some(s)) = self.sub.receive() {
            if (1..=3).contains(&s.role) {
                self.latest[s.role as usize - 1] = Some(*s);
            }
        }
    }

    /// Waits (guard 20 s) until `role`'s status satisfies `f`; returns it.
    fn wait(
        &mut self,
        role: ServiceRole,
        what: &str,
        f: impl Fn(&ServiceStatus) -> bool,
    ) -> ServiceStatus {
        let t0 = Instant::now();
        loop {
            self.poll();
            if let Some(s) = self.latest[role as usize - 1]
                && f(&s)
            {
                return s;
            }
            assert!(
                t0.elapsed() < Duration::from_secs(20),
                "{}: {what} not seen within 20 s (last status {:?})",
                role.name(),
                self.latest[role as usize - 1]
            );
            std::thread::sleep(Duration::from_millis(20));
        }
    }
}

/// Publisher + notifier of one stream.
struct Injector<T: std::fmt::Debug + Copy + ZeroCopySend + 'static> {
    publisher: iceoryx2::port::publisher::Publisher<ipc::Service, T, ()>,
    notifier: iceoryx2::port::notifier::Notifier<ipc::Service>,
}

impl<T: std::fmt::Debug + Copy + ZeroCopySend + 'static> Injector<T> {
    fn open(node: &Node<ipc::Service>, inst: &str, kind: ServiceKind) -> Self {
        let publisher = open_publish_subscribe::<T>(node, inst, kind)
            .expect("service")
            .publisher_builder()
            .create()
            .expect("publisher");
        let notifier = open_event(node, inst, kind)
            .expect("event")
            .notifier_builder()
            .create()
            .expect("notifier");
        Self {
            publisher,
            notifier,
        }
    }

    fn send(&self, m: T) {
        self.publisher.send_copy(m).expect("send");
        let _ = self.notifier.notify();
    }
}

fn header(stamp_ns: u64) -> Header {
    Header {
        seq: MARK,
        tick: MARK,
        stamp_ns,
        source_stamp_ns: stamp_ns,
    }
}

fn good_setpoint() -> JointSetpoint {
    JointSetpoint {
        header: header(monotonic_ns()),
        dof: 6,
        ..Default::default()
    }
}

fn good_torque() -> TorqueCommand {
    TorqueCommand {
        header: header(monotonic_ns()),
        dof: 6,
        setpoint_seq: MARK,
        state_seq: u64::MAX,
        ..Default::default()
    }
}

fn good_state() -> JointState {
    JointState {
        header: header(monotonic_ns()),
        dof: 6,
        torque_seq: MARK,
        ..Default::default()
    }
}

fn good_move() -> MotionCommand {
    MotionCommand {
        seq: MARK,
        stamp_ns: monotonic_ns(),
        kind: CommandKind::Move as u32,
        profile: ProfileKind::Soft as u32,
        space: TargetSpace::Joint as u32,
        dof: 6,
        target: [0.1; 8],
        duration_s: 0.0,
        limit_scale: 1.0,
    }
}

#[test]
fn every_bad_input_class_is_refused_named_counted_and_moves_nothing() {
    let dir = tempfile::tempdir().expect("tempdir");
    let inst = instance("bad-input");
    let cfg = write_config(dir.path(), &inst, "", "");
    let rec = Recorder::start(&inst);
    let proc = start_holding(&inst, &cfg, 120, None);
    let node = node();
    let mut statuses = Statuses::open(&node, &inst);
    let sp = Injector::<JointSetpoint>::open(&node, &inst, ServiceKind::Setpoint);
    let tq = Injector::<TorqueCommand>::open(&node, &inst, ServiceKind::Torque);
    let st = Injector::<JointState>::open(&node, &inst, ServiceKind::State);
    let cmd = Injector::<MotionCommand>::open(&node, &inst, ServiceKind::Command);
    // The ports connect on the receivers' next wake-ups.
    std::thread::sleep(Duration::from_millis(500));
    let start_ns = monotonic_ns();

    // One message per class; the receiving stage must count it and name it.
    let mut expect = |role: ServiceRole, class: &str, reason: RefusalReason, send: &dyn Fn()| {
        let base = statuses.wait(role, "a status", |_| true);
        send();
        let command = role == ServiceRole::Planner && class.starts_with("command");
        let after = statuses.wait(role, &format!("{class} refused"), |s| {
            s.refused_messages > base.refused_messages
        });
        assert_eq!(
            after.refused_messages,
            base.refused_messages + 1,
            "{}: {class}: exactly one refusal",
            role.name()
        );
        let got = if command {
            after.last_command_refusal
        } else {
            after.last_input_refusal
        };
        assert_eq!(
            RefusalReason::from_wire(got),
            Some(reason),
            "{}: {class} is named ({})",
            role.name(),
            reason.describe()
        );
        if command {
            assert_eq!(after.commands_refused, base.commands_refused + 1);
            assert_eq!(after.commands_accepted, base.commands_accepted, "{class}");
        }
    };

    use RefusalReason as R;
    use ServiceRole::{Actuator, Dynamics, Planner};
    // Motion commands, straight onto the bus (`send` refuses most of these locally).
    expect(Planner, "command: NaN target", R::NonFinite, &|| {
        let mut c = good_move();
        c.target[2] = f64::NAN;
        cmd.send(c)
    });
    expect(
        Planner,
        "command: out-of-limit target",
        R::OutOfLimits,
        &|| {
            let mut c = good_move();
            c.target[2] = -1.0; // joint 3 is limited to [0°, 180°]
            cmd.send(c)
        },
    );
    expect(
        Planner,
        "command: impossible duration",
        R::BadDuration,
        &|| {
            let mut c = good_move();
            c.profile = ProfileKind::Quintic as u32;
            c.duration_s = -2.0;
            cmd.send(c)
        },
    );
    expect(Planner, "command: infinite duration", R::NonFinite, &|| {
        let mut c = good_move();
        c.duration_s = f64::INFINITY;
        cmd.send(c)
    });
    expect(Planner, "command: joint count", R::WrongDof, &|| {
        let mut c = good_move();
        c.dof = 7;
        cmd.send(c)
    });
    expect(Planner, "command: unknown kind", R::UnknownKind, &|| {
        let mut c = good_move();
        c.kind = 99;
        cmd.send(c)
    });
    expect(Planner, "command: stale stamp", R::Stale, &|| {
        let mut c = good_move();
        c.stamp_ns = monotonic_ns() - 10_000_000_000;
        cmd.send(c)
    });
    // Setpoints → dynamics.
    expect(Dynamics, "setpoint: NaN", R::NonFinite, &|| {
        let mut m = good_setpoint();
        m.qd[1] = f64::NAN;
        sp.send(m)
    });
    expect(Dynamics, "setpoint: joint count", R::WrongDof, &|| {
        let mut m = good_setpoint();
        m.dof = 5;
        sp.send(m)
    });
    expect(Dynamics, "setpoint: out of limits", R::OutOfLimits, &|| {
        let mut m = good_setpoint();
        m.q[1] = 3.0; // joint 2 is limited to ±90°
        sp.send(m)
    });
    expect(Dynamics, "setpoint: stale stamp", R::Stale, &|| {
        let mut m = good_setpoint();
        m.header.stamp_ns -= 5_000_000_000;
        sp.send(m)
    });
    expect(
        Dynamics,
        "setpoint: stamp from the future",
        R::Stale,
        &|| {
            let mut m = good_setpoint();
            m.header.stamp_ns += 5_000_000_000;
            sp.send(m)
        },
    );
    expect(
        Dynamics,
        "setpoint: well-formed, from a second publisher",
        R::SecondPublisher,
        &|| sp.send(good_setpoint()),
    );
    // Torques → actuator.
    expect(Actuator, "torque: infinity", R::NonFinite, &|| {
        let mut m = good_torque();
        m.tau[0] = f64::INFINITY;
        tq.send(m)
    });
    expect(Actuator, "torque: joint count", R::WrongDof, &|| {
        let mut m = good_torque();
        m.dof = 9;
        tq.send(m)
    });
    expect(Actuator, "torque: stale stamp", R::Stale, &|| {
        let mut m = good_torque();
        m.header.stamp_ns -= 5_000_000_000;
        tq.send(m)
    });
    // Zero torque would let the arm sag under gravity: it must not be applied. The test
    // process is not one the pipeline's supervisor started: an outsider, whose attempt
    // to drive the arm latches the actuator's safe state (the arm holds).
    expect(
        Actuator,
        "torque: well-formed, from an outsider",
        R::Outsider,
        &|| tq.send(good_torque()),
    );
    let latched = statuses.wait(Actuator, "the safe state after an outsider's torque", |s| {
        s.lifecycle == microrobot_messages::LifecycleState::Fault as u32
    });
    assert_eq!(latched.faults, 1, "the run's one fault is the outsider's");
    // The pipeline's own dynamics still drives the stream: a reset resumes it.
    let mut reset = crate::common::command(CommandKind::Reset);
    reset.seq = 1;
    reset.stamp_ns = monotonic_ns();
    cmd.send(reset);
    statuses.wait(Actuator, "active again after a reset", |s| {
        s.lifecycle == microrobot_messages::LifecycleState::Active as u32
    });
    // States → planner and dynamics (both subscribe; both refuse).
    for (class, reason, m) in [
        ("state: NaN", R::NonFinite, {
            let mut m = good_state();
            m.q[4] = f64::NAN;
            m
        }),
        ("state: joint count", R::WrongDof, {
            let mut m = good_state();
            m.dof = 0;
            m
        }),
        (
            "state: well-formed, from a second publisher",
            R::SecondPublisher,
            good_state(),
        ),
    ] {
        let base_p = statuses.wait(Planner, "a status", |_| true);
        let base_d = statuses.wait(Dynamics, "a status", |_| true);
        st.send(m);
        for (role, base) in [(Planner, base_p), (Dynamics, base_d)] {
            let after = statuses.wait(role, class, |s| s.refused_messages > base.refused_messages);
            assert_eq!(
                after.refused_messages,
                base.refused_messages + 1,
                "{}: {class}",
                role.name()
            );
            assert_eq!(
                RefusalReason::from_wire(after.last_input_refusal),
                Some(reason),
                "{}: {class}",
                role.name()
            );
        }
    }
    let end_ns = monotonic_ns();
    std::thread::sleep(Duration::from_millis(300));
    proc.signal(libc::SIGINT);
    let out = proc.finish(60.0);
    assert_eq!(out.code(), Some(0), "{}", out.stderr);
    let streams = rec.finish();

    // Nothing came of the injected messages: no torque for an injected setpoint, no state
    // applying an injected torque, no moving setpoint.
    assert!(
        streams
            .torques
            .iter()
            .filter(|t| t.header.seq != MARK)
            .all(|t| t.header.tick != MARK && t.setpoint_seq != MARK)
    );
    assert!(
        streams
            .states
            .iter()
            .filter(|s| s.header.seq != MARK)
            .all(|s| s.torque_seq != MARK)
    );
    let planner_sp: Vec<_> = streams
        .setpoints
        .iter()
        .filter(|s| s.header.seq != MARK && s.header.stamp_ns >= start_ns)
        .collect();
    assert!(planner_sp.len() > 100, "{}", planner_sp.len());
    // No motion planned: after the outsider's latch and the reset, the planner may
    // re-plan a hold from where the arm is (flagged MOVING), but not move it.
    let planned_speed = planner_sp
        .iter()
        .flat_map(|s| (0..6).map(move |j| s.qd[j].abs()))
        .fold(0.0, f64::max);
    assert!(
        planned_speed < 1e-9,
        "a setpoint moved at {planned_speed} rad/s"
    );
    // The arm did not move: the measured state over the whole injection window.
    let measured: Vec<_> = streams
        .states
        .iter()
        .filter(|s| {
            s.header.seq != MARK && s.header.stamp_ns >= start_ns && s.header.stamp_ns <= end_ns
        })
        .collect();
    assert!(measured.len() > 100, "{}", measured.len());
    let q0 = measured[0].q;
    let drift = measured
        .iter()
        .flat_map(|s| (0..6).map(move |j| (s.q[j] - q0[j]).abs()))
        .fold(0.0, f64::max);
    assert!(drift < 1e-6, "the arm moved by {drift} rad");
}
