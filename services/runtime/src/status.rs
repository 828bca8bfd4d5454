//! The ~10 Hz status/heartbeat publisher every service owns: fills identity, stamp and
//! CPU time, and publishes on the Status service (plus its event).
//!
//! Measurements that cost more than the rest of a status together are refreshed at most
//! once per [`MEASURE_PERIOD_NS`] (and in the final status): the resident set size (a
//! `/proc/self/statm` read, about 18 µs after a status period's sleep) and the stage's
//! latency percentiles ([`crate::Stage::report_latency`], a scan of each histogram's
//! counts, about 10 µs). Between refreshes a status carries the last values; the
//! counters, the lifecycle and the CPU time are fresh in every status.

use iceoryx2::prelude::*;
use microrobot_messages::{LifecycleState, ServiceRole, ServiceStatus, monotonic_ns, topic};

use crate::ports::Outbox;

use crate::stats::{RssReader, cpu_time_ms};

/// The shortest time between two refreshes of a status's costly measurements (ns): the
/// resident set size and the latency percentiles. `cargo run --release -p
/// microrobot-runtime --example summary_cost` measures what they cost.
pub const MEASURE_PERIOD_NS: u64 = 1_000_000_000;

/// Publishes [`ServiceStatus`] at the configured period.
pub struct StatusPort {
    out: Outbox<ServiceStatus>,
    rss: RssReader,
    period_ns: u64,
    next_due_ns: u64,
    next_measure_ns: u64,
    seq: u64,
    role: ServiceRole,
    pid: u32,
}

impl StatusPort {
    /// Opens the Status service of `instance` for `role`.
    pub fn open(
        node: &Node<ipc::Service>,
        instance: &str,
        role: ServiceRole,
        period_ms: f64,
    ) -> anyhow::Result<Self> {
        Ok(Self {
            out: Outbox::open(node, instance, topic::STATUS)?,
            rss: RssReader::new(),
            period_ns: crate::config::ms_to_ns(period_ms),
            next_due_ns: 0,
            next_measure_ns: 0,
            seq: 0,
            role,
            pid: std::process::id(),
        })
    }

    /// Whether a periodic status is due at `now_ns`.
    #[inline]
    pub fn due(&self, now_ns: u64) -> bool {
        now_ns >= self.next_due_ns
    }

    /// Whether the costly measurements are due at `now_ns` (the first status, then at
    /// most once per [`MEASURE_PERIOD_NS`]); [`StatusPort::measure`] takes them.
    #[inline]
    pub fn measure_due(&self, now_ns: u64) -> bool {
        now_ns >= self.next_measure_ns
    }

    /// Refreshes every costly measurement in `st`, the stage's (`stage_latency`, e.g.
    /// [`crate::Stage::report_latency`]) and the port's own (the resident set size), and
    /// schedules the next refresh: one call, so neither is refreshed without the other.
    pub fn measure(
        &mut self,
        now_ns: u64,
        st: &mut ServiceStatus,
        stage_latency: impl FnOnce(&mut ServiceStatus),
    ) {
        stage_latency(st);
        st.rss_kib = self.rss.rss_kib();
        self.next_measure_ns = now_ns.saturating_add(MEASURE_PERIOD_NS);
    }

    /// Period in ns.
    pub fn period_ns(&self) -> u64 {
        self.period_ns
    }

    /// Fills the common fields of `st` and publishes it; schedules the next one.
    /// Errors are swallowed (status is best effort) and counted by the caller via the result.
    pub fn publish(&mut self, now_ns: u64, st: &mut ServiceStatus) -> bool {
        self.seq += 1;
        st.seq = self.seq;
        st.stamp_ns = now_ns;
        st.role = self.role as u32;
        st.pid = self.pid;
        st.cpu_time_ms = cpu_time_ms();
        self.next_due_ns = now_ns + self.period_ns;
        self.out.send(*st)
    }

    /// Publishes the final status (lifecycle Finalized), its measurements fresh
    /// (`stage_latency` as for [`StatusPort::measure`]).
    pub fn publish_final(
        &mut self,
        st: &mut ServiceStatus,
        stage_latency: impl FnOnce(&mut ServiceStatus),
    ) {
        st.lifecycle = LifecycleState::Finalized as u32;
        let now = monotonic_ns();
        self.measure(now, st, stage_latency);
        self.publish(now, st);
    }
}
