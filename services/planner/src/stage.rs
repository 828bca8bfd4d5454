//! The planner service's stage: the pipeline's clock. It waits for the actuator's
//! measured state, then ticks on its own timer (or, ticking on states, on each new
//! measured state), publishing one setpoint per tick. Commands are taken when their
//! event wakes it and at the runner's sweep ([`Cycle::sweep`]); master samples at every
//! wake-up in teleop mode, otherwise at the sweep.

use microrobot_messages::{
    JointSetpoint, JointState, LifecycleState, MasterPose, MotionCommand, RefusalQuantity,
    RefusalReason, ServiceRole, ServiceStatus, monotonic_ns, state_flags, topic,
};
use microrobot_runtime::config::{PipelineConfig, ms_to_ns};
use microrobot_runtime::stats::LatencyHistogram;
use microrobot_runtime::validate::Refusal;
use microrobot_runtime::{
    BadConfig, Cycle, Inbox, Outbox, PeriodicClock, Reactor, Ready, Shutdown, Source, Stage,
    Subscription, TickTimer, Ticker, serve,
};

use crate::program::ProgramRunner;
use crate::{CommandError, Mode, PlannerCore, load_robot};

/// The planner service (`microrobot-planner`).
pub fn run(cfg: &PipelineConfig, shutdown: &Shutdown) -> anyhow::Result<()> {
    let robot = load_robot(cfg)?;
    let program = match &cfg.program {
        Some(p) => Some(
            ProgramRunner::from_file(p, &robot).map_err(|e| BadConfig(format!("program: {e}")))?,
        ),
        None => None,
    };
    // Ticking on states wakes on them; the timer clock reads the newest state each tick.
    let on_states = cfg.planner_ticks_on_states();
    serve(cfg, shutdown, ServiceRole::Planner, |setup| {
        let (node, inst) = (setup.node, setup.instance());
        let setpoints = Outbox::open(node, inst, topic::SETPOINT)?;
        let states_how = Subscription::CYCLIC.with_history(1);
        let states = Inbox::open(
            node,
            inst,
            topic::STATE,
            if on_states {
                states_how
            } else {
                states_how.polled()
            },
        )?;
        let commands = Inbox::open(
            node,
            inst,
            topic::COMMAND,
            Subscription::CYCLIC.default_queue(),
        )?;
        let master = Inbox::open(
            node,
            inst,
            topic::MASTER,
            Subscription::CYCLIC
                .default_queue()
                .with_history(1)
                .polled(),
        )?;
        let mut core = PlannerCore::new(&robot, cfg, program);
        setup.publish_status(|st| st.lifecycle = LifecycleState::Inactive as u32);

        // Wait for the actuator's measured state (history 1).
        let deadline = monotonic_ns() + ms_to_ns(cfg.planner.state_timeout_ms);
        while !core.started() {
            if setup.shutdown.is_requested() {
                return Ok(None);
            }
            states.drain(|r| {
                core.accept_state_from(&r.msg, r.publisher, monotonic_ns(), || r.from_pipeline());
            });
            if core.started() {
                break;
            }
            if monotonic_ns() > deadline {
                anyhow::bail!(
                    "no measured state from the actuator within {} ms (is the actuator of instance `{inst}` running?)",
                    cfg.planner.state_timeout_ms
                );
            }
            std::thread::sleep(std::time::Duration::from_millis(2));
        }
        tracing::info!("planner: starting from the measured state");

        let PeriodicClock { timer, ticker } =
            PeriodicClock::start(cfg.period_ns(), cfg.realtime.overrun)?;
        if on_states {
            // Ticks come from states; the timer only paces status and watchdog checks.
            let p = ms_to_ns(cfg.status_period_ms);
            timer.arm_absolute(monotonic_ns() + p, p)?;
        }
        let ports = Ports {
            setpoints,
            states,
            commands,
            master,
            timer,
        };
        if cfg.lockstep {
            // The first setpoint answers the initial state; the loop runs on it alone.
            if !ports.setpoints.send(core.tick(monotonic_ns())) {
                anyhow::bail!("the first lockstep setpoint could not be published");
            }
        }
        let stage = PlannerStage {
            core,
            ticker,
            lateness: LatencyHistogram::new(),
            wake_to_setpoint: LatencyHistogram::new(),
            state_clock_misses: 0,
            on_states,
            lockstep: cfg.lockstep,
            period_ns: cfg.period_ns(),
        };
        Ok(Some((stage, ports)))
    })
}

/// The ports of the planner stage.
struct Ports {
    setpoints: Outbox<JointSetpoint>,
    /// Woken on when ticking on states; else polled at each tick.
    states: Inbox<JointState>,
    commands: Inbox<MotionCommand>,
    /// Polled: the newest valid sample is used at the next tick.
    master: Inbox<MasterPose>,
    /// The clock (or, ticking on states, the status and watchdog pace).
    timer: TickTimer,
}

#[derive(Clone, Copy)]
struct Sources {
    state: Option<Source>,
    command: Source,
    timer: Source,
}

struct PlannerStage {
    core: PlannerCore,
    ticker: Ticker,
    /// Wake-up after the tick's ideal time (or after the state's stamp, ticking on
    /// states).
    lateness: LatencyHistogram,
    /// Wake-up for a tick (the instant its lateness ends) → its setpoint sent.
    wake_to_setpoint: LatencyHistogram,
    /// Ticks on states that woke more than one period after the state was stamped.
    state_clock_misses: u64,
    on_states: bool,
    lockstep: bool,
    period_ns: u64,
}

impl PlannerStage {
    /// The commands, on their event and at the sweep ([`Inbox::take_on_demand`]).
    fn take_commands(&mut self, ports: &Ports, woken: bool, cycle: &mut Cycle<'_>) {
        let mut took = false;
        let sweep = cycle.sweep;
        ports.commands.take_on_demand(woken, sweep, |r| {
            let c = r.msg;
            let verdict = self.core.on_command(&c, monotonic_ns());
            match &verdict {
                Ok(()) => tracing::info!("planner: command {} (seq {}) accepted", c.kind, c.seq),
                Err(e) => {
                    tracing::warn!("planner: command {} (seq {}) refused: {e}", c.kind, c.seq)
                }
            }
            // The verdict goes into the status's ring, where its sender finds it (the
            // ring's slot follows the count of commands taken).
            cycle.status.commands_accepted = self.core.counters.commands_accepted;
            cycle.status.commands_refused = self.core.counters.commands_refused;
            cycle.status.record_command_verdict(
                c.seq,
                r.publisher,
                verdict.map_or_else(|e| e.reason(), |()| RefusalReason::None),
            );
            took = true;
        });
        // Senders wait for their verdicts: publish them now rather than at the next
        // periodic status (also keeps a burst of commands from overrunning the ring).
        if took {
            cycle.publish_status_now();
        }
    }

    /// Ticking on states, each new measured state is a tick; otherwise the newest one
    /// is kept for the next tick.
    fn take_states(&mut self, ports: &Ports) {
        let (on_states, lockstep, period_ns) = (self.on_states, self.lockstep, self.period_ns);
        ports.states.drain(|r| {
            let msg = r.msg;
            let new_period = msg.flags & state_flags::FINAL == 0;
            let taken = self
                .core
                .accept_state_from(&msg, r.publisher, monotonic_ns(), || r.from_pipeline());
            if taken && on_states && new_period {
                let now = monotonic_ns();
                if !lockstep {
                    // The state's stamp is the master clock's tick: lateness is the
                    // wake-up after it, as for the timer clock.
                    let late = now.saturating_sub(msg.header.stamp_ns);
                    self.lateness.record(late);
                    self.state_clock_misses += u64::from(late > period_ns);
                }
                self.core.check_state(now);
                ports.setpoints.send(self.core.tick(now));
                self.wake_to_setpoint
                    .record(monotonic_ns().saturating_sub(now));
            }
        });
    }

    fn on_timer(&mut self, ports: &Ports) {
        self.ticker.on_expirations(ports.timer.read_expirations());
        if self.on_states {
            while self.ticker.next_tick().is_some() {}
            // A silent actuator stops the ticks: the stale check still runs here.
            if !self.lockstep {
                self.core.check_state(monotonic_ns());
            }
        } else {
            while let Some(t) = self.ticker.next_tick() {
                let now = monotonic_ns();
                self.lateness.record(now.saturating_sub(t.ideal_ns));
                self.core.check_state(now);
                ports.setpoints.send(self.core.tick(monotonic_ns()));
                self.wake_to_setpoint
                    .record(monotonic_ns().saturating_sub(now));
            }
        }
    }
}

impl Stage for PlannerStage {
    type Ports = Ports;
    type Sources = Sources;

    fn register<'p>(ports: &'p Ports, reactor: &mut Reactor<'p>) -> std::io::Result<Sources> {
        Ok(Sources {
            state: ports.states.register(reactor)?,
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
        self.take_commands(ports, ready.contains(on.command), cycle);
        // Master samples: the newest valid one is used at the next tick. Taken at every
        // wake-up in teleop mode, otherwise at the sweep (counted, the queue kept short).
        if cycle.sweep || self.core.mode() == Mode::Teleop {
            ports.master.for_each(|r| {
                self.core.on_master(&r.msg, r.publisher, monotonic_ns());
            });
        }
        if ready.contains_opt(on.state) || !self.on_states {
            self.take_states(ports);
        }
        if ready.contains(on.timer) {
            self.on_timer(ports);
        }
        Ok(())
    }

    fn report(&self, st: &mut ServiceStatus) {
        let core = &self.core;
        st.ready = 1;
        st.lifecycle = if core.mode() == Mode::EStop || core.mode() == Mode::SafeHold {
            LifecycleState::Fault as u32
        } else {
            LifecycleState::Active as u32
        };
        st.cycles = core.counters.ticks;
        st.deadline_misses = if self.lockstep {
            0
        } else if self.on_states {
            self.state_clock_misses
        } else {
            self.ticker.deadline_misses
        };
        st.skipped_ticks = if self.lockstep {
            0
        } else {
            self.ticker.skipped_ticks
        };
        st.lost_messages = core.lost_messages();
        st.refused_messages = core.counters.states_refused + core.counters.commands_refused;
        st.stale_cycles = core.counters.stale_cycles;
        st.faults = core.counters.estops;
        st.estops = core.counters.estops;
        st.estop_latency_ns = core.last_estop_latency_ns.unwrap_or(0);
        st.estop_latency_max_ns = core.max_estop_latency_ns;
        st.last_command_refusal =
            core.last_error
                .as_ref()
                .map_or(RefusalReason::None, CommandError::reason) as u32;
        let detail = core.last_error.as_ref().and_then(CommandError::detail);
        st.refusal_joint = detail.and_then(|d| d.joint).map_or(0, |j| j as u32 + 1);
        st.refusal_quantity = detail.map_or(RefusalQuantity::None, |d| d.quantity) as u32;
        st.refusal_value = detail.map_or(0.0, |d| d.value);
        st.refusal_min = detail.map_or(0.0, |d| d.min);
        st.refusal_max = detail.map_or(0.0, |d| d.max);
        st.last_input_refusal = core
            .last_state_refusal
            .map_or(RefusalReason::None, Refusal::reason) as u32;
        st.commands_accepted = core.counters.commands_accepted;
        st.commands_refused = core.counters.commands_refused;
        st.motion_time_s = core.motion_time_s();
        st.program_done = core.program_done() as u32;
        let (state, end) = core.program_outcome();
        st.program_state = state as u32;
        st.program_end = end as u32;
        st.activity = core.activity() as u32;
    }

    fn report_latency(&self, st: &mut ServiceStatus) {
        st.latency = self.lateness.summary();
        st.latency_sum_ns = self.lateness.sum_ns();
        st.hops[0] = self.wake_to_setpoint.hop_latency();
    }

    fn finish(&mut self, _ports: &Ports) {
        let t = self.core.teleop();
        if t.counters.samples > 0 || t.counters.refused > 0 {
            let l = t.latency.summary();
            tracing::info!(
                "planner: teleop: {} master samples, {} refused ({} from a second device), {} stale cycles, {} flips refused, {} cycles at the workspace edge; master sample -> setpoint p50 {:.1} us, p99 {:.1} us",
                t.counters.samples,
                t.counters.refused,
                t.counters.second_device,
                t.counters.stale_cycles,
                t.counters.flips_refused,
                t.counters.edge_cycles,
                l.p50_ns as f64 / 1e3,
                l.p99_ns as f64 / 1e3
            );
        }
    }
}
