//! The runner's status: the counters ([`Stage::report`]) are fresh in every status, the
//! costly measurements (the stage's latency summaries, [`Stage::report_latency`], and the
//! resident set size) are refreshed in the first status, at most once per
//! [`MEASURE_PERIOD_NS`] after it, and in the final status.

use std::cell::Cell;
use std::time::{Duration, Instant};

use microrobot_messages::{LifecycleState, ServiceRole, ServiceStatus, monotonic_ns, topic};
use microrobot_runtime::node::named_node;
use microrobot_runtime::status::MEASURE_PERIOD_NS;
use microrobot_runtime::{
    Cycle, Inbox, Reactor, Ready, Shutdown, Source, Stage, Subscription, TimerFd, serve,
};

mod common;

/// The stage's tick: 1 kHz.
const TICK_NS: u64 = 1_000_000;

/// Counts its wake-ups; `report` says how many in `cycles`, `report_latency` in
/// `latency.count` (and how often it was asked in `latency.p50_ns`).
struct Counter {
    wakes: u64,
    measured: Cell<u64>,
}

impl Stage for Counter {
    type Ports = TimerFd;
    type Sources = Source;

    fn register<'p>(tick: &'p TimerFd, reactor: &mut Reactor<'p>) -> std::io::Result<Source> {
        reactor.add(tick)
    }

    fn wake(
        &mut self,
        tick: &TimerFd,
        _on: Source,
        _ready: Ready,
        _cycle: &mut Cycle<'_>,
    ) -> anyhow::Result<()> {
        self.wakes += tick.read_expirations();
        Ok(())
    }

    fn report(&self, status: &mut ServiceStatus) {
        status.cycles = self.wakes;
    }

    fn report_latency(&self, status: &mut ServiceStatus) {
        self.measured.set(self.measured.get() + 1);
        status.latency.count = self.wakes;
        status.latency.p50_ns = self.measured.get();
    }
}

#[test]
fn counters_are_fresh_in_every_status_and_measurements_at_most_once_a_period() {
    let instance = format!(
        "measure{}-{}",
        std::process::id(),
        monotonic_ns() % 1_000_000
    );
    let mut cfg = common::plain_config(&instance);
    cfg.status_period_ms = 20.0;

    let node = named_node(&format!("measure.{}", std::process::id())).unwrap();
    let statuses = Inbox::open(
        &node,
        &instance,
        topic::STATUS,
        Subscription::CYCLIC.polled(),
    )
    .unwrap();
    let shutdown = Shutdown::new().unwrap();
    let runner = {
        let (cfg, shutdown) = (cfg.clone(), shutdown.clone());
        std::thread::spawn(move || {
            serve(&cfg, &shutdown, ServiceRole::Planner, |_| {
                let tick = TimerFd::new()?;
                tick.arm_absolute(monotonic_ns() + TICK_NS, TICK_NS)?;
                let stage = Counter {
                    wakes: 0,
                    measured: Cell::new(0),
                };
                Ok(Some((stage, tick)))
            })
        })
    };

    // 2.5 measure periods of statuses from the first, taken every 10 ms (the queue
    // holds far more).
    let mut seen: Vec<ServiceStatus> = Vec::new();
    let give_up = Instant::now() + Duration::from_secs(10);
    while seen.is_empty() {
        assert!(Instant::now() < give_up, "no first status");
        statuses.for_each(|r| seen.push(r.msg));
        std::thread::sleep(Duration::from_millis(1));
    }
    let start = Instant::now();
    let window = Duration::from_nanos(MEASURE_PERIOD_NS * 5 / 2);
    while start.elapsed() < window {
        statuses.for_each(|r| seen.push(r.msg));
        std::thread::sleep(Duration::from_millis(10));
    }
    shutdown.request();
    runner.join().unwrap().unwrap();
    let give_up = Instant::now() + Duration::from_secs(10);
    while seen
        .last()
        .is_none_or(|s| s.lifecycle != LifecycleState::Finalized as u32)
    {
        assert!(Instant::now() < give_up, "no final status");
        statuses.for_each(|r| seen.push(r.msg));
        std::thread::sleep(Duration::from_millis(10));
    }

    let (last, periodic) = seen.split_last().unwrap();
    // Counters: a status per period, each with the wake-ups up to it.
    assert!(periodic.len() >= 50, "{} statuses in 2.5 s", periodic.len());
    assert!(periodic.windows(2).all(|w| w[0].cycles <= w[1].cycles));
    let counted: std::collections::BTreeSet<u64> = periodic.iter().map(|s| s.cycles).collect();
    assert!(
        counted.len() >= 50,
        "the counters were not fresh: {counted:?}"
    );

    // Measurements: the first status, then once per period (three in 2.5 periods), each
    // status carrying the last one; every status has the resident set size.
    let refreshes: std::collections::BTreeSet<u64> =
        periodic.iter().map(|s| s.latency.p50_ns).collect();
    assert_eq!(
        refreshes,
        (1..=3).collect(),
        "refreshes seen in the periodic statuses"
    );
    let first_of = |n: u64| {
        periodic
            .iter()
            .find(|s| s.latency.p50_ns == n)
            .map(|s| s.stamp_ns)
            .unwrap()
    };
    assert!(first_of(2) - first_of(1) >= MEASURE_PERIOD_NS);
    assert!(first_of(3) - first_of(2) >= MEASURE_PERIOD_NS);
    assert!(periodic.iter().all(|s| s.rss_kib > 0));
    assert!(periodic.iter().all(|s| s.latency.count <= s.cycles));

    // The final status is measured afresh: its summary covers every wake-up.
    assert_eq!(last.latency.p50_ns, 4);
    assert_eq!(last.latency.count, last.cycles);
    assert!(
        last.cycles > 2000,
        "{} wake-ups in 2.5 s at 1 kHz",
        last.cycles
    );
}
