//! The status stream of one instance, as seen by the supervisor, `top` and `send`: the
//! latest [`ServiceStatus`] per role, plus the one before it (for rates).

use std::time::{Duration, Instant};

use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::*;
use microrobot_messages::{ServiceKind, ServiceRole, ServiceStatus, open_publish_subscribe};

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

/// Subscriber to the status stream with the latest status per role.
pub struct StatusMonitor {
    _node: Node<ipc::Service>,
    subscriber: Subscriber<ipc::Service, ServiceStatus, ()>,
    /// Latest per role (index: [`slot`]).
    pub latest: [Option<Seen>; 3],
    /// The one before the latest, per role.
    pub previous: [Option<Seen>; 3],
    /// Statuses stamped before this (per role) are ignored: a predecessor's.
    pub not_before_ns: [u64; 3],
}

impl StatusMonitor {
    /// Subscribes to the status stream of `instance` with a node named `node_name`.
    pub fn open(instance: &str, node_name: &str) -> anyhow::Result<Self> {
        let node = microrobot_runtime::node::named_node(node_name)?;
        Self::with_node(node, instance)
    }

    /// Subscribes to the status stream of `instance` with `node`.
    pub fn with_node(node: Node<ipc::Service>, instance: &str) -> anyhow::Result<Self> {
        let subscriber =
            open_publish_subscribe::<ServiceStatus>(&node, instance, ServiceKind::Status)?
                .subscriber_builder()
                .create()
                .map_err(|e| anyhow::anyhow!("status subscriber: {e:?}"))?;
        Ok(Self {
            _node: node,
            subscriber,
            latest: [None; 3],
            previous: [None; 3],
            not_before_ns: [0; 3],
        })
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
            let st = match self.subscriber.receive() {
                Ok(Some(sample)) => *sample,
                Ok(None) => break,
                Err(e) => anyhow::bail!("status receive: {e:?}"),
            };
            let Some(role) = ServiceRole::from_wire(st.role) else {
                continue;
            };
            let i = slot(role);
            if st.stamp_ns < self.not_before_ns[i] {
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

    /// Forgets `role`'s statuses and ignores those stamped before `ns` (a restart).
    pub fn reset(&mut self, role: ServiceRole, ns: u64) {
        let i = slot(role);
        self.latest[i] = None;
        self.previous[i] = None;
        self.not_before_ns[i] = ns;
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
