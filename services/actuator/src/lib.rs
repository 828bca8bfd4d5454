//! The actuator service: receives torque commands, applies them through an
//! [`ActuatorBackend`] (the simulated arm, or a real driver), publishes the measured
//! joint state, and keeps the arm safe on its own when commands stop.
//!
//! Clock modes:
//! * **free-running** (default, like hardware): the actuator's own timerfd ticks at
//!   `rate_hz`; each tick applies the newest valid torque (zero-order hold) for one period
//!   and publishes the state. Torque commands are received (and timed) as they arrive.
//! * **lockstep**: exactly one plant step of `1/rate_hz` per torque command, in order;
//!   nothing is dropped; the same inputs give bit-identical outputs. The timer then only
//!   runs the watchdog (and the plant, once the safe state has latched).
//!
//! The loop logic lives in [`ActuatorCore`] (no IPC), so an in-process replay of the
//! sampled loop runs exactly the code the process runs.

pub mod backend;
pub mod resume;
pub mod safety;
pub mod sim;

use anyhow::Context as _;
use iceoryx2::port::update_connections::UpdateConnections;
use microrobot_messages::{
    CommandKind, Header, JointSetpoint, JointState, LifecycleState, MAX_JOINTS, MotionCommand,
    ServiceKind, ServiceRole, ServiceStatus, TorqueCommand, monotonic_ns, open_event,
    open_publish_subscribe, state_flags,
};
use microrobot_model::{JointKind, JointVector, Robot};
use microrobot_runtime::config::PipelineConfig;
use microrobot_runtime::stats::LatencyHistogram;
use microrobot_runtime::validate::{Refusal, SeqTracker, check_fresh, check_torque};
use microrobot_runtime::watchdog::{Freshness, Watchdog};
use microrobot_runtime::{BadConfig, PeriodicClock, Reactor, Shutdown, StatusPort, open_node};

pub use backend::{ActuatorBackend, BackendError, Measured};
pub use resume::{RESUME_ENV, ResumeState};
pub use safety::{Mode, Safety};
pub use sim::SimArm;

/// Cumulative counters of the actuator (reported in its status).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Counters {
    /// Plant steps.
    pub cycles: u64,
    /// Torque commands refused (non-finite, wrong dof, out of order, stale).
    pub refused: u64,
    /// Steps taken while commands were stale (own hold) or the safe state was latched.
    pub stale_cycles: u64,
    /// Steps in which the backend saturated a torque.
    pub saturated_cycles: u64,
    /// Steps whose torque change was cut by the torque slope (`torque_slope_ms`).
    pub slope_limited_cycles: u64,
    /// Safe-state latches (and backend faults).
    pub faults: u64,
    /// Reset commands refused (e.g. commands not fresh yet).
    pub resets_refused: u64,
}

/// The actuator's loop logic, independent of IPC and clocks (time is passed in).
pub struct ActuatorCore<B: ActuatorBackend> {
    backend: B,
    safety: Safety,
    dof: usize,
    period_s: f64,
    lockstep: bool,
    auto_resume: bool,
    stale_ns: u64,
    watchdog: Watchdog,
    seq: SeqTracker,
    latest: Option<TorqueCommand>,
    latest_unapplied: bool,
    steps_on_latest: u64,
    state_seq: u64,
    last_measured: Measured,
    /// Counters for the status.
    pub counters: Counters,
    /// Largest |q_measured − q_desired| per joint (see [`ActuatorCore::step`]).
    pub tracking_error_max: [f64; MAX_JOINTS],
    /// Largest |τ applied| per joint.
    pub peak_torque: [f64; MAX_JOINTS],
    /// Why the last refused torque command was refused.
    pub last_refusal: Option<Refusal>,
}

impl<B: ActuatorBackend> ActuatorCore<B> {
    /// A core around a configured-or-not `backend`, with the nominal `model` for the
    /// safety layer's own control law.
    pub fn new(mut backend: B, model: &Robot, cfg: &PipelineConfig) -> Result<Self, BackendError> {
        if backend.lifecycle() == LifecycleState::Unconfigured {
            backend.configure()?;
        }
        let period_s = 1.0 / cfg.rate_hz;
        let ramp_steps = (cfg.watchdog.ramp_ms * 1e-3 / period_s).ceil() as u32;
        let last_measured = backend.read()?;
        let mut slope = JointVector::repeat(f64::INFINITY);
        if cfg.actuator.torque_slope_ms > 0.0 {
            let steps_per_full_scale = cfg.actuator.torque_slope_ms * 1e-3 / period_s;
            for (i, j) in model.joints().iter().enumerate().take(slope.len()) {
                slope[i] = j.limits.effort / steps_per_full_scale;
            }
        }
        Ok(Self {
            dof: backend.dof(),
            safety: Safety::new(
                model,
                cfg.actuator.hold_kp_per_s2,
                cfg.actuator.hold_kd_per_s,
                cfg.watchdog.safe_state,
                ramp_steps,
            )
            .with_slope(&slope),
            backend,
            period_s,
            lockstep: cfg.lockstep,
            auto_resume: cfg.watchdog.auto_resume,
            stale_ns: cfg.watchdog.stale_ns(),
            watchdog: Watchdog::new(cfg.watchdog.stale_ms, cfg.watchdog.fault_ms),
            seq: SeqTracker::new(cfg.watchdog.stale_ns()),
            latest: None,
            latest_unapplied: false,
            steps_on_latest: 0,
            state_seq: 0,
            last_measured,
            counters: Counters::default(),
            tracking_error_max: [0.0; MAX_JOINTS],
            peak_torque: [0.0; MAX_JOINTS],
            last_refusal: None,
        })
    }

    /// The backend (e.g. to read the simulation's true state).
    pub fn backend(&self) -> &B {
        &self.backend
    }

    /// Sequence gaps seen on the torque stream.
    pub fn lost_messages(&self) -> u64 {
        self.seq.lost
    }

    /// Whether the safe state is latched.
    pub fn safe_state_latched(&self) -> bool {
        self.safety.latched()
    }

    /// Logical time of the last command (tick × period, s).
    pub fn motion_time_s(&self) -> f64 {
        self.latest
            .map(|c| c.header.tick as f64 * self.period_s)
            .unwrap_or(0.0)
    }

    /// The lifecycle to report: Fault while the safe state is latched.
    pub fn lifecycle(&self) -> LifecycleState {
        if self.safety.latched() {
            LifecycleState::Fault
        } else {
            self.backend.lifecycle()
        }
    }

    /// Validates a received torque command (from iceoryx2 publisher `publisher`) and,
    /// when good, makes it the command to apply. Freshness is judged on the wall clock
    /// only when not in lockstep (in lockstep the logical tick governs).
    pub fn accept_torque(
        &mut self,
        msg: &TorqueCommand,
        publisher: u128,
        now_ns: u64,
    ) -> Result<(), Refusal> {
        let r = check_torque(msg, self.dof)
            .and_then(|()| {
                if self.lockstep {
                    Ok(())
                } else {
                    check_fresh(msg.header.stamp_ns, now_ns, self.stale_ns)
                }
            })
            .and_then(|()| self.seq.accept(publisher, msg.header.seq, now_ns));
        match r {
            Ok(()) => {
                self.latest = Some(*msg);
                self.latest_unapplied = true;
                self.watchdog.feed(now_ns);
                if self.backend.lifecycle() == LifecycleState::Inactive
                    && !self.safety.latched()
                    && self.backend.activate().is_ok()
                {
                    self.safety.on_switch_on();
                }
                Ok(())
            }
            Err(e) => {
                self.counters.refused += 1;
                self.last_refusal = Some(e);
                Err(e)
            }
        }
    }

    /// Runs the watchdog at `now_ns`: stale → own hold (free-running only), fault →
    /// latch the safe state; fresh again → follow commands (or auto-resume).
    pub fn check_watchdog(&mut self, now_ns: u64) {
        let q = self.last_measured.q;
        match self.watchdog.check(now_ns) {
            Freshness::Waiting => {}
            Freshness::Fresh => {
                if self.safety.latched() {
                    if self.auto_resume {
                        self.safety.reset(&q);
                    }
                } else {
                    self.safety.on_fresh(&q);
                }
            }
            Freshness::Stale => {
                if !self.lockstep {
                    self.safety.on_stale(&q);
                }
            }
            Freshness::Fault => {
                if !self.safety.latched() && self.backend.lifecycle() == LifecycleState::Active {
                    self.counters.faults += 1;
                    self.safety.on_fault(&q);
                }
            }
        }
    }

    /// A Reset command: leaves the safe state (bumplessly, blended) if commands are
    /// fresh, and acknowledges a backend fault. Returns whether anything was reset.
    pub fn reset(&mut self, now_ns: u64) -> bool {
        let mut did = false;
        if self.backend.lifecycle() == LifecycleState::Fault && self.backend.reset_fault().is_ok() {
            did = true;
        }
        if self.safety.latched() {
            if self.watchdog.check(now_ns) == Freshness::Fresh {
                self.safety.reset(&self.last_measured.q);
                did = true;
            } else {
                self.counters.resets_refused += 1;
            }
        }
        did
    }

    /// A restart: continues from `tau`, the torque the predecessor applied last (blended,
    /// never a step), and with `latch` comes up in the safe state, holding the measured
    /// position, active, until a Reset (or `auto_resume` on fresh commands).
    pub fn resume_after_restart(&mut self, tau: &JointVector, latch: bool) {
        let mut t = *tau;
        for i in self.dof..t.len() {
            t[i] = 0.0;
        }
        self.safety.blend_from(&t);
        if latch {
            if self.backend.lifecycle() == LifecycleState::Inactive {
                let _ = self.backend.activate();
            }
            self.counters.faults += 1;
            self.safety.on_fault(&self.last_measured.q);
            // `on_fault` blends from the last applied torque, which is `t`.
        }
    }

    /// Whether the plant is stepped by the actuator's own timer (free-running, or the
    /// safe state in lockstep).
    pub fn steps_on_timer(&self) -> bool {
        !self.lockstep || self.safety.latched()
    }

    /// One plant step of one period: the applied torque is the newest command (mode
    /// Command) or the safety layer's own law, blended after a switch. Returns the
    /// state message to publish (stamped `now_ns`).
    ///
    /// Tracking error: for the first step that applies torque command k, the error is
    /// |q measured after the step − q_desired of command k| per joint, i.e. the
    /// measured position at the end of the period the command was computed for, against
    /// setpoint k's position — the same logical time (tick k) in lockstep.
    pub fn step(&mut self, now_ns: u64) -> JointState {
        let active = self.backend.lifecycle() == LifecycleState::Active;
        let use_cmd = self.safety.mode() == Mode::Command && self.latest.is_some();
        let mut fresh_cmd = None;
        if active {
            let cmd_tau = self.latest.map(|c| JointVector::from_column_slice(&c.tau));
            let q = self.last_measured.q;
            let qd = self.last_measured.qd;
            let tau = self.safety.torque(cmd_tau.as_ref(), &q, &qd);
            if self.safety.slope_limited() {
                self.counters.slope_limited_cycles += 1;
            }
            if self.backend.write(&tau, self.period_s).is_err() {
                self.counters.faults += 1;
            }
            if use_cmd && self.latest_unapplied {
                fresh_cmd = self.latest;
                self.steps_on_latest = 0;
            }
            self.steps_on_latest += 1;
            self.latest_unapplied = false;
        }
        if let Ok(m) = self.backend.read() {
            self.last_measured = m;
        }
        let m = self.last_measured;
        self.counters.cycles += 1;
        if active && !use_cmd {
            self.counters.stale_cycles += 1;
        }
        if m.saturated && active {
            self.counters.saturated_cycles += 1;
        }
        for i in 0..self.dof {
            self.peak_torque[i] = self.peak_torque[i].max(m.tau_applied[i].abs());
        }
        if let Some(c) = fresh_cmd {
            for i in 0..self.dof {
                let e = (m.q[i] - c.q_desired[i]).abs();
                if e > self.tracking_error_max[i] {
                    self.tracking_error_max[i] = e;
                }
            }
        }
        self.state_message(now_ns)
    }

    /// Shutdown: the backend goes Inactive (drives disabled, brakes on) if it was
    /// active, and the returned last state message says so (lifecycle Inactive). Called
    /// on every clean stop, including SIGTERM from a dead supervisor (PDEATHSIG).
    pub fn shutdown(&mut self, now_ns: u64) -> JointState {
        if self.backend.lifecycle() == LifecycleState::Active && self.backend.deactivate().is_err()
        {
            self.counters.faults += 1;
        }
        if let Ok(m) = self.backend.read() {
            self.last_measured = m;
        }
        let mut s = self.state_message(now_ns);
        s.flags |= state_flags::FINAL;
        s
    }

    /// The current measured state as a message (also used for the initial state).
    pub fn state_message(&mut self, now_ns: u64) -> JointState {
        self.state_seq += 1;
        let m = &self.last_measured;
        let mut s = JointState {
            header: Header {
                seq: self.state_seq,
                // The tick whose period this state ends: the command's tick, plus one per
                // extra period the command was held (free-running, a late setpoint).
                tick: self
                    .latest
                    .map(|c| c.header.tick + self.steps_on_latest.saturating_sub(1))
                    .unwrap_or(0),
                stamp_ns: now_ns,
                source_stamp_ns: self.latest.map(|c| c.header.source_stamp_ns).unwrap_or(0),
            },
            torque_seq: self.latest.map(|c| c.header.seq).unwrap_or(u64::MAX),
            dof: self.dof as u32,
            lifecycle: self.lifecycle() as u32,
            ..Default::default()
        };
        s.q[..self.dof].copy_from_slice(&m.q.as_slice()[..self.dof]);
        s.qd[..self.dof].copy_from_slice(&m.qd.as_slice()[..self.dof]);
        s.tau_applied[..self.dof].copy_from_slice(&m.tau_applied.as_slice()[..self.dof]);
        if self.safety.latched() {
            s.flags |= state_flags::SAFE_STATE;
        }
        if self.safety.mode() == Mode::StaleHold {
            s.flags |= state_flags::COMMAND_STALE;
        }
        if m.saturated {
            s.flags |= state_flags::SATURATED;
        }
        if self.safety.slope_limited() {
            s.flags |= state_flags::SLOPE_LIMITED;
        }
        s
    }
}

/// The robot's initial joint vector from `initial_q_deg` (deg for revolute, mm for prismatic).
pub fn initial_q(robot: &Robot, cfg: &PipelineConfig) -> JointVector {
    let mut q = JointVector::zeros();
    if let Some(v) = &cfg.actuator.sim.initial_q_deg {
        for (i, j) in robot.joints().iter().enumerate() {
            let x = v.get(i).copied().unwrap_or(0.0);
            q[i] = match j.kind {
                JointKind::Revolute => x.to_radians(),
                JointKind::Prismatic => x * 1e-3,
            };
        }
    }
    q
}

/// Loads the robot file named by the config (a bad file is a config error).
pub fn load_robot(cfg: &PipelineConfig) -> anyhow::Result<Robot> {
    Robot::from_file(&cfg.robot).map_err(|e| BadConfig(format!("robot file: {e}")).into())
}

/// How long a (re)started actuator listens for the planner's last setpoint to resume
/// the arm where it was instead of at `initial_q_deg`.
const RESUME_PROBE_MS: u64 = 200;

/// The actuator service (`microrobot service actuator`).
pub fn run(cfg: &PipelineConfig, shutdown: &Shutdown) -> anyhow::Result<()> {
    let robot = load_robot(cfg)?;
    let dof = robot.dof();
    let inst = cfg.instance.as_str();
    let node = open_node(inst, ServiceRole::Actuator)?;

    let torque_sub = open_publish_subscribe::<TorqueCommand>(&node, inst, ServiceKind::Torque)?
        .subscriber_builder()
        .buffer_size(microrobot_messages::ports::qos::SUBSCRIBER_BUFFER)
        .history_request(0)
        .create()
        .map_err(|e| anyhow::anyhow!("torque subscriber: {e:?}"))?;
    let torque_listener = open_event(&node, inst, ServiceKind::Torque)?
        .listener_builder()
        .create()
        .map_err(|e| anyhow::anyhow!("torque listener: {e:?}"))?;
    let state_pub = open_publish_subscribe::<JointState>(&node, inst, ServiceKind::State)?
        .publisher_builder()
        .create()
        .map_err(|e| anyhow::anyhow!("state publisher: {e:?}"))?;
    let state_notifier = open_event(&node, inst, ServiceKind::State)?
        .notifier_builder()
        .create()
        .map_err(|e| anyhow::anyhow!("state notifier: {e:?}"))?;
    let cmd_sub = open_publish_subscribe::<MotionCommand>(&node, inst, ServiceKind::Command)?
        .subscriber_builder()
        .history_request(0)
        .create()
        .map_err(|e| anyhow::anyhow!("command subscriber: {e:?}"))?;
    let cmd_listener = open_event(&node, inst, ServiceKind::Command)?
        .listener_builder()
        .create()
        .map_err(|e| anyhow::anyhow!("command listener: {e:?}"))?;
    let sp_sub = open_publish_subscribe::<JointSetpoint>(&node, inst, ServiceKind::Setpoint)?
        .subscriber_builder()
        .history_request(1)
        .create()
        .map_err(|e| anyhow::anyhow!("setpoint subscriber: {e:?}"))?;
    let mut status = StatusPort::open(&node, inst, ServiceRole::Actuator, cfg.status_period_ms)?;

    // Resume where the arm is: the predecessor's last published state (handed over by
    // the supervisor after a restart), else a running planner's last setpoint, else the
    // config.
    let resume = ResumeState::from_env(&robot).map_err(BadConfig)?;
    let mut q0 = initial_q(&robot, cfg);
    if let Some(r) = &resume {
        q0 = r.q;
        tracing::info!(
            "actuator: restarted; resuming the arm at its last published state{}",
            if cfg.watchdog.auto_resume {
                ""
            } else {
                " in the safe state (send a reset to resume)"
            }
        );
    }
    let probe_end = monotonic_ns() + RESUME_PROBE_MS * 1_000_000;
    'probe: while resume.is_none() && monotonic_ns() < probe_end && !shutdown.is_requested() {
        while let Ok(Some(s)) = sp_sub.receive() {
            if s.dof as usize == dof && microrobot_messages::all_finite(&s.q, s.dof) {
                q0 = JointVector::from_column_slice(&s.q);
                tracing::info!("actuator: resuming the arm at the planner's last setpoint");
                break 'probe;
            }
        }
        std::thread::sleep(std::time::Duration::from_millis(5));
    }
    drop(sp_sub);

    let mut sim = SimArm::new(&robot, &cfg.actuator.sim, &q0);
    if let Some(r) = &resume {
        sim.set_state(&r.q, &r.qd);
    }
    let mut core = ActuatorCore::new(sim, &robot, cfg).context("simulated arm")?;
    if let Some(r) = &resume {
        core.resume_after_restart(&r.tau, !cfg.watchdog.auto_resume);
    }
    let mut e2e = LatencyHistogram::new();

    let PeriodicClock { timer, mut ticker } =
        PeriodicClock::start(cfg.period_ns(), cfg.realtime.overrun)?;
    let mut reactor = Reactor::new().context("epoll")?;
    let on_torque = reactor.add(&torque_listener).context("epoll")?;
    let on_command = reactor.add(&cmd_listener).context("epoll")?;
    let on_timer = reactor.add(&timer).context("epoll")?;
    let on_stop = reactor.add(shutdown).context("epoll")?;

    // Free-running with the planner on its own timer, the plant steps are phased half a
    // period after the planner's ticks (below). When the planner ticks on states, this
    // timer is the pipeline's master clock and is left where it is.
    let mut phased = cfg.planner_ticks_on_states();
    let publish = |s: JointState| {
        let ok = state_pub.send_copy(s).is_ok();
        let _ = state_notifier.notify();
        ok
    };
    // Initial state (history 1 on State: the planner starts from it).
    publish(core.state_message(monotonic_ns()));

    let mut st = ServiceStatus {
        ready: 1,
        ..Default::default()
    };
    let fill = |st: &mut ServiceStatus,
                core: &ActuatorCore<SimArm>,
                e2e: &LatencyHistogram,
                ticker_misses: u64| {
        st.lifecycle = core.lifecycle() as u32;
        st.cycles = core.counters.cycles;
        st.deadline_misses = ticker_misses;
        st.lost_messages = core.lost_messages();
        st.refused_messages = core.counters.refused + core.counters.resets_refused;
        st.stale_cycles = core.counters.stale_cycles;
        st.clamped_cycles = core.counters.saturated_cycles + core.counters.slope_limited_cycles;
        st.faults = core.counters.faults;
        st.motion_time_s = core.motion_time_s();
        st.latency = e2e.summary();
        st.tracking_error_max = core.tracking_error_max;
        st.peak_torque = core.peak_torque;
        st.last_input_refusal = core
            .last_refusal
            .map_or(microrobot_messages::RefusalReason::None, Refusal::reason)
            as u32;
    };
    fill(&mut st, &core, &e2e, 0);
    status.publish(monotonic_ns(), &mut st);

    // Set up: from here on the loop runs pinned and SCHED_FIFO.
    microrobot_runtime::enter_cycle(cfg);
    while !shutdown.is_requested() {
        let ready = reactor.wait().context("epoll_wait")?;
        if ready.contains(on_stop) || shutdown.is_requested() {
            break;
        }
        if ready.contains(on_torque) {
            let _ = torque_listener.try_wait(|_| {});
            while let Ok(Some(sample)) = torque_sub.receive() {
                let msg = *sample;
                let publisher = sample.header().publisher_id().value();
                drop(sample);
                let now = monotonic_ns();
                if core.accept_torque(&msg, publisher, now).is_ok() {
                    e2e.record(now.saturating_sub(msg.header.source_stamp_ns));
                    if !cfg.lockstep && !phased {
                        // Free-running: put the plant steps half a period after the
                        // planner's ticks, so torque k is applied in the step that ends
                        // before setpoint k+1 (the same one-period loop delay as lockstep).
                        phased = true;
                        let p = cfg.period_ns();
                        let mut first = msg.header.source_stamp_ns + p / 2;
                        while first <= now {
                            first += p;
                        }
                        if timer.arm_absolute(first, p).is_ok() {
                            let _ = timer.read_expirations();
                            ticker =
                                microrobot_runtime::Ticker::new(first, p, cfg.realtime.overrun);
                        }
                    }
                    if !core.steps_on_timer() {
                        core.check_watchdog(now);
                        publish(core.step(monotonic_ns()));
                    }
                }
            }
        }
        // Drained on every wake-up (see the planner: a new sender's sample can become
        // visible after its notification).
        {
            if ready.contains(on_command) {
                let _ = cmd_listener.try_wait(|_| {});
            }
            while let Ok(Some(sample)) = cmd_sub.receive() {
                if CommandKind::from_wire(sample.kind) == Some(CommandKind::Reset)
                    && core.reset(monotonic_ns())
                {
                    tracing::info!("actuator: reset, following torque commands again");
                }
            }
        }
        if ready.contains(on_timer) {
            ticker.on_expirations(timer.read_expirations());
            // Hands the last state (history 1) to subscribers that joined since the last
            // send: in lockstep nothing is sent until the first torque, and the planner
            // starts from that state.
            let _ = state_pub.update_connections();
            let mut n = 0;
            while ticker.next_tick().is_some() {
                let now = monotonic_ns();
                let was_latched = core.safe_state_latched();
                core.check_watchdog(now);
                if core.safe_state_latched() && !was_latched {
                    tracing::warn!(
                        "actuator: no valid torque command for {} ms: safe state latched ({:?}); send a reset to resume",
                        cfg.watchdog.fault_ms,
                        cfg.watchdog.safe_state
                    );
                }
                if core.steps_on_timer() && n < 100 {
                    publish(core.step(now));
                    n += 1;
                }
            }
        }
        let now = monotonic_ns();
        if status.due(now) {
            fill(&mut st, &core, &e2e, 0);
            status.publish(now, &mut st);
        }
    }
    // Safe on the way out, however the stop was asked for (Ctrl-C, SIGTERM, the
    // supervisor's death): brakes on, and the last state says so.
    publish(core.shutdown(monotonic_ns()));
    tracing::info!("actuator: stopped, backend inactive (drives disabled)");
    fill(&mut st, &core, &e2e, 0);
    status.publish_final(&mut st);
    Ok(())
}
