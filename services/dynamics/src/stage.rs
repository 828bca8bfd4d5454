//! The dynamics service's stage: woken by each setpoint, it takes the newest measured
//! states, computes the torque ([`DynamicsCore`]) and publishes it; a status-period timer
//! keeps the state queue short and counts periods without setpoints.

use microrobot_messages::{
    JointSetpoint, JointState, LifecycleState, RefusalReason, ServiceRole, ServiceStatus,
    TorqueCommand, monotonic_ns, topic,
};
use microrobot_runtime::config::{OwnedSection, PipelineConfig};
use microrobot_runtime::stats::LatencyHistogram;
use microrobot_runtime::validate::Refusal;
use microrobot_runtime::{
    BadConfig, Cycle, Inbox, Outbox, Reactor, Ready, Received, Shutdown, Source, Stage,
    Subscription, TimerFd, serve,
};

use crate::{DynamicsConfig, DynamicsCore};

/// The dynamics service (`microrobot-dynamics`).
pub fn run(cfg: &PipelineConfig, shutdown: &Shutdown) -> anyhow::Result<()> {
    let robot = microrobot_model::Robot::from_file(&cfg.robot)
        .map_err(|e| BadConfig(format!("robot file: {e}")))?;
    let dynamics = DynamicsConfig::from_pipeline(cfg).map_err(|e| BadConfig(e.to_string()))?;
    serve(cfg, shutdown, ServiceRole::Dynamics, |setup| {
        let inst = setup.instance();
        let ports = Ports {
            setpoints: Inbox::open(setup.node, inst, topic::SETPOINT, Subscription::CYCLIC)?,
            states: Inbox::open(
                setup.node,
                inst,
                topic::STATE,
                Subscription::CYCLIC.with_history(1).polled(),
            )?,
            torques: Outbox::open(setup.node, inst, topic::TORQUE)?,
            timer: TimerFd::new()?,
        };
        let period = microrobot_runtime::config::ms_to_ns(cfg.status_period_ms);
        ports.timer.arm_absolute(monotonic_ns() + period, period)?;
        let stage = DynamicsStage {
            core: DynamicsCore::new(&robot, cfg, &dynamics),
            latency: LatencyHistogram::new(),
            setpoint_to_awake: LatencyHistogram::new(),
            awake_to_torque: LatencyHistogram::new(),
            last_setpoint_ns: monotonic_ns(),
            input_stale_periods: 0,
            rate_hz: cfg.rate_hz,
        };
        Ok(Some((stage, ports)))
    })
}

/// The ports of the dynamics stage.
struct Ports {
    setpoints: Inbox<JointSetpoint>,
    states: Inbox<JointState>,
    torques: Outbox<TorqueCommand>,
    /// At the status period: drains states, counts periods without setpoints.
    timer: TimerFd,
}

#[derive(Clone, Copy)]
struct Sources {
    setpoint: Source,
    timer: Source,
}

struct DynamicsStage {
    core: DynamicsCore,
    /// Setpoint source stamp → torque published.
    latency: LatencyHistogram,
    /// Its two hops, which add up to it sample by sample: setpoint source stamp → the
    /// wake-up that took the setpoint, and that wake-up → torque stamp (the lockstep
    /// wait for the measured state, the computation, the write).
    setpoint_to_awake: LatencyHistogram,
    awake_to_torque: LatencyHistogram,
    last_setpoint_ns: u64,
    /// Status periods that ended without a setpoint for longer than `stale_ms`.
    input_stale_periods: u64,
    rate_hz: f64,
}

impl DynamicsStage {
    /// Takes every queued measured state (the newest valid one is used).
    fn take_states(&mut self, states: &Inbox<JointState>) {
        states.for_each(|r| self.take_state(&r));
    }

    /// Validates one measured state and keeps it if valid (refusals are counted by the
    /// core).
    fn take_state(&mut self, r: &Received<'_, JointState>) {
        let _ = self
            .core
            .accept_state_from(&r.msg, r.publisher, monotonic_ns(), || r.from_pipeline());
    }

    /// Lockstep: setpoint `tick` needs measured state `tick − 1`. Its delivery to this
    /// subscriber can trail the planner's (the actuator may be preempted between
    /// subscribers on a shared CPU): wait for it, yielding, up to `fault_ms` (after which
    /// the actuator has latched its safe state anyway) or until a stop is asked for.
    fn await_state_for(&mut self, tick: u64, states: &Inbox<JointState>, cycle: &Cycle<'_>) {
        let give_up = monotonic_ns() + cycle.cfg.watchdog.fault_ns();
        loop {
            let arrived = self
                .core
                .state_tick()
                .is_some_and(|t| t.saturating_add(1) >= tick);
            if arrived || cycle.shutdown.is_requested() {
                return;
            }
            if monotonic_ns() >= give_up {
                // At most once per `fault_ms`: the wait was that long.
                tracing::warn!(
                    "dynamics: lockstep setpoint of tick {tick} found no measured state of tick {} within fault_ms (newest: {:?})",
                    tick.saturating_sub(1),
                    self.core.state_tick()
                );
                return;
            }
            match states.next() {
                Some(r) => self.take_state(&r),
                None => std::thread::yield_now(),
            }
        }
    }

    /// Answers every queued setpoint with its torque command (awake at `woke` for the
    /// setpoints published before it).
    fn answer_setpoints(&mut self, ports: &Ports, woke: u64, cycle: &Cycle<'_>) {
        let cfg = cycle.cfg;
        // Once a stop is asked for, nothing new is computed (a torque from a state
        // the shutdown cut off would differ from run to run).
        while !cycle.shutdown.is_requested() {
            let Some(r) = ports.setpoints.next() else {
                break;
            };
            let sp = r.msg;
            let source = sp.header.source_stamp_ns;
            // Awake for this setpoint: at the wake-up, or, for one published after
            // it and taken in the same drain, when taken.
            let awake = if source <= woke { woke } else { monotonic_ns() };
            if cfg.lockstep {
                self.await_state_for(sp.header.tick, &ports.states, cycle);
                if cycle.shutdown.is_requested() {
                    break;
                }
            }
            let now = monotonic_ns();
            self.last_setpoint_ns = now;
            let taken = self
                .core
                .compute_from(&sp, r.publisher, now, || r.from_pipeline());
            if let Ok(mut cmd) = taken {
                cmd.header.stamp_ns = monotonic_ns();
                ports.torques.send(cmd);
                let stamp = cmd.header.stamp_ns;
                self.latency.record(stamp.saturating_sub(source));
                self.setpoint_to_awake.record(awake.saturating_sub(source));
                self.awake_to_torque.record(stamp.saturating_sub(awake));
            }
        }
    }
}

impl Stage for DynamicsStage {
    type Ports = Ports;
    type Sources = Sources;

    fn register<'p>(ports: &'p Ports, reactor: &mut Reactor<'p>) -> std::io::Result<Sources> {
        Ok(Sources {
            setpoint: ports.setpoints.wake_on(reactor)?,
            timer: reactor.add(&ports.timer)?,
        })
    }

    fn wake(
        &mut self,
        ports: &Ports,
        on: Sources,
        ready: Ready,
        cycle: &mut Cycle<'_>,
    ) -> anyhow::Result<()> {
        let cfg = cycle.cfg;
        if ready.contains(on.setpoint) {
            let woke = monotonic_ns();
            self.take_states(&ports.states);
            // The drain rule (see `Inbox::drain`): the setpoints, then the wake-ups, then
            // the setpoints that came meanwhile; the wake-ups' read is not between the
            // wake-up and the torque.
            self.answer_setpoints(ports, woke, cycle);
            ports.setpoints.clear_events();
            self.answer_setpoints(ports, woke, cycle);
        }
        if ready.contains(on.timer) {
            let _ = ports.timer.read_expirations();
            // Keep the state queue short even when no setpoint arrives.
            self.take_states(&ports.states);
            let now = monotonic_ns();
            if !cfg.lockstep && now.saturating_sub(self.last_setpoint_ns) > cfg.watchdog.stale_ns()
            {
                self.input_stale_periods += 1;
            }
        }
        Ok(())
    }

    fn report(&self, st: &mut ServiceStatus) {
        let core = &self.core;
        st.ready = 1;
        st.lifecycle = LifecycleState::Active as u32;
        st.cycles = core.counters.cycles;
        st.lost_messages = core.lost_messages();
        st.refused_messages = core.counters.refused;
        st.stale_cycles = core.counters.stale_cycles + self.input_stale_periods;
        // Effort clamps and slew limits together (the torque flags tell them apart).
        st.clamped_cycles = core.counters.clamped_cycles + core.counters.slew_limited_cycles;
        st.peak_torque = core.peak_torque;
        st.motion_time_s = core.last_tick().unwrap_or(0) as f64 / self.rate_hz;
        st.last_input_refusal = core
            .last_refusal
            .map_or(RefusalReason::None, Refusal::reason) as u32;
    }

    fn report_latency(&self, st: &mut ServiceStatus) {
        st.latency = self.latency.summary();
        st.latency_sum_ns = self.latency.sum_ns();
        st.hops = [
            self.setpoint_to_awake.hop_latency(),
            self.awake_to_torque.hop_latency(),
        ];
    }
}
