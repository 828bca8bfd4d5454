//! The door every actuator comes through: [`serve`] runs any [`ActuatorBackend`] as the
//! pipeline's actuator process. The backend reads and writes its hardware; everything
//! else is here, the same for every backend: the ports, the start state, the lifecycle
//! and its hooks, the watchdogs (stale hold, safe-state latch, reset), the one-publisher
//! rule, stall handling, one state per plant cycle (free-running) or per torque command
//! (lockstep) with its header bookkeeping, the status at `status_period_ms`, and the
//! last state and status on SIGINT/SIGTERM.

use anyhow::Context as _;
use microrobot_messages::{
    CommandKind, JointState, LifecycleHook, MotionCommand, RefusalReason, ServiceRole,
    ServiceStatus, TorqueCommand, monotonic_ns, topic,
};
use microrobot_model::{JointVector, Robot};
use microrobot_runtime::config::{OwnedSection, PipelineConfig};
use microrobot_runtime::stats::LatencyHistogram;
use microrobot_runtime::validate::Refusal;
use microrobot_runtime::{
    ArrivalTicker, BadConfig, Cycle, Inbox, Outbox, Reactor, Ready, Shutdown, Source, Stage,
    Subscription, Ticker, TimerFd,
};

use crate::{
    ActuatorBackend, ActuatorConfig, ActuatorCore, ResumeState, SimConfig, initial_q, load_robot,
};

/// Where the arm is believed to be when the actuator starts.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum StartFrom {
    /// `actuator.sim.initial_q_deg` (zero when absent).
    Config,
    /// A running planner's last setpoint (the actuator restarted without a handed-over
    /// state).
    PlannerSetpoint,
    /// The predecessor's last published state, handed over by the supervisor
    /// ([`RESUME_ENV`](crate::RESUME_ENV)).
    Restart,
}

/// The start state: a simulated backend starts its plant here; a real one reads its
/// encoders instead and may use this only as a plausibility check.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StartState {
    /// Position (rad or m).
    pub q: JointVector,
    /// Velocity (rad/s or m/s): nonzero only after a restart of a moving arm.
    pub qd: JointVector,
    /// Where it comes from.
    pub from: StartFrom,
}

/// What a backend is built from: the resolved pipeline config, the robot it names and
/// the start state.
#[derive(Debug, Clone, Copy)]
pub struct Setup<'a> {
    /// The pipeline config (rate, lockstep, watchdog …).
    pub cfg: &'a PipelineConfig,
    /// `[actuator]` of it (the simulated arm, the safe-state gains, …).
    pub actuator: &'a ActuatorConfig,
    /// The robot (joint names, kinds, limits, inertias).
    pub robot: &'a Robot,
    /// Where the arm is.
    pub start: StartState,
}

impl Setup<'_> {
    /// Number of joints.
    pub fn dof(&self) -> usize {
        self.robot.dof()
    }

    /// Control rate (Hz).
    pub fn rate_hz(&self) -> f64 {
        self.cfg.rate_hz
    }

    /// Control period (s): what `write` is called with.
    pub fn period_s(&self) -> f64 {
        1.0 / self.cfg.rate_hz
    }

    /// Whether the pipeline runs in lockstep (one `write` per torque command).
    pub fn lockstep(&self) -> bool {
        self.cfg.lockstep
    }

    /// The joint names, in order.
    pub fn joint_names(&self) -> impl Iterator<Item = &str> {
        self.robot.joints().iter().map(|j| j.name.as_str())
    }
}

/// How long a (re)started actuator listens for the planner's last setpoint to resume
/// the arm where it was instead of at `initial_q_deg`.
const RESUME_PROBE_MS: u64 = 200;

/// Runs the actuator process with the backend `make_backend` builds until `shutdown`.
/// A backend that cannot be built, or drives another number of joints than the robot
/// has, is a config error (exit code 2 through [`microrobot_runtime::service_main`]).
pub fn serve<B, F>(cfg: &PipelineConfig, shutdown: &Shutdown, make_backend: F) -> anyhow::Result<()>
where
    B: ActuatorBackend,
    F: FnOnce(&Setup) -> anyhow::Result<B>,
{
    let robot = load_robot(cfg)?;
    let actuator = ActuatorConfig::from_pipeline(cfg).map_err(|e| BadConfig(e.to_string()))?;
    let dof = robot.dof();
    microrobot_runtime::serve(cfg, shutdown, ServiceRole::Actuator, |setup| {
        let (node, inst) = (setup.node, setup.instance());
        let torques = Inbox::open(node, inst, topic::TORQUE, Subscription::CYCLIC)?;
        let states = Outbox::open(node, inst, topic::STATE)?;
        let commands = Inbox::open(
            node,
            inst,
            topic::COMMAND,
            Subscription::CYCLIC.default_queue(),
        )?;
        let start = start_state(cfg, &actuator.sim, &robot, setup.shutdown, node)?;
        let backend = make_backend(&Setup {
            cfg,
            actuator: &actuator,
            robot: &robot,
            start: start.state,
        })
        .context("actuator backend")?;
        if backend.dof() != dof {
            return Err(BadConfig(format!(
                "the actuator backend drives {} joints, the robot `{}` has {dof}",
                backend.dof(),
                robot.name()
            ))
            .into());
        }
        let mut core =
            ActuatorCore::new(backend, &robot, cfg, &actuator).context("actuator backend")?;
        if let Some(r) = &start.resume {
            core.resume_after_restart(&r.tau, !cfg.watchdog.auto_resume);
        }
        // One timerfd, not a `PeriodicClock`'s pair: once the torques phase the steps it
        // is moved, and then never onto the CPU's next expiry (see `ArrivalTicker`).
        let timer = TimerFd::new()?;
        let first = monotonic_ns() + cfg.period_ns();
        timer.arm_absolute(first, cfg.period_ns())?;
        let ticker = Ticker::new(first, cfg.period_ns(), cfg.realtime.overrun);
        let ports = Ports {
            torques,
            states,
            commands,
            timer,
        };
        let mut stage = ActuatorStage {
            core,
            clock: StepClock::Timer(ticker),
            e2e: LatencyHistogram::new(),
            torque_to_taken: LatencyHistogram::new(),
            step_to_state: LatencyHistogram::new(),
            // Free-running with the planner on its own timer, each plant step runs as its
            // torque arrives, at the latest half a period after the planner's tick (see
            // `phase`). When the planner ticks on states, this timer is the pipeline's
            // master clock and stays.
            phased: cfg.planner_ticks_on_states(),
            answered: u64::MAX,
            accepted: u64::MAX,
            faults_logged: 0,
            hook_budget_ms: hook_budget_ms(&actuator),
        };
        // Initial state (history 1 on State: the planner starts from it).
        let first = stage.core.state_message(monotonic_ns());
        stage.publish(&ports, first);
        Ok(Some((stage, ports)))
    })
}

/// The start state and, after a restart, the handed-over state it came from.
struct Start {
    state: StartState,
    resume: Option<ResumeState>,
}

/// Where the arm is: the predecessor's last published state (handed over by the
/// supervisor after a restart), else a running planner's last setpoint (listened for
/// [`RESUME_PROBE_MS`]), else the config.
fn start_state(
    cfg: &PipelineConfig,
    sim: &SimConfig,
    robot: &Robot,
    shutdown: &Shutdown,
    node: &iceoryx2::prelude::Node<iceoryx2::prelude::ipc::Service>,
) -> anyhow::Result<Start> {
    let resume = ResumeState::from_env(robot).map_err(BadConfig)?;
    let mut state = StartState {
        q: initial_q(robot, sim),
        qd: JointVector::zeros(),
        from: StartFrom::Config,
    };
    if let Some(r) = &resume {
        state = StartState {
            q: r.q,
            qd: r.qd,
            from: StartFrom::Restart,
        };
        tracing::info!(
            "actuator: restarted; resuming the arm at its last published state{}",
            if cfg.watchdog.auto_resume {
                ""
            } else {
                " in the safe state (send a reset to resume)"
            }
        );
        return Ok(Start { state, resume });
    }
    let setpoints = Inbox::open(
        node,
        &cfg.instance,
        topic::SETPOINT,
        Subscription::CYCLIC
            .default_queue()
            .with_history(1)
            .polled(),
    )?;
    let dof = robot.dof();
    let probe_end = monotonic_ns() + RESUME_PROBE_MS * 1_000_000;
    while monotonic_ns() < probe_end && !shutdown.is_requested() {
        while let Some(r) = setpoints.next() {
            let s = r.msg;
            if s.dof as usize == dof && microrobot_messages::all_finite(&s.q, s.dof) {
                state.q = JointVector::from_column_slice(&s.q);
                state.from = StartFrom::PlannerSetpoint;
                tracing::info!("actuator: resuming the arm at the planner's last setpoint");
                return Ok(Start { state, resume });
            }
        }
        std::thread::sleep(std::time::Duration::from_millis(5));
    }
    Ok(Start { state, resume })
}

/// The ports of the actuator stage.
pub(crate) struct Ports {
    torques: Inbox<TorqueCommand>,
    states: Outbox<JointState>,
    /// Resets (every other command is the planner's).
    commands: Inbox<MotionCommand>,
    /// The plant's period (free-running) and the watchdogs' clock.
    timer: TimerFd,
}

#[derive(Clone, Copy)]
pub(crate) struct Sources {
    torque: Source,
    command: Source,
    timer: Source,
}

/// What clocks the plant's steps.
enum StepClock {
    /// The actuator's own timer, a step per tick: lockstep (the safe state's steps),
    /// the planner ticking on states (this timer is the pipeline's master clock), and
    /// free-running until the first torque command phases the steps.
    Timer(Ticker),
    /// Free-running on the planner's clock: each step runs as its torque arrives, the
    /// timer only for steps whose torque did not come (see [`ArrivalTicker`]).
    Arrival(ArrivalTicker),
}

impl StepClock {
    fn period_ns(&self) -> u64 {
        match self {
            Self::Timer(t) => t.period_ns(),
            Self::Arrival(t) => t.period_ns(),
        }
    }
}

/// How late, at most, the arrival clock's timer notices a missing torque command, for a
/// backend whose cycle may run late (see [`ArrivalTicker`]): 1 ms, and never more than a
/// quarter of `stale_ms`.
const FALLBACK_LAG_MAX_NS: u64 = 1_000_000;

/// Steps run back to back in one wake-up, at most (the rest of a backlog is dropped).
const CATCH_UP_STEPS_MAX: u32 = 100;

/// The framework around a backend: [`ActuatorCore`] (lifecycle, watchdogs, safe-state
/// latch, one-publisher rule) and the bookkeeping of the cycle.
pub(crate) struct ActuatorStage<B: ActuatorBackend> {
    core: ActuatorCore<B>,
    clock: StepClock,
    /// Setpoint source stamp → torque received.
    e2e: LatencyHistogram,
    /// Its last hop, for the same torques: torque stamp → torque received (taken from
    /// the queue after the wake-up).
    torque_to_taken: LatencyHistogram,
    /// Plant step (the state's stamp) → its state sent: the backend's write and read.
    step_to_state: LatencyHistogram,
    /// Whether the plant's steps are phased against the planner's ticks (or need not be).
    phased: bool,
    /// The torque the last published state answered, and the last torque accepted: in
    /// lockstep every torque is owed one state.
    answered: u64,
    accepted: u64,
    faults_logged: u64,
    /// `actuator.hook_budget_ms`, as the status carries it.
    hook_budget_ms: u32,
}

/// `actuator.hook_budget_ms` for the status (whole ms, at least 1).
fn hook_budget_ms(actuator: &ActuatorConfig) -> u32 {
    // Validated to (0, 600000] ms.
    actuator
        .hook_budget_ms
        .ceil()
        .clamp(1.0, f64::from(u32::MAX)) as u32
}

/// Says in the status, sent at once, that the cycle is about to block inside `hook`
/// for up to `budget_ms` (the next status, at the end of the wake-up, clears it).
fn announce_hook(cycle: &mut Cycle<'_>, hook: LifecycleHook, budget_ms: u32) {
    cycle.publish_status_with(|st| {
        st.hook = hook as u32;
        st.hook_budget_ms = budget_ms;
    });
}

impl<B: ActuatorBackend> ActuatorStage<B> {
    fn publish(&mut self, ports: &Ports, s: JointState) {
        self.answered = s.torque_seq;
        ports.states.send(s);
    }

    /// Checks the watchdogs and steps the plant once, publishing its state.
    fn step(&mut self, ports: &Ports, now: u64) {
        self.core.check_watchdog(now);
        self.step_and_publish(ports, monotonic_ns());
    }

    /// Steps the plant at `now` and publishes its state (timed: step → state sent).
    fn step_and_publish(&mut self, ports: &Ports, now: u64) {
        let s = self.core.step(now);
        self.publish(ports, s);
        self.step_to_state
            .record(monotonic_ns().saturating_sub(s.header.stamp_ns));
    }

    /// Free-running: puts the plant steps' latest time half a period after the
    /// planner's ticks, so torque k is applied in the step that ends before setpoint
    /// k+1 (the same one-period loop delay as lockstep), and from then on clocks the
    /// steps by the torques' arrival ([`StepClock::Arrival`]).
    fn phase(&mut self, ports: &Ports, cfg: &PipelineConfig, source_stamp_ns: u64, now: u64) {
        self.phased = true;
        let p = cfg.period_ns();
        let mut first = source_stamp_ns + p / 2;
        while first <= now {
            first += p;
        }
        if ports.timer.arm_absolute(first, p).is_ok() {
            let _ = ports.timer.read_expirations();
            let lead = if self.core.backend().cycle_may_run_late() {
                let max_lag = FALLBACK_LAG_MAX_NS.min(cfg.watchdog.stale_ns() / 4);
                ArrivalTicker::lead_for(p, max_lag)
            } else {
                0
            };
            self.clock = StepClock::Arrival(ArrivalTicker::new(first, p, lead));
        }
    }

    /// Free-running on the planner's clock: the plant step of this period runs as its
    /// torque arrives, rather than on a timer wake-up of its own (one wake-up per period
    /// instead of two), so torque k is applied in the step that ends before setpoint
    /// k+1, one step per period. A step whose torque did not come by its time runs at
    /// the next wake-up, the next torque's or the timer's (see [`ArrivalTicker`]), and
    /// holds or ramps as the watchdog says. Nothing on the actuator's own timer clock
    /// (lockstep, the planner ticking on states): that timer steps the plant.
    fn step_on_arrival(&mut self, ports: &Ports, now: u64) {
        let StepClock::Arrival(clock) = &mut self.clock else {
            return;
        };
        let timer = &ports.timer;
        if clock
            .take_early(now, |first, p| timer.arm_absolute(first, p).is_ok())
            .is_some()
        {
            self.step(ports, now);
        }
    }

    /// Arrival clock: the steps whose time has come without their torque, each checking
    /// the watchdog first; those older than `stale_ms` are not replayed (a stall: no
    /// torque that old is applied, and the plant does not run a burst of catch-up
    /// steps).
    fn run_due(&mut self, ports: &Ports, cfg: &PipelineConfig) {
        let stale_ns = cfg.watchdog.stale_ns();
        let mut n = 0;
        loop {
            let now = monotonic_ns();
            let StepClock::Arrival(clock) = &mut self.clock else {
                return;
            };
            if clock.next_due(now, stale_ns).is_none() {
                return;
            }
            self.core.check_watchdog(now);
            if n < CATCH_UP_STEPS_MAX {
                self.step_and_publish(ports, now);
                n += 1;
            }
        }
    }

    fn take_torques(&mut self, ports: &Ports, cycle: &mut Cycle<'_>, was_latched: &mut bool) {
        let cfg = cycle.cfg;
        let budget = self.hook_budget_ms;
        ports.torques.drain(|r| {
            let msg = r.msg;
            let now = monotonic_ns();
            let verdict = self.core.accept_torque_from(
                &msg,
                r.publisher,
                now,
                || r.from_pipeline(),
                &mut |hook| announce_hook(cycle, hook, budget),
            );
            if verdict == Err(Refusal::Outsider) && !*was_latched && self.core.safe_state_latched()
            {
                *was_latched = true;
                tracing::error!(
                    "actuator: a torque command from a process the supervisor did not start: refused, safe state latched; send a reset once the pipeline's own dynamics publishes again"
                );
            }
            if verdict.is_ok() {
                self.accepted = msg.header.seq;
                self.e2e
                    .record(now.saturating_sub(msg.header.source_stamp_ns));
                self.torque_to_taken
                    .record(now.saturating_sub(msg.header.stamp_ns));
                if !cfg.lockstep && !self.phased {
                    self.phase(ports, cfg, msg.header.source_stamp_ns, now);
                }
                if self.core.steps_on_timer() {
                    self.step_on_arrival(ports, now);
                } else {
                    self.step(ports, now);
                }
            }
            // An activation that blocked: its periods are not replayed.
            self.after_hooks(ports);
        });
    }

    /// After the framework called a lifecycle hook: the timer periods that elapsed inside
    /// it are dropped, not replayed (the core restarted its clocks from the hook's end,
    /// see `ActuatorCore::reset`). Returns whether a hook took longer than a period.
    fn after_hooks(&mut self, ports: &Ports) -> bool {
        if self.core.take_hook_ns() <= self.clock.period_ns() {
            return false;
        }
        let expirations = ports.timer.read_expirations();
        match &mut self.clock {
            StepClock::Timer(t) => {
                t.on_expirations(expirations);
                while t.next_tick().is_some() {}
            }
            StepClock::Arrival(t) => {
                t.on_expirations(expirations);
                t.skip_due(monotonic_ns());
            }
        }
        true
    }

    /// The resets, on their event and at the sweep ([`Inbox::take_on_demand`]).
    fn take_commands(&mut self, ports: &Ports, cycle: &mut Cycle<'_>, woken: bool) {
        let (cfg, sweep) = (cycle.cfg, cycle.sweep);
        let budget = self.hook_budget_ms;
        ports.commands.take_on_demand(woken, sweep, |r| {
            if CommandKind::from_wire(r.msg.kind) == Some(CommandKind::Reset)
                && self.core.reset(monotonic_ns(), &mut |hook| {
                    announce_hook(cycle, hook, budget)
                })
            {
                tracing::info!("actuator: reset, following torque commands again");
                let blocked = self.after_hooks(ports);
                if !cfg.lockstep && blocked {
                    // A fresh state now (as after activation), for the pipeline to
                    // answer: the torque held from before the reset is older than the
                    // reset took, and is not applied once older than `stale_ms`.
                    self.step(ports, monotonic_ns());
                } else if self.accepted != u64::MAX && self.accepted != self.answered {
                    // Lockstep: a torque taken while latched and not yet answered by a
                    // timer step is answered now, or the loop (which ticks on states)
                    // would wait for a state while this waits for a torque. Otherwise
                    // the last state's answer is still on its way (one state per torque:
                    // another state now would run two loops).
                    self.step(ports, monotonic_ns());
                }
            } else {
                self.after_hooks(ports);
            }
        });
    }

    fn on_timer(&mut self, ports: &Ports, cfg: &PipelineConfig) {
        let expirations = ports.timer.read_expirations();
        // Hands the last state (history 1) to subscribers that joined since the last
        // send: in lockstep nothing is sent until the first torque, and the planner
        // starts from that state.
        ports.states.update_connections();
        match &mut self.clock {
            StepClock::Timer(t) => t.on_expirations(expirations),
            // Its due steps ran at the start of this wake-up (`run_due`).
            StepClock::Arrival(t) => {
                t.on_expirations(expirations);
                return;
            }
        }
        let stale_ns = cfg.watchdog.stale_ns();
        let mut n = 0;
        while let StepClock::Timer(t) = &mut self.clock
            && let Some(tick) = t.next_tick()
        {
            let now = monotonic_ns();
            // Free-running, a period that ended more than `stale_ms` ago is not replayed
            // (a stall): no torque that old is applied, and the plant does not run a
            // burst of catch-up steps.
            if !cfg.lockstep && now.saturating_sub(tick.ideal_ns) > stale_ns {
                continue;
            }
            self.core.check_watchdog(now);
            if self.core.steps_on_timer() && n < CATCH_UP_STEPS_MAX {
                self.step_and_publish(ports, now);
                n += 1;
            }
        }
    }
}

impl<B: ActuatorBackend> Stage for ActuatorStage<B> {
    type Ports = Ports;
    type Sources = Sources;

    fn register<'p>(ports: &'p Ports, reactor: &mut Reactor<'p>) -> std::io::Result<Sources> {
        Ok(Sources {
            torque: ports.torques.wake_on(reactor)?,
            command: ports.commands.wake_on(reactor)?,
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
        let mut was_latched = self.core.safe_state_latched();
        // Before any queued command can feed the watchdog: was this process stalled?
        // (A freeze inside this wake-up is caught by the next command or plant step.)
        let stalls = self.core.counters.stalls;
        self.core.on_wake(monotonic_ns());
        // Steps whose time passed without their torque run before any newer torque.
        self.run_due(ports, cfg);
        if ready.contains(on.torque) {
            self.take_torques(ports, cycle, &mut was_latched);
        }
        self.take_commands(ports, cycle, ready.contains(on.command));
        if ready.contains(on.timer) {
            self.on_timer(ports, cfg);
        }
        if self.core.counters.stalls != stalls {
            tracing::warn!(
                "actuator: stalled for {:.1} ms (longer than stale_ms = {} ms): the missed periods are not replayed; holding until a torque command answers a state published after the stall",
                self.core.last_stall_ns() as f64 * 1e-6,
                cfg.watchdog.stale_ms
            );
        }
        if self.core.safe_state_latched() && !was_latched {
            tracing::warn!(
                "actuator: no valid torque command for {} ms: safe state latched ({:?}); send a reset to resume",
                cfg.watchdog.fault_ms,
                cfg.watchdog.safe_state
            );
        }
        if self.core.backend_faults() != self.faults_logged {
            self.faults_logged = self.core.backend_faults();
            if let Some(f) = self.core.last_fault() {
                tracing::error!("actuator: backend fault: {f}; send a reset to acknowledge");
            }
        }
        Ok(())
    }

    fn report(&self, st: &mut ServiceStatus) {
        let core = &self.core;
        st.ready = 1;
        st.lifecycle = core.lifecycle() as u32;
        st.cycles = core.counters.cycles;
        st.lost_messages = core.lost_messages();
        st.refused_messages = core.counters.refused + core.counters.resets_refused;
        st.stale_cycles = core.counters.stale_cycles;
        st.clamped_cycles = core.counters.saturated_cycles + core.counters.slope_limited_cycles;
        st.faults = core.counters.faults;
        st.motion_time_s = core.motion_time_s();
        st.tracking_error_max = core.tracking_error_max;
        st.peak_torque = core.peak_torque;
        st.last_input_refusal = core
            .last_refusal
            .map_or(RefusalReason::None, Refusal::reason) as u32;
        if let Some(f) = core.last_fault() {
            st.fault_code = f.code;
            st.fault_joint = f.joint.map_or(0, |j| j as u32 + 1);
        }
        // Out of any hook (see `announce_hook`).
        st.hook = LifecycleHook::None as u32;
        st.hook_budget_ms = 0;
    }

    fn report_latency(&self, st: &mut ServiceStatus) {
        st.latency = self.e2e.summary();
        st.latency_sum_ns = self.e2e.sum_ns();
        st.hops = [
            self.torque_to_taken.hop_latency(),
            self.step_to_state.hop_latency(),
        ];
    }

    /// Safe on the way out, however the stop was asked for (Ctrl-C, SIGTERM, the
    /// supervisor's death): brakes on, and the last state says so.
    fn finish(&mut self, ports: &Ports) {
        let s = self.core.shutdown(monotonic_ns());
        self.publish(ports, s);
        tracing::info!("actuator: stopped, backend inactive (drives disabled)");
    }
}
