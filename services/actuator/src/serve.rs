//! The door every actuator comes through: [`serve`] runs any [`ActuatorBackend`] as the
//! pipeline's actuator process. The backend reads and writes its hardware; everything
//! else is here, the same for every backend: the ports, the start state, the lifecycle
//! and its hooks, the watchdogs (stale hold, safe-state latch, reset), the one-publisher
//! rule, stall handling, one state per plant cycle (free-running) or per torque command
//! (lockstep) with its header bookkeeping, the status at `status_period_ms`, and the
//! last state and status on SIGINT/SIGTERM.

use anyhow::Context as _;
use iceoryx2::port::update_connections::UpdateConnections;
use microrobot_messages::{
    CommandKind, JointSetpoint, JointState, MotionCommand, ServiceKind, ServiceRole, ServiceStatus,
    TorqueCommand, monotonic_ns, open_event, open_publish_subscribe,
};
use microrobot_model::{JointVector, Robot};
use microrobot_runtime::config::PipelineConfig;
use microrobot_runtime::stats::LatencyHistogram;
use microrobot_runtime::validate::Refusal;
use microrobot_runtime::{BadConfig, PeriodicClock, Reactor, Shutdown, StatusPort, open_node};

use crate::{ActuatorBackend, ActuatorCore, ResumeState, initial_q, load_robot};

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
    /// The pipeline config (rate, lockstep, watchdog, `[actuator]` …).
    pub cfg: &'a PipelineConfig,
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
    let dof = robot.dof();
    let inst = cfg.instance.as_str();
    let node = open_node(inst, ServiceRole::Actuator)?;

    let torque_svc = open_publish_subscribe::<TorqueCommand>(&node, inst, ServiceKind::Torque)?;
    let mut provenance = microrobot_runtime::provenance::Provenance::from_env();
    let torque_sub = torque_svc
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
    let mut start = StartState {
        q: initial_q(&robot, cfg),
        qd: JointVector::zeros(),
        from: StartFrom::Config,
    };
    if let Some(r) = &resume {
        start = StartState {
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
    }
    let probe_end = monotonic_ns() + RESUME_PROBE_MS * 1_000_000;
    'probe: while resume.is_none() && monotonic_ns() < probe_end && !shutdown.is_requested() {
        while let Ok(Some(s)) = sp_sub.receive() {
            if s.dof as usize == dof && microrobot_messages::all_finite(&s.q, s.dof) {
                start.q = JointVector::from_column_slice(&s.q);
                start.from = StartFrom::PlannerSetpoint;
                tracing::info!("actuator: resuming the arm at the planner's last setpoint");
                break 'probe;
            }
        }
        std::thread::sleep(std::time::Duration::from_millis(5));
    }
    drop(sp_sub);

    let backend = make_backend(&Setup {
        cfg,
        robot: &robot,
        start,
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
    let mut core = ActuatorCore::new(backend, &robot, cfg).context("actuator backend")?;
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
    // The torque the last published state answered, and the last torque accepted: in
    // lockstep every torque is owed one state.
    let answered = std::cell::Cell::new(u64::MAX);
    let mut accepted = u64::MAX;
    let publish = |s: JointState| {
        answered.set(s.torque_seq);
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
    let fill = |st: &mut ServiceStatus, core: &ActuatorCore<B>, e2e: &LatencyHistogram| {
        st.lifecycle = core.lifecycle() as u32;
        st.cycles = core.counters.cycles;
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
        if let Some(f) = core.last_fault() {
            st.fault_code = f.code;
            st.fault_joint = f.joint.map_or(0, |j| j as u32 + 1);
        }
    };
    fill(&mut st, &core, &e2e);
    status.publish(monotonic_ns(), &mut st);

    let stale_ns = cfg.watchdog.stale_ns();
    let mut faults_logged = 0;
    // Set up: from here on the loop runs pinned and SCHED_FIFO.
    microrobot_runtime::enter_cycle(cfg);
    while !shutdown.is_requested() {
        let ready = reactor.wait().context("epoll_wait")?;
        if ready.contains(on_stop) || shutdown.is_requested() {
            break;
        }
        let mut was_latched = core.safe_state_latched();
        // Before any queued command can feed the watchdog: was this process stalled?
        if let Some(gap) = core.on_wake(monotonic_ns()) {
            tracing::warn!(
                "actuator: stalled for {:.1} ms (longer than stale_ms = {} ms): the missed periods are not replayed; holding until a torque command answers a state published after the stall",
                gap as f64 * 1e-6,
                cfg.watchdog.stale_ms
            );
        }
        if ready.contains(on_torque) {
            let _ = torque_listener.try_wait(|_| {});
            while let Ok(Some(sample)) = torque_sub.receive() {
                let msg = *sample;
                let publisher = sample.header().publisher_id().value();
                drop(sample);
                let now = monotonic_ns();
                let verdict = core.accept_torque_from(&msg, publisher, now, || {
                    provenance.check(&torque_svc, publisher)
                        == microrobot_runtime::provenance::Origin::Pipeline
                });
                if verdict == Err(Refusal::Outsider) && !was_latched && core.safe_state_latched() {
                    was_latched = true;
                    tracing::error!(
                        "actuator: a torque command from a process the supervisor did not start: refused, safe state latched; send a reset once the pipeline's own dynamics publishes again"
                    );
                }
                if verdict.is_ok() {
                    accepted = msg.header.seq;
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
                    // Lockstep: a torque taken while latched and not yet answered by a
                    // timer step is answered now, or the loop (which ticks on states)
                    // would wait for a state while this waits for a torque.
                    if cfg.lockstep && accepted != u64::MAX && accepted != answered.get() {
                        let now = monotonic_ns();
                        core.check_watchdog(now);
                        publish(core.step(now));
                    }
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
            while let Some(tick) = ticker.next_tick() {
                let now = monotonic_ns();
                // Free-running, a period that ended more than `stale_ms` ago is not
                // replayed (a stall): no torque that old is applied, and the plant does
                // not run a burst of catch-up steps.
                if !cfg.lockstep && now.saturating_sub(tick.ideal_ns) > stale_ns {
                    continue;
                }
                core.check_watchdog(now);
                if core.steps_on_timer() && n < 100 {
                    publish(core.step(now));
                    n += 1;
                }
            }
        }
        if core.safe_state_latched() && !was_latched {
            tracing::warn!(
                "actuator: no valid torque command for {} ms: safe state latched ({:?}); send a reset to resume",
                cfg.watchdog.fault_ms,
                cfg.watchdog.safe_state
            );
        }
        if core.backend_faults() != faults_logged {
            faults_logged = core.backend_faults();
            if let Some(f) = core.last_fault() {
                tracing::error!("actuator: backend fault: {f}; send a reset to acknowledge");
            }
        }
        let now = monotonic_ns();
        if status.due(now) {
            fill(&mut st, &core, &e2e);
            status.publish(now, &mut st);
        }
    }
    // Safe on the way out, however the stop was asked for (Ctrl-C, SIGTERM, the
    // supervisor's death): brakes on, and the last state says so.
    publish(core.shutdown(monotonic_ns()));
    tracing::info!("actuator: stopped, backend inactive (drives disabled)");
    fill(&mut st, &core, &e2e);
    status.publish_final(&mut st);
    Ok(())
}
