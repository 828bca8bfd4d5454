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
//! sampled loop runs exactly the code the process runs; [`serve`] is the process around
//! it, for any [`ActuatorBackend`] (the simulated arm's [`run`] is one call of it).
//!
//! A stall (the process frozen or late for longer than `stale_ms`, free-running): the
//! missed plant periods are not replayed, the actuator holds with its own law from the
//! measured state (flag `STALLED`), and it follows torque commands again only once one
//! arrives that was computed from a state it published after the stall — never one
//! older than `stale_ms`, never one that answers a state from before the stall. A stall
//! longer than `fault_ms` latches the safe state like any other silence that long. See
//! [`ActuatorCore::on_wake`].

pub mod backend;
pub mod config;
pub mod lifecycle;
pub mod plant;
pub mod resume;
pub mod safety;
mod serve;
pub mod sim;

use microrobot_messages::{
    Header, JointState, LifecycleHook, LifecycleState, MAX_JOINTS, TorqueCommand, state_flags,
    torque_flags,
};
use microrobot_model::{JointKind, JointVector, Robot};
use microrobot_runtime::config::PipelineConfig;
use microrobot_runtime::validate::{Refusal, SeqTracker, check_fresh, check_torque};
use microrobot_runtime::watchdog::{Freshness, Watchdog};
use microrobot_runtime::{BadConfig, Shutdown};

pub use backend::{ActuatorBackend, Fault, Measured};
pub use config::{ActuatorConfig, SimConfig};
pub use lifecycle::Lifecycle;
pub use resume::{RESUME_ENV, ResumeState};
pub use safety::{Mode, Safety};
pub use serve::{Setup, StartFrom, StartState, serve};
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
    /// Stalls: the loop did not run for longer than `stale_ms` (free-running).
    pub stalls: u64,
}

/// The actuator's loop logic, independent of IPC and clocks (time is passed in).
pub struct ActuatorCore<B: ActuatorBackend> {
    hw: Lifecycle<B>,
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
    /// Backend faults already counted in `counters.faults`.
    hw_faults_counted: u64,
    /// Wall time of the last plant step (free-running stall detection).
    last_step_ns: Option<u64>,
    /// After a stall: the first state published after it; commands answering an older
    /// state are not followed. `None` when no stall is pending.
    resync_state_seq: Option<u64>,
    /// The length of the last stall (ns).
    last_stall_ns: u64,
    /// Wall time spent inside lifecycle hooks, not yet taken by the stage.
    hook_ns: u64,
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
    /// A core around an unconfigured `backend` (configured here), with the nominal
    /// `model` for the safety layer's own control law, the `[actuator]` settings of
    /// `actuator` and the rate and watchdog settings of `cfg`. Refuses a backend that
    /// drives another number of joints than `model` has.
    pub fn new(
        backend: B,
        model: &Robot,
        cfg: &PipelineConfig,
        actuator: &ActuatorConfig,
    ) -> Result<Self, Fault> {
        if backend.dof() != model.dof() {
            return Err(Fault {
                joint: None,
                code: 0,
                text: format!(
                    "the backend drives {} joints, the robot `{}` has {}",
                    backend.dof(),
                    model.name(),
                    model.dof()
                )
                .into(),
            });
        }
        let mut hw = Lifecycle::new(backend);
        hw.configure()?;
        // Configuring is before the cycle starts: nothing to restart.
        hw.take_hook_ns();
        let period_s = 1.0 / cfg.rate_hz;
        let ramp_steps = (cfg.watchdog.ramp_ms * 1e-3 / period_s).ceil() as u32;
        let last_measured = match hw.read(0) {
            Some(m) => m,
            None => {
                return Err(hw
                    .last_fault()
                    .cloned()
                    .unwrap_or_else(|| Fault::drive(0, "the first read failed")));
            }
        };
        let mut slope = JointVector::repeat(f64::INFINITY);
        if actuator.torque_slope_ms > 0.0 {
            let steps_per_full_scale = actuator.torque_slope_ms * 1e-3 / period_s;
            for (i, j) in model.joints().iter().enumerate().take(slope.len()) {
                slope[i] = j.limits.effort / steps_per_full_scale;
            }
        }
        Ok(Self {
            dof: model.dof(),
            safety: Safety::new(
                model,
                actuator.hold_kp_per_s2,
                actuator.hold_kd_per_s,
                cfg.watchdog.safe_state,
                ramp_steps,
            )
            .with_slope(&slope),
            hw,
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
            hw_faults_counted: 0,
            last_step_ns: None,
            resync_state_seq: None,
            last_stall_ns: 0,
            hook_ns: 0,
            counters: Counters::default(),
            tracking_error_max: [0.0; MAX_JOINTS],
            peak_torque: [0.0; MAX_JOINTS],
            last_refusal: None,
        })
    }

    /// The backend (e.g. to read the simulation's true state).
    pub fn backend(&self) -> &B {
        self.hw.backend()
    }

    /// The backend's last fault (kept after a reset, for the status).
    pub fn last_fault(&self) -> Option<&Fault> {
        self.hw.last_fault()
    }

    /// Faults the backend entered so far.
    pub fn backend_faults(&self) -> u64 {
        self.hw.faults()
    }

    /// Whether a stall is pending: holding until a command computed from a state
    /// published after it arrives.
    pub fn stalled(&self) -> bool {
        self.resync_state_seq.is_some()
    }

    /// Counts backend faults not counted yet.
    fn count_backend_faults(&mut self) {
        let n = self.hw.faults();
        self.counters.faults += n - self.hw_faults_counted;
        self.hw_faults_counted = n;
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
            self.hw.state()
        }
    }

    /// Validates a received torque command (from iceoryx2 publisher `publisher`) and,
    /// when good, makes it the command to apply. Freshness is judged on the wall clock
    /// only when not in lockstep (in lockstep the logical tick governs). After a stall
    /// ([`ActuatorCore::on_wake`]) a command that answers a state from before it (or that
    /// the dynamics computed without feedback it wanted: `STATE_STALE`) is refused as
    /// stale: it would correct an error the arm no longer has.
    pub fn accept_torque(
        &mut self,
        msg: &TorqueCommand,
        publisher: u128,
        now_ns: u64,
    ) -> Result<(), Refusal> {
        self.accept_torque_from(msg, publisher, now_ns, || true, &mut |_| {})
    }

    /// [`Self::accept_torque`], where a well-formed command from a publisher the stream
    /// does not follow yet is taken only if `from_pipeline()` says the pipeline's
    /// supervisor started its process (the stage asks [`microrobot_runtime::provenance`]).
    /// One that is not is refused ([`Refusal::Outsider`]) and, with the drives on,
    /// latches the safe state: someone is trying to drive the arm. `announce` is called
    /// just before a lifecycle hook that blocks the cycle runs (the activation a first
    /// accepted command starts), so the stage can say so in its status first.
    pub fn accept_torque_from(
        &mut self,
        msg: &TorqueCommand,
        publisher: u128,
        now_ns: u64,
        from_pipeline: impl FnOnce() -> bool,
        announce: &mut dyn FnMut(LifecycleHook),
    ) -> Result<(), Refusal> {
        self.detect_stall(now_ns);
        let r = check_torque(msg, self.dof)
            .and_then(|()| {
                if self.lockstep {
                    Ok(())
                } else {
                    check_fresh(msg.header.stamp_ns, now_ns, self.stale_ns)
                }
            })
            .and_then(|()| {
                if self.seq.is_new_publisher(publisher) && !from_pipeline() {
                    if !self.safety.latched() && self.hw.state() == LifecycleState::Active {
                        self.counters.faults += 1;
                        let q = self.last_measured.q;
                        self.safety.on_fault(&q);
                    }
                    Err(Refusal::Outsider)
                } else {
                    Ok(())
                }
            })
            .and_then(|()| self.seq.accept(publisher, msg.header.seq, now_ns))
            .and_then(|()| match self.resync_state_seq {
                Some(first) if !self.lockstep => {
                    let wanted_feedback_missing = msg.flags & torque_flags::STATE_STALE != 0;
                    let answers_old_state = msg.state_seq != u64::MAX && msg.state_seq < first;
                    if wanted_feedback_missing || answers_old_state {
                        Err(Refusal::Stale)
                    } else {
                        self.resync_state_seq = None;
                        Ok(())
                    }
                }
                _ => Ok(()),
            });
        match r {
            Ok(()) => {
                self.latest = Some(*msg);
                self.latest_unapplied = true;
                self.watchdog.feed(now_ns);
                if self.hw.state() == LifecycleState::Inactive
                    && !self.safety.latched()
                    && self.hw.activate(announce)
                {
                    self.safety.on_switch_on();
                }
                self.after_hooks();
                self.count_backend_faults();
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
                if !self.safety.latched() && self.hw.state() == LifecycleState::Active {
                    self.counters.faults += 1;
                    self.safety.on_fault(&q);
                }
            }
        }
    }

    /// A Reset command: leaves the safe state (bumplessly, blended) if commands are
    /// fresh, and acknowledges a backend fault. Returns whether anything was reset.
    /// `announce` is called just before the backend's `on_reset` runs.
    pub fn reset(&mut self, now_ns: u64, announce: &mut dyn FnMut(LifecycleHook)) -> bool {
        let mut did = false;
        if self.hw.state() == LifecycleState::Fault && self.hw.reset_fault(announce) {
            did = true;
        }
        self.count_backend_faults();
        if self.safety.latched() {
            // Judged at `now_ns`, before the hook: its time is no silence of the pipeline.
            if self.watchdog.check(now_ns) == Freshness::Fresh {
                self.safety.reset(&self.last_measured.q);
                did = true;
            } else {
                self.counters.resets_refused += 1;
            }
        }
        self.after_hooks();
        did
    }

    /// After a lifecycle hook the framework called (a reset that rebuilds a bus, an
    /// activation that enables drives): the time spent inside it is neither a stall of
    /// the cycle nor a silence of the pipeline, so the watchdog's and the stall
    /// detection's clocks restart from its end with the ages they had at its start. The
    /// held torque command keeps its own stamp: free-running, one older than `stale_ms`
    /// is still never applied ([`Self::step`]). Returns the time spent (ns); the stage
    /// drops the timer periods that elapsed in it (not replayed).
    fn after_hooks(&mut self) -> u64 {
        let took = self.hw.take_hook_ns();
        self.watchdog.pause(took);
        if let Some(t) = &mut self.last_step_ns {
            *t = t.saturating_add(took);
        }
        self.hook_ns = self.hook_ns.saturating_add(took);
        took
    }

    /// Wall time spent inside lifecycle hooks since the last call (ns).
    pub fn take_hook_ns(&mut self) -> u64 {
        std::mem::take(&mut self.hook_ns)
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
            if self.hw.state() == LifecycleState::Inactive {
                let _ = self.hw.activate(&mut |_| {});
                self.after_hooks();
                self.count_backend_faults();
            }
            self.counters.faults += 1;
            self.safety.on_fault(&self.last_measured.q);
            // `on_fault` blends from the last applied torque, which is `t`.
        }
    }

    /// Free-running: call first on every wake-up of the loop at `now_ns`, before any
    /// torque command is accepted. When the loop has not stepped the plant for longer
    /// than `stale_ms` (the process was frozen, or not scheduled), this is a stall:
    /// counted, flagged `STALLED` on the states until a command answering a state
    /// published after it arrives, and judged by the watchdog now, before the commands
    /// queued during the stall could feed it — so the actuator holds with its own law
    /// (or latches the safe state if the silence reached `fault_ms`). The missed
    /// periods are not replayed: the stage drops every timer tick older than
    /// `stale_ms`. Returns the stall's length in ns. Lockstep has no stalls: logical
    /// time waits for the actuator.
    ///
    /// A freeze can also land inside a wake-up, after this check (SIGSTOP, a host stall
    /// in the middle of a plant step): every accepted command and every plant step
    /// makes the same check with its own time, so the commands queued during such a
    /// stall are judged exactly as after one between wake-ups.
    pub fn on_wake(&mut self, now_ns: u64) -> Option<u64> {
        self.detect_stall(now_ns)
    }

    /// The stall check of [`ActuatorCore::on_wake`]; the stall's length is also kept for
    /// [`ActuatorCore::last_stall_ns`].
    fn detect_stall(&mut self, now_ns: u64) -> Option<u64> {
        if self.lockstep {
            return None;
        }
        let gap = now_ns.saturating_sub(self.last_step_ns?);
        if gap <= self.stale_ns {
            return None;
        }
        self.last_step_ns = Some(now_ns);
        self.counters.stalls += 1;
        self.last_stall_ns = gap;
        self.resync_state_seq = Some(self.state_seq + 1);
        self.check_watchdog(now_ns);
        Some(gap)
    }

    /// The length of the last stall detected (ns; 0 before the first), for the log line
    /// of a stall found inside a wake-up (`counters.stalls` tells that one was).
    pub fn last_stall_ns(&self) -> u64 {
        self.last_stall_ns
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
    ///
    /// Free-running, a command stamped `stale_ms` or more before `now_ns` is never
    /// applied: the step holds instead (as [`ActuatorCore::check_watchdog`] switches
    /// when no command arrived for that long).
    pub fn step(&mut self, now_ns: u64) -> JointState {
        if !self.lockstep {
            self.detect_stall(now_ns);
            self.last_step_ns = Some(now_ns);
            if self.safety.mode() == Mode::Command
                && self
                    .latest
                    .is_some_and(|c| now_ns.saturating_sub(c.header.stamp_ns) >= self.stale_ns)
            {
                self.safety.on_stale(&self.last_measured.q);
            }
        }
        let active = self.hw.state() == LifecycleState::Active;
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
            self.hw.write(now_ns, self.period_s, &tau);
            if use_cmd && self.latest_unapplied {
                fresh_cmd = self.latest;
                self.steps_on_latest = 0;
            }
            self.steps_on_latest += 1;
            self.latest_unapplied = false;
        }
        if let Some(m) = self.hw.read(now_ns) {
            self.last_measured = m;
        }
        self.count_backend_faults();
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
    /// active, and the returned last state message says so (lifecycle Inactive); then
    /// the backend's `on_shutdown`. Called on every clean stop, including SIGTERM from a
    /// dead supervisor (PDEATHSIG).
    pub fn shutdown(&mut self, now_ns: u64) -> JointState {
        self.hw.deactivate();
        if let Some(m) = self.hw.read(now_ns) {
            self.last_measured = m;
        }
        self.count_backend_faults();
        let mut s = self.state_message(now_ns);
        s.flags |= state_flags::FINAL;
        self.hw.finalize();
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
        if self.resync_state_seq.is_some() {
            s.flags |= state_flags::STALLED;
        }
        s
    }
}

/// The robot's initial joint vector from `initial_q_deg` of `sim` (deg for revolute, mm
/// for prismatic), in SI (rad, m).
pub fn initial_q(robot: &Robot, sim: &SimConfig) -> JointVector {
    let mut q = JointVector::zeros();
    if let Some(v) = &sim.initial_q_deg {
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

/// The actuator service with the simulated arm (`microrobot-actuator`): [`serve`]
/// with a [`SimArm`] started where [`Setup::start`] says the arm is.
pub fn run(cfg: &PipelineConfig, shutdown: &Shutdown) -> anyhow::Result<()> {
    serve(cfg, shutdown, |setup: &Setup| {
        let start = &setup.start;
        let mut sim = SimArm::new(setup.robot, &setup.actuator.sim, &start.q);
        if start.from == StartFrom::Restart {
            sim.set_state(&start.q, &start.qd);
        }
        Ok(sim)
    })
}
