//! The actuator core: validation of torque commands, the stale hold, the latched safe
//! state and its reset, with a fake clock.

use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use microrobot_actuator::backend::{ActuatorBackend, Fault, Measured};
use microrobot_actuator::{ActuatorConfig, ActuatorCore, Mode, SimArm, initial_q};
use microrobot_messages::{
    Header, LifecycleHook, LifecycleState, TorqueCommand, state_flags, torque_flags,
};
use microrobot_model::JointVector;
use microrobot_model::Robot;
use microrobot_runtime::config::PipelineConfig;

const MS: u64 = 1_000_000;

fn core() -> (ActuatorCore<SimArm>, Robot) {
    let cfg = PipelineConfig {
        robot: PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../config/robots/seed-arm.toml"),
        ..Default::default()
    };
    let robot = Robot::from_file(&cfg.robot).unwrap();
    let a = ActuatorConfig::default();
    let sim = SimArm::new(&robot, &a.sim, &initial_q(&robot, &a.sim));
    (ActuatorCore::new(sim, &robot, &cfg, &a).unwrap(), robot)
}

fn torque(seq: u64, stamp_ns: u64) -> TorqueCommand {
    TorqueCommand {
        header: Header {
            seq,
            tick: seq,
            stamp_ns,
            source_stamp_ns: stamp_ns,
        },
        dof: 6,
        ..Default::default()
    }
}

#[test]
fn garbage_torque_commands_are_refused_and_counted() {
    let (mut c, _) = core();
    let now = 1000 * MS;
    let mut nan = torque(1, now);
    nan.tau[0] = f64::NAN;
    assert!(c.accept_torque(&nan, 1, now).is_err());
    let mut dof = torque(1, now);
    dof.dof = 7;
    assert!(c.accept_torque(&dof, 1, now).is_err());
    assert!(
        c.accept_torque(&torque(1, now - 60 * MS), 1, now).is_err(),
        "stale"
    );
    assert!(c.accept_torque(&torque(1, now), 1, now).is_ok());
    assert!(
        c.accept_torque(&torque(1, now), 1, now).is_err(),
        "duplicate"
    );
    assert_eq!(c.counters.refused, 4);
    assert_eq!(c.lifecycle(), LifecycleState::Active);
}

#[test]
fn missing_commands_hold_then_latch_until_reset() {
    let (mut c, _) = core();
    let t0 = 1000 * MS;
    c.accept_torque(&torque(1, t0), 1, t0).unwrap();
    // The plant steps every period (a gap longer than stale_ms would be a stall).
    let step_until = |c: &mut ActuatorCore<_>, from: u64, to: u64| {
        let mut s = None;
        for now in (from..=to).step_by(MS as usize) {
            c.check_watchdog(now);
            s = Some(c.step(now));
        }
        s.expect("at least one step")
    };
    let s = step_until(&mut c, t0, t0 + 60 * MS);
    assert_ne!(s.flags & state_flags::COMMAND_STALE, 0);
    assert!(!c.safe_state_latched());
    let s = step_until(&mut c, t0 + 61 * MS, t0 + 250 * MS);
    assert!(c.safe_state_latched());
    assert_ne!(s.flags & state_flags::SAFE_STATE, 0);
    assert_eq!(s.lifecycle, LifecycleState::Fault as u32);
    assert_eq!(c.counters.faults, 1);
    // Reset without fresh commands is refused.
    assert!(!c.reset(t0 + 260 * MS, &mut |_| {}));
    assert!(c.safe_state_latched());
    // Fresh commands alone do not unlatch (no auto_resume) ...
    c.accept_torque(&torque(2, t0 + 270 * MS), 1, t0 + 270 * MS)
        .unwrap();
    c.check_watchdog(t0 + 271 * MS);
    assert!(c.safe_state_latched());
    // ... a reset does.
    assert!(c.reset(t0 + 272 * MS, &mut |_| {}));
    assert!(!c.safe_state_latched());
}

#[test]
fn the_arm_holds_still_under_its_own_law_in_the_safe_state() {
    let (mut c, _) = core();
    let t0 = 1000 * MS;
    // Gravity torque is not commanded: the first command is zero torque, then nothing.
    c.accept_torque(&torque(1, t0), 1, t0).unwrap();
    c.step(t0);
    c.check_watchdog(t0 + 300 * MS);
    let q_latch = c.backend().true_state().0;
    for k in 0..2000 {
        c.check_watchdog(t0 + 300 * MS + k * MS);
        c.step(t0 + 300 * MS + k * MS);
    }
    let (q, qd) = c.backend().true_state();
    let drift = (0..6)
        .map(|i| (q[i] - q_latch[i]).abs())
        .fold(0.0, f64::max);
    assert!(drift < 2e-2, "drift {drift}");
    assert!(qd.iter().all(|v| v.abs() < 1e-2));
    let _ = Mode::Safe;
}

/// A command answering state `state_seq`, stamped `stamp_ns`.
fn answering(seq: u64, stamp_ns: u64, state_seq: u64) -> TorqueCommand {
    TorqueCommand {
        state_seq,
        ..torque(seq, stamp_ns)
    }
}

#[test]
fn after_a_stall_the_arm_holds_until_a_command_answers_a_state_from_after_it() {
    let (mut c, _) = core();
    let t0 = 1000 * MS;
    let mut seq = 0;
    let mut last_state = 0;
    for k in 0..10 {
        let now = t0 + k * MS;
        seq += 1;
        assert_eq!(c.on_wake(now), None, "no stall while stepping every period");
        c.accept_torque(&answering(seq, now, last_state), 1, now)
            .unwrap();
        c.check_watchdog(now);
        last_state = c.step(now).header.seq;
    }
    // Frozen for 100 ms (between stale_ms = 50 and fault_ms = 200).
    let wake = t0 + 110 * MS;
    assert_eq!(c.on_wake(wake), Some(101 * MS));
    assert_eq!(c.counters.stalls, 1);
    // Queued during the stall, stamped fresh, but answering the state before it (or
    // computed without the feedback the dynamics wanted): not followed.
    seq += 1;
    assert!(
        c.accept_torque(&answering(seq, wake, last_state), 1, wake)
            .is_err()
    );
    seq += 1;
    let mut no_feedback = answering(seq, wake, u64::MAX);
    no_feedback.flags = torque_flags::STATE_STALE;
    assert!(c.accept_torque(&no_feedback, 1, wake).is_err());
    c.check_watchdog(wake);
    let s = c.step(wake);
    assert_ne!(s.flags & state_flags::STALLED, 0);
    assert_ne!(s.flags & state_flags::COMMAND_STALE, 0, "holding");
    assert!(!c.safe_state_latched());
    // A command answering the first state after the stall: followed again.
    let now = wake + MS;
    seq += 1;
    c.accept_torque(&answering(seq, now, s.header.seq), 1, now)
        .unwrap();
    c.check_watchdog(now);
    let s = c.step(now);
    assert_eq!(
        s.flags & (state_flags::STALLED | state_flags::COMMAND_STALE),
        0
    );
    assert_eq!(c.counters.stalls, 1);
}

#[test]
fn a_stall_longer_than_fault_ms_latches_the_safe_state_before_queued_commands_count() {
    let (mut c, _) = core();
    let t0 = 1000 * MS;
    c.accept_torque(&answering(1, t0, 0), 1, t0).unwrap();
    c.check_watchdog(t0);
    let s = c.step(t0);
    let wake = t0 + 300 * MS;
    assert!(c.on_wake(wake).is_some());
    assert!(c.safe_state_latched(), "300 ms without commands");
    // The command queued last during the stall is fresh by its stamp, but it answers
    // the state before the stall: it neither feeds the watchdog nor allows a reset.
    assert!(
        c.accept_torque(&answering(2, wake, s.header.seq), 1, wake)
            .is_err()
    );
    assert!(!c.reset(wake, &mut |_| {}));
    assert!(c.safe_state_latched());
    // A step never applies a command older than stale_ms, whatever the caller did.
    let s = c.step(wake);
    assert_ne!(s.flags & state_flags::SAFE_STATE, 0);
    assert_ne!(s.flags & state_flags::STALLED, 0);
}

/// A freeze that lands inside a wake-up, after its stall check (SIGSTOP in the middle
/// of a plant step): the commands the dynamics queued meanwhile are stamped fresh, and
/// the next wake-up's check would come after they fed the watchdog and drove the plant.
/// The first command or step after the freeze judges it instead, as `on_wake` would.
#[test]
fn a_stall_inside_a_wake_up_is_caught_by_the_next_command_or_step() {
    for first_after in ["command", "step"] {
        let (mut c, _) = core();
        let t0 = 1000 * MS;
        c.accept_torque(&answering(1, t0, 0), 1, t0).unwrap();
        c.check_watchdog(t0);
        let s = c.step(t0);
        // Frozen 2 s right after that step; no `on_wake` before what comes next.
        let resumed = t0 + 2000 * MS;
        let queued = answering(2, resumed - MS, s.header.seq);
        if first_after == "command" {
            assert!(
                c.accept_torque(&queued, 1, resumed).is_err(),
                "{first_after}"
            );
        } else {
            let s = c.step(resumed);
            assert_ne!(s.flags & state_flags::STALLED, 0, "{first_after}");
            assert!(
                c.accept_torque(&queued, 1, resumed).is_err(),
                "{first_after}"
            );
        }
        assert_eq!(c.counters.stalls, 1, "{first_after}");
        assert_eq!(c.last_stall_ns(), 2000 * MS, "{first_after}");
        assert!(
            c.safe_state_latched(),
            "{first_after}: 2 s without commands"
        );
        let s = c.step(resumed);
        assert_ne!(s.flags & state_flags::SAFE_STATE, 0, "{first_after}");
        assert_ne!(s.flags & state_flags::STALLED, 0, "{first_after}");
        // Counted once: the wake-up's own check finds nothing more.
        assert_eq!(c.on_wake(resumed + MS), None, "{first_after}");
        assert_eq!(c.counters.stalls, 1, "{first_after}");
    }
}

#[test]
fn lockstep_has_no_stalls() {
    let cfg = PipelineConfig {
        robot: PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../config/robots/seed-arm.toml"),
        lockstep: true,
        ..Default::default()
    };
    let robot = Robot::from_file(&cfg.robot).unwrap();
    let a = ActuatorConfig::default();
    let sim = SimArm::new(&robot, &a.sim, &initial_q(&robot, &a.sim));
    let mut c = ActuatorCore::new(sim, &robot, &cfg, &a).unwrap();
    c.accept_torque(&torque(1, MS), 1, MS).unwrap();
    c.step(MS);
    assert_eq!(c.on_wake(10_000 * MS), None);
    assert!(!c.stalled());
}

/// How long the slow bus's reset blocks in the `fault_ms` test (longer than `fault_ms`).
const RESET_BLOCKS: Duration = Duration::from_millis(250);

/// A bus fault, then a reset whose hook blocks for longer than `fault_ms`: the time
/// inside the hook is neither a stall nor a silence, so the arm follows the next fresh
/// command without re-latching, while a command older than `stale_ms` is not applied.
fn reset_blocking_longer_than_fault_ms_recovers(lockstep: bool) {
    let cfg = PipelineConfig {
        robot: PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../config/robots/seed-arm.toml"),
        lockstep,
        ..Default::default()
    };
    assert!(RESET_BLOCKS.as_nanos() as u64 > cfg.watchdog.fault_ns());
    let robot = Robot::from_file(&cfg.robot).unwrap();
    let fail = Arc::new(AtomicBool::new(false));
    let a = ActuatorConfig::default();
    let arm = SlowBusArm {
        sim: SimArm::new(&robot, &a.sim, &initial_q(&robot, &a.sim)),
        fail: fail.clone(),
        reset_blocks: RESET_BLOCKS,
        activate_blocks: Duration::ZERO,
        events: Default::default(),
    };
    let mut c = ActuatorCore::new(arm, &robot, &cfg, &a).unwrap();
    let t0 = 1000 * MS;
    let mut t = t0;
    for seq in 1..=5 {
        assert_eq!(c.on_wake(t), None);
        c.accept_torque(&torque(seq, t), 1, t).unwrap();
        c.check_watchdog(t);
        c.step(t);
        t += MS;
    }
    assert_eq!(c.lifecycle(), LifecycleState::Active);
    // The bus fails; the pipeline keeps sending.
    fail.store(true, Ordering::Relaxed);
    c.accept_torque(&torque(6, t), 1, t).unwrap();
    c.step(t);
    assert_eq!(c.lifecycle(), LifecycleState::Fault);
    t += MS;
    c.accept_torque(&torque(7, t), 1, t).unwrap();
    // The reset blocks: the fake clock moves on by what it really took.
    let start = std::time::Instant::now();
    assert!(c.reset(t, &mut |_| {}));
    let took = start.elapsed().as_nanos() as u64;
    assert!(took >= RESET_BLOCKS.as_nanos() as u64);
    t += took;
    assert_eq!(c.on_wake(t), None, "the blocking reset is no stall");
    c.check_watchdog(t);
    assert!(
        !c.safe_state_latched(),
        "the watchdog restarted from the hook's end"
    );
    let s = c.step(t);
    assert_eq!(
        s.flags & (state_flags::SAFE_STATE | state_flags::STALLED),
        0
    );
    if !lockstep {
        // Free-running, the torque from before the reset is too old to apply.
        assert_ne!(s.flags & state_flags::COMMAND_STALE, 0);
    }
    assert_eq!(c.counters.stalls, 0);
    assert_eq!(c.counters.faults, 1, "the bus fault only: no re-latch");
    // The pipeline answers that state: followed again, drives back on.
    t += MS;
    c.accept_torque(&answering(8, t, s.header.seq), 1, t)
        .unwrap();
    c.check_watchdog(t);
    let s = c.step(t);
    assert_eq!(c.lifecycle(), LifecycleState::Active);
    assert_eq!(
        s.flags & (state_flags::SAFE_STATE | state_flags::STALLED | state_flags::COMMAND_STALE),
        0
    );
    assert_eq!(s.torque_seq, 8);
    // Silence after it is still judged from then on: latched after fault_ms.
    t += cfg.watchdog.fault_ns() + MS;
    c.check_watchdog(t);
    assert!(c.safe_state_latched());
}

#[test]
fn a_reset_blocking_longer_than_fault_ms_recovers_free_running() {
    reset_blocking_longer_than_fault_ms_recovers(false);
}

#[test]
fn a_reset_blocking_longer_than_fault_ms_recovers_in_lockstep() {
    reset_blocking_longer_than_fault_ms_recovers(true);
}

/// The simulated arm behind a bus that can fail, whose hooks block (like a real
/// master's that brings the bus up again), recording which hook ran, in order.
struct SlowBusArm {
    sim: SimArm,
    fail: Arc<AtomicBool>,
    reset_blocks: Duration,
    activate_blocks: Duration,
    events: Arc<std::sync::Mutex<Vec<String>>>,
}

/// How long the slow bus's hooks block in the announcement test: longer than the
/// supervisor's `hung_ms` and the watchdog's `fault_ms` (500 ms and 200 ms by default).
const HOOK_BLOCKS: Duration = Duration::from_millis(600);

impl SlowBusArm {
    fn note(&self, what: &str) {
        self.events.lock().unwrap().push(what.to_string());
    }
}

impl ActuatorBackend for SlowBusArm {
    fn dof(&self) -> usize {
        self.sim.dof()
    }
    fn on_activate(&mut self) -> Result<(), Fault> {
        self.note("on_activate");
        std::thread::sleep(self.activate_blocks);
        Ok(())
    }
    fn on_reset(&mut self) -> Result<(), Fault> {
        self.note("on_reset");
        std::thread::sleep(self.reset_blocks);
        self.fail.store(false, Ordering::Relaxed);
        Ok(())
    }
    fn write(&mut self, now_ns: u64, period_s: f64, tau: &JointVector) -> Result<(), Fault> {
        if self.fail.load(Ordering::Relaxed) {
            return Err(Fault::drive(0x8130, "bus lost"));
        }
        self.sim.write(now_ns, period_s, tau)
    }
    fn read(&mut self, now_ns: u64) -> Result<Measured, Fault> {
        self.sim.read(now_ns)
    }
}

/// Every hook that blocks the cycle is announced just before it runs (the stage then
/// publishes a status naming it and its budget, so the supervisor does not take the
/// blocked actuator for hung), and only then: a call that runs no hook announces none.
#[test]
fn a_hook_blocking_longer_than_hung_ms_is_announced_before_it_runs() {
    let cfg = PipelineConfig {
        robot: PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../config/robots/seed-arm.toml"),
        ..Default::default()
    };
    assert!(HOOK_BLOCKS.as_secs_f64() * 1e3 > cfg.supervisor.hung_ms);
    let robot = Robot::from_file(&cfg.robot).unwrap();
    let a = ActuatorConfig::default();
    assert!(
        a.hook_budget_ms > HOOK_BLOCKS.as_secs_f64() * 1e3,
        "the default budget covers it"
    );
    let fail = Arc::new(AtomicBool::new(false));
    let events = Arc::new(std::sync::Mutex::new(Vec::new()));
    let arm = SlowBusArm {
        sim: SimArm::new(&robot, &a.sim, &initial_q(&robot, &a.sim)),
        fail: fail.clone(),
        reset_blocks: HOOK_BLOCKS,
        activate_blocks: HOOK_BLOCKS,
        events: events.clone(),
    };
    let mut c = ActuatorCore::new(arm, &robot, &cfg, &a).unwrap();
    let note = |e: &Arc<std::sync::Mutex<Vec<String>>>, h: LifecycleHook| {
        e.lock().unwrap().push(format!("announce {}", h.name()));
    };
    let t0 = 1000 * MS;
    // The first command activates (blocking).
    c.accept_torque_from(&torque(1, t0), 1, t0, || true, &mut |h| note(&events, h))
        .unwrap();
    let took = c.take_hook_ns();
    assert!(took >= HOOK_BLOCKS.as_nanos() as u64);
    let mut t = t0 + took;
    // The next ones run no hook, nor does a reset without a fault.
    c.accept_torque_from(&torque(2, t), 1, t, || true, &mut |h| note(&events, h))
        .unwrap();
    assert!(!c.reset(t, &mut |h| note(&events, h)));
    assert_eq!(
        *events.lock().unwrap(),
        ["announce on_activate", "on_activate"]
    );
    c.check_watchdog(t);
    c.step(t);
    assert_eq!(c.lifecycle(), LifecycleState::Active);
    // A bus fault, then a reset that blocks: announced first.
    fail.store(true, Ordering::Relaxed);
    t += MS;
    c.accept_torque(&torque(3, t), 1, t).unwrap();
    c.step(t);
    assert_eq!(c.lifecycle(), LifecycleState::Fault);
    events.lock().unwrap().clear();
    assert!(c.reset(t, &mut |h| note(&events, h)));
    assert_eq!(*events.lock().unwrap(), ["announce on_reset", "on_reset"]);
    t += c.take_hook_ns();
    // The activation after it, on the next fresh command, is announced too.
    events.lock().unwrap().clear();
    c.step(t);
    t += MS;
    c.accept_torque_from(&torque(4, t), 1, t, || true, &mut |h| note(&events, h))
        .unwrap();
    assert_eq!(
        *events.lock().unwrap(),
        ["announce on_activate", "on_activate"]
    );
    assert_eq!(c.lifecycle(), LifecycleState::Active);
}
