//! The stage runner: one loop for every service. A service is its pure core plus a
//! [`Stage`]: what it does when one of its ports or timers wakes it, and what it reports
//! in its status. [`serve`] owns the rest, the same for all: the node, the status port
//! and its period, the set-up before the cycle, the reactor and the shutdown event,
//! [`enter_cycle`](crate::enter_cycle), the final status and the exit.
//!
//! The loop is ros2_control's `read(); update(); write(); sleep_until` with the wait
//! first: the stage sleeps in one `epoll_wait` over its event listeners and timers
//! ([`crate::Reactor`]) and does all its work in [`Stage::wake`].

use iceoryx2::prelude::*;
use microrobot_messages::{ServiceRole, ServiceStatus, monotonic_ns};

use crate::{PipelineConfig, Reactor, Ready, Shutdown, StatusPort, open_node};

/// What a service does in its cycle.
pub trait Stage {
    /// The ports and timers the stage sleeps on and works with ([`crate::ports`]). The
    /// runner owns them and lends them to the reactor and to every wake-up (the reactor
    /// borrows each file descriptor for as long as it can report it).
    type Ports;
    /// Which of the ports' sources woke the stage: the reactor's handles, from
    /// [`Stage::register`].
    type Sources: Copy;

    /// Registers the ports' listeners and timers with the reactor.
    fn register<'p>(
        ports: &'p Self::Ports,
        reactor: &mut Reactor<'p>,
    ) -> std::io::Result<Self::Sources>;

    /// One wake-up: `ready` says which of `on` fired. The stage reads its own timers
    /// (it may re-arm them) and drains its inboxes.
    fn wake(
        &mut self,
        ports: &Self::Ports,
        on: Self::Sources,
        ready: Ready,
        cycle: &mut Cycle<'_>,
    ) -> anyhow::Result<()>;

    /// Writes the stage's counters into its status (the runner stamps and publishes it
    /// at the status period, when asked to, and once more at the end).
    fn report(&self, status: &mut ServiceStatus);

    /// Writes the stage's latency summaries into its status (`latency`,
    /// `latency_sum_ns`, `hops`). Their percentiles scan each histogram's counts (about
    /// 10 µs after a sleep), so the runner asks for them at most once per
    /// [`crate::status::MEASURE_PERIOD_NS`] and in the final status, not at every
    /// status; each summary is consistent in itself (count, sum and percentiles of the
    /// same samples).
    fn report_latency(&self, _status: &mut ServiceStatus) {}

    /// The last word on the way out (SIGINT/SIGTERM or the supervisor's death), before
    /// the final status: e.g. the actuator's last, safe state.
    fn finish(&mut self, _ports: &Self::Ports) {}
}

/// What a wake-up may use besides its ports.
pub struct Cycle<'a> {
    /// The resolved pipeline config.
    pub cfg: &'a PipelineConfig,
    /// The stop request (a long wake-up checks it).
    pub shutdown: &'a Shutdown,
    /// The status the runner publishes (a stage writes what [`Stage::report`] cannot
    /// know afterwards, e.g. the verdict of a command it just took).
    pub status: &'a mut ServiceStatus,
    /// True on the first wake-up, and on a wake-up whose predecessor ended at least
    /// [`SWEEP_NS`] after the last sweep (the runner reads the clock only after each
    /// wake-up; with wake-ups every period `p`, sweeps are at most `SWEEP_NS + p` apart):
    /// the wake-up to look at an inbox the stage otherwise takes only when its own event
    /// wakes it (commands, [`crate::Inbox::take_on_demand`]), or only while it is in use
    /// (the master device's samples). See [`SWEEP_NS`] for why that loses nothing.
    pub sweep: bool,
    status_port: &'a mut StatusPort,
    publish_status: bool,
}

/// How often, at most, a stage sweeps its on-demand inboxes ([`Cycle::sweep`]): 1 ms.
///
/// An empty receive is not free: iceoryx2 checks the publisher list and every
/// connection, 0.07–0.1 µs back to back and 0.27–0.39 µs on average after a 250 µs sleep
/// on the reference VM (`cargo run --release -p microrobot-runtime --example
/// empty_poll`). So a stage does not poll an inbox that is nearly always empty at every
/// wake-up. Taking such an inbox on its event alone would lose samples, though: a
/// subscriber that has not received since a publisher appeared has no connection to it,
/// and if that publisher is gone by the time of the receive its sample is gone with it
/// (iceoryx2 0.10; a subscriber connected before the publisher leaves keeps the sample).
/// A stage blocked past a short-lived sender's life, or an event that never came, would
/// then lose a command. The sweep connects each inbox to a new publisher within 1 ms and
/// a period of its appearance, and `microrobot send` waits at least 20 ms between
/// creating its publisher and sending (the bus contract asks the same of every
/// short-lived sender).
pub const SWEEP_NS: u64 = 1_000_000;

impl Cycle<'_> {
    /// Publishes the status at the end of this wake-up rather than at the next period
    /// (a command's sender waits for its verdict).
    pub fn publish_status_now(&mut self) {
        self.publish_status = true;
    }

    /// Publishes the status at once, in the middle of the wake-up, after `fill` wrote
    /// into it (the counters are those of the last [`Stage::report`]): e.g. the
    /// actuator saying it is about to block inside a lifecycle hook. Another status
    /// follows at the end of this wake-up.
    pub fn publish_status_with(&mut self, fill: impl FnOnce(&mut ServiceStatus)) {
        fill(self.status);
        self.status_port.publish(monotonic_ns(), self.status);
        self.publish_status = true;
    }
}

/// What the set-up before the cycle may use: the node to open ports on, the config,
/// the stop request and the status port (a stage that waits for something before its
/// cycle says so in its status meanwhile).
pub struct SetUp<'a> {
    /// The service's iceoryx2 node.
    pub node: &'a Node<ipc::Service>,
    /// The resolved pipeline config.
    pub cfg: &'a PipelineConfig,
    /// The stop request: a set-up that waits returns `Ok(None)` once it is asked for.
    pub shutdown: &'a Shutdown,
    status_port: StatusPort,
    status: ServiceStatus,
}

impl<'a> SetUp<'a> {
    /// The pipeline instance.
    pub fn instance(&self) -> &'a str {
        &self.cfg.instance
    }

    /// Publishes a status written by `fill` now (e.g. `Inactive` while waiting).
    pub fn publish_status(&mut self, fill: impl FnOnce(&mut ServiceStatus)) {
        fill(&mut self.status);
        self.status_port.publish(monotonic_ns(), &mut self.status);
    }
}

/// Runs the service `role` until `shutdown`: opens its node and status port, calls
/// `set_up` (which opens the ports, waits for what the stage needs and builds it;
/// `Ok(None)` when a stop came first), publishes the first status, enters the cycle
/// (CPU pinning and SCHED_FIFO) and wakes the stage on its sources until the stop; then
/// [`Stage::finish`] and the final status.
pub fn serve<S: Stage>(
    cfg: &PipelineConfig,
    shutdown: &Shutdown,
    role: ServiceRole,
    set_up: impl FnOnce(&mut SetUp<'_>) -> anyhow::Result<Option<(S, S::Ports)>>,
) -> anyhow::Result<()> {
    use anyhow::Context as _;
    let node = open_node(&cfg.instance, role)?;
    let status_port = StatusPort::open(&node, &cfg.instance, role, cfg.status_period_ms)?;
    let mut setup = SetUp {
        node: &node,
        cfg,
        shutdown,
        status_port,
        status: ServiceStatus::default(),
    };
    let built = set_up(&mut setup)?;
    let SetUp {
        mut status_port,
        mut status,
        ..
    } = setup;
    let Some((mut stage, ports)) = built else {
        status_port.publish_final(&mut status, |_| {});
        return Ok(());
    };

    let mut reactor = Reactor::new().context("epoll")?;
    let on = S::register(&ports, &mut reactor).context("epoll")?;
    let on_stop = reactor.add(shutdown).context("epoll")?;
    let now = monotonic_ns();
    stage.report(&mut status);
    status_port.measure(now, &mut status, |st| stage.report_latency(st));
    status_port.publish(now, &mut status);

    // Set up: from here on the loop runs pinned and SCHED_FIFO.
    let mut housekeeping = crate::enter_cycle(cfg);
    // The first wake-up sweeps; after that, the one after a wake-up that ended
    // `SWEEP_NS` or more after the last sweep.
    let (mut sweep, mut swept_ns) = (true, 0);
    while !shutdown.is_requested() {
        let ready = reactor.wait().context("epoll_wait")?;
        if ready.contains(on_stop) || shutdown.is_requested() {
            break;
        }
        let mut cycle = Cycle {
            cfg,
            shutdown,
            status: &mut status,
            status_port: &mut status_port,
            publish_status: false,
            sweep,
        };
        stage.wake(&ports, on, ready, &mut cycle)?;
        let asked = cycle.publish_status;
        let now = monotonic_ns();
        if sweep {
            swept_ns = now;
        }
        sweep = now.saturating_sub(swept_ns) >= SWEEP_NS;
        if asked || status_port.due(now) {
            let measure = status_port.measure_due(now);
            // Below the cycle's priority: the stage this wake-up's message woke goes first.
            housekeeping.run(|| {
                stage.report(&mut status);
                if measure {
                    status_port.measure(now, &mut status, |st| stage.report_latency(st));
                }
                status_port.publish(now, &mut status);
            });
        }
    }
    stage.finish(&ports);
    stage.report(&mut status);
    status_port.publish_final(&mut status, |st| stage.report_latency(st));
    Ok(())
}
