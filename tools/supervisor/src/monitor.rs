//! The status stream of one instance, as seen by the supervisor, `top` and `send`: the
//! latest [`ServiceStatus`] per role, plus the one before it (for rates).
//!
//! A status keeps a role alive in the supervisor's eyes and may announce a blocking
//! lifecycle hook that stretches its hang allowance, so the supervisor names the process
//! it started for each role ([`StatusMonitor::expect`]): from then on, only statuses
//! that claim that pid and whose iceoryx2 publisher was created by that process (the
//! node details, as [`microrobot_runtime::provenance`] reads them for the cyclic
//! streams) count for the role. Others (another process, a leftover of an earlier
//! instance) are dropped and reported once ([`StatusMonitor::take_refused`]).

use std::fmt;
use std::time::{Duration, Instant};

use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::*;
use iceoryx2::service::port_factory::publish_subscribe::PortFactory;
use microrobot_messages::{ServiceKind, ServiceRole, ServiceStatus, open_publish_subscribe};
use microrobot_runtime::provenance::publisher_pid;

/// Roles in pipeline start order.
pub const ROLES: [ServiceRole; 3] = [
    ServiceRole::Actuator,
    ServiceRole::Dynamics,
    ServiceRole::Planner,
];

/// Index of `role` in per-role arrays (planner 0, dynamics 1, actuator 2).
pub fn slot(role: ServiceRole) -> usize {
    match role {
        ServiceRole::Planner => 0,
        ServiceRole::Dynamics => 1,
        ServiceRole::Actuator => 2,
    }
}

/// One status and when it arrived here.
#[derive(Debug, Clone, Copy)]
pub struct Seen {
    pub status: ServiceStatus,
    pub at: Instant,
}

/// A status dropped because it does not come from the process started for its role.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Refused {
    pub role: ServiceRole,
    /// The pid the status claims (`ServiceStatus::pid`).
    pub claimed_pid: u32,
    /// The process that created the status's iceoryx2 publisher (`None`: not found, the
    /// publisher is gone).
    pub publisher_pid: Option<i32>,
    /// The process started for the role.
    pub expected_pid: u32,
}

impl fmt::Display for Refused {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let by = match self.publisher_pid {
            Some(p) => format!("published by pid {p}"),
            None => "from a publisher no live process owns".to_string(),
        };
        write!(
            f,
            "ignoring {} statuses that claim pid {} ({by}): the {} started here is pid {}",
            self.role.name(),
            self.claimed_pid,
            self.role.name(),
            self.expected_pid
        )
    }
}

/// How many refused origins are remembered (and so reported once); beyond, further ones
/// are still dropped, without a report.
const REPORTED_MAX: usize = 64;

/// Subscriber to the status stream with the latest status per role.
pub struct StatusMonitor {
    _node: Node<ipc::Service>,
    service: PortFactory<ipc::Service, ServiceStatus, ()>,
    subscriber: Subscriber<ipc::Service, ServiceStatus, ()>,
    /// Latest per role (index: [`slot`]).
    pub latest: [Option<Seen>; 3],
    /// The one before the latest, per role.
    pub previous: [Option<Seen>; 3],
    /// Statuses stamped before this (per role) are ignored: a predecessor's.
    pub not_before_ns: [u64; 3],
    /// The process whose statuses alone count for a role (`None`: any publisher's).
    expected: [Option<u32>; 3],
    /// The publisher found to belong to the expected process, per role.
    owner: [Option<u128>; 3],
    /// Refused origins already reported, (slot, publisher, claimed pid), each with
    /// whether it is settled as another process's (else looked up again).
    reported: Vec<((usize, u128, u32), bool)>,
    /// Refusals not yet taken by [`Self::take_refused`].
    refused: Vec<Refused>,
}

impl StatusMonitor {
    /// Subscribes to the status stream of `instance` with a node named `node_name`.
    pub fn open(instance: &str, node_name: &str) -> anyhow::Result<Self> {
        let node = microrobot_runtime::node::named_node(node_name)?;
        Self::with_node(node, instance)
    }

    /// Subscribes to the status stream of `instance` with `node`.
    pub fn with_node(node: Node<ipc::Service>, instance: &str) -> anyhow::Result<Self> {
        let service =
            open_publish_subscribe::<ServiceStatus>(&node, instance, ServiceKind::Status)?;
        let subscriber = service
            .subscriber_builder()
            .create()
            .map_err(|e| anyhow::anyhow!("status subscriber: {e:?}"))?;
        Ok(Self {
            _node: node,
            service,
            subscriber,
            latest: [None; 3],
            previous: [None; 3],
            not_before_ns: [0; 3],
            expected: [None; 3],
            owner: [None; 3],
            reported: Vec::new(),
            refused: Vec::new(),
        })
    }

    /// From now on, counts for `role` only the statuses of process `pid` (the one the
    /// supervisor started for it): they must claim `pid` and come from a publisher that
    /// process created.
    pub fn expect(&mut self, role: ServiceRole, pid: u32) {
        let i = slot(role);
        self.expected[i] = Some(pid);
        self.owner[i] = None;
    }

    /// The statuses refused since the last call, each origin once.
    pub fn take_refused(&mut self) -> Vec<Refused> {
        std::mem::take(&mut self.refused)
    }

    /// Whether `st`, sent by `publisher`, counts for slot `i` (see [`Self::expect`]).
    /// Looks the publisher's process up once per origin: the owner and each origin found
    /// to be another process's are remembered; a publisher not found (gone, or not yet
    /// listed) is looked up again at its next status.
    fn admits(&mut self, i: usize, role: ServiceRole, st: &ServiceStatus, publisher: u128) -> bool {
        let Some(expected) = self.expected[i] else {
            return true;
        };
        if st.pid == expected && self.owner[i] == Some(publisher) {
            return true;
        }
        let key = (i, publisher, st.pid);
        let seen = self.reported.iter().position(|(k, _)| *k == key);
        if let Some(n) = seen
            && self.reported[n].1
        {
            return false;
        }
        let by = publisher_pid(&self.service, publisher);
        if st.pid == expected && by.is_some_and(|p| i64::from(p) == i64::from(expected)) {
            self.owner[i] = Some(publisher);
            return true;
        }
        // Another process's for certain: it claims another pid, or its publisher is.
        let settled = st.pid != expected || by.is_some();
        match seen {
            Some(n) => self.reported[n].1 = settled,
            None if self.reported.len() < REPORTED_MAX => {
                self.reported.push((key, settled));
                self.refused.push(Refused {
                    role,
                    claimed_pid: st.pid,
                    publisher_pid: by,
                    expected_pid: expected,
                });
            }
            None => {}
        }
        false
    }

    /// The node (to open more ports on it).
    pub fn node(&self) -> &Node<ipc::Service> {
        &self._node
    }

    /// Takes every waiting status; returns how many were new.
    pub fn poll(&mut self) -> anyhow::Result<usize> {
        Ok(self.poll_all()?.len())
    }

    /// Takes every waiting status; returns the new ones, oldest first.
    pub fn poll_all(&mut self) -> anyhow::Result<Vec<ServiceStatus>> {
        let mut new = Vec::new();
        loop {
            let (st, publisher) = match self.subscriber.receive() {
                Ok(Some(sample)) => (*sample, sample.header().publisher_id().value()),
                Ok(None) => break,
                Err(e) => anyhow::bail!("status receive: {e:?}"),
            };
            let Some(role) = ServiceRole::from_wire(st.role) else {
                continue;
            };
            let i = slot(role);
            if st.stamp_ns < self.not_before_ns[i] || !self.admits(i, role, &st, publisher) {
                continue;
            }
            if let Some(prev) = &self.latest[i]
                && prev.status.pid == st.pid
                && prev.status.seq >= st.seq
            {
                continue;
            }
            self.previous[i] = self.latest[i].take();
            self.latest[i] = Some(Seen {
                status: st,
                at: Instant::now(),
            });
            new.push(st);
        }
        Ok(new)
    }

    /// Forgets `role`'s statuses and ignores those stamped before `ns` (a restart); the
    /// process expected for it stays until the next [`Self::expect`].
    pub fn reset(&mut self, role: ServiceRole, ns: u64) {
        let i = slot(role);
        self.latest[i] = None;
        self.previous[i] = None;
        self.not_before_ns[i] = ns;
        self.owner[i] = None;
    }

    /// Latest status of `role`.
    pub fn get(&self, role: ServiceRole) -> Option<&ServiceStatus> {
        self.latest[slot(role)].as_ref().map(|s| &s.status)
    }

    /// Cycles per second of `role` between its last two statuses (same process).
    pub fn rate(&self, role: ServiceRole) -> Option<f64> {
        let i = slot(role);
        let (a, b) = (self.previous[i]?, self.latest[i]?);
        if a.status.pid != b.status.pid || b.status.stamp_ns <= a.status.stamp_ns {
            return None;
        }
        let dt = (b.status.stamp_ns - a.status.stamp_ns) as f64 * 1e-9;
        Some(b.status.cycles.saturating_sub(a.status.cycles) as f64 / dt)
    }

    /// Polls until `done` holds or `timeout` passes; returns whether `done` held.
    pub fn wait_for(
        &mut self,
        timeout: Duration,
        done: impl FnMut(&Self) -> bool,
    ) -> anyhow::Result<bool> {
        poll_until(
            self,
            timeout,
            Duration::from_millis(10),
            |m| m.poll().map(drop),
            done,
        )
    }
}

/// Runs `pump` on `subject` every `interval` until `done` holds for it (true) or
/// `timeout` passes (false): the wait of every bus watcher here (the status monitor,
/// driver-check's rig).
pub(crate) fn poll_until<S>(
    subject: &mut S,
    timeout: Duration,
    interval: Duration,
    mut pump: impl FnMut(&mut S) -> anyhow::Result<()>,
    mut done: impl FnMut(&S) -> bool,
) -> anyhow::Result<bool> {
    let end = Instant::now() + timeout;
    loop {
        pump(subject)?;
        if done(subject) {
            return Ok(true);
        }
        if Instant::now() >= end {
            return Ok(false);
        }
        std::thread::sleep(interval);
    }
}
