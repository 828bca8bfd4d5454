//! The ~10 Hz status/heartbeat publisher every service owns: fills identity, stamp,
//! CPU time and RSS, and publishes on the Status service (plus its event).

use iceoryx2::prelude::*;
use microrobot_messages::{LifecycleState, ServiceRole, ServiceStatus, monotonic_ns, topic};

use crate::ports::Outbox;

use crate::stats::{RssReader, cpu_time_ms};

/// Publishes [`ServiceStatus`] at the configured period.
pub struct StatusPort {
    out: Outbox<ServiceStatus>,
    rss: RssReader,
    period_ns: u64,
    next_due_ns: u64,
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
        st.rss_kib = self.rss.rss_kib();
        self.next_due_ns = now_ns + self.period_ns;
        self.out.send(*st)
    }

    /// Publishes the final status (lifecycle Finalized).
    pub fn publish_final(&mut self, st: &mut ServiceStatus) {
        st.lifecycle = LifecycleState::Finalized as u32;
        self.publish(monotonic_ns(), st);
    }
}
