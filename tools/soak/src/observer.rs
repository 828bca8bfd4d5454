//! The soak's online observer: a thread that drains the setpoint, torque, state and
//! status streams of the instance (every [`POLL_MS`] ms; each subscriber queues 64
//! messages, 64 ms at 1 kHz), checks every consecutive pair against the stream
//! invariants ([`microrobot_bus_tools::invariants`]), and keeps only what the report
//! needs: health edges (for the time to detect and recover each fault), safe-state
//! latches, lost-message increments of the services, resource samples, its own receive
//! gaps, and the per-hop latency budget measured from the messages' own stamps
//! ([`Hops`]).

use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::Duration;

use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::*;
use microrobot_messages::{
    Header, JointSetpoint, JointState, LifecycleState, MAX_JOINTS, ServiceKind, ServiceRole,
    ServiceStatus, TorqueCommand, monotonic_ns, open_publish_subscribe, setpoint_flags,
    state_flags, torque_flags,
};
use serde::{Deserialize, Serialize};

use microrobot_runtime::stats::LatencyHistogram;

use microrobot_bus_tools::invariants::{self, Bounds, Jump};

/// Drain period of the observer thread.
pub const POLL_MS: u64 = 2;
/// A resource sample per service at most this often.
const RESOURCE_SAMPLE_NS: u64 = 2_000_000_000;

/// A change of health seen on a stream.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum EdgeKind {
    /// The actuator reports stale commands or its safe state (or is not active).
    StateUnhealthy,
    /// The actuator follows fresh torque commands again.
    StateHealthy,
    /// The safe state latched (rising edge of SAFE_STATE, or a restart that came up in it).
    Latch,
    /// Dynamics computes without fresh measured state.
    TorqueStale,
    TorqueFresh,
    /// The planner mirrors the measured arm (the actuator's safe state).
    SetpointHold,
    SetpointFree,
    /// A new publisher (process) on the stream.
    NewSetpointPublisher,
    NewTorquePublisher,
    NewStatePublisher,
}

/// One edge, stamped with the message's own `CLOCK_MONOTONIC` time.
#[derive(Debug, Clone, Copy, Serialize, Deserialize)]
pub struct Edge {
    pub stamp_ns: u64,
    pub kind: EdgeKind,
}

/// Lost messages a service counted between two of its statuses.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Loss {
    pub stamp_ns: u64,
    pub role: String,
    pub count: u64,
}

/// One resource sample of one service process.
#[derive(Debug, Clone, Copy, Serialize, Deserialize)]
pub struct ResourceSample {
    pub stamp_ns: u64,
    pub pid: u32,
    pub rss_kib: u64,
    pub cpu_time_ms: u32,
}

/// Torque stamps kept for joining a state to the torque it applied (by `torque_seq`).
const TORQUE_STAMPS: usize = 1024;
/// States waiting for a torque the observer has not read yet (see `time_state`).
const PENDING_STATES: usize = 16;

/// The pipeline's latency split by hop, from the stamps every message carries
/// (`stamp_ns` when written, `source_stamp_ns` of the setpoint it derives from; all
/// `CLOCK_MONOTONIC`, so the hops add up on one clock):
/// - `setpoint_to_torque`: setpoint published → torque published (the dynamics'
///   wake-up, its computation and its write);
/// - `torque_to_state`: torque published → the first state published that applied it
///   (the actuator's wake-up, its plant or bus step and its write);
/// - `setpoint_to_state`: the whole chain on the bus, setpoint → that state.
///
/// The actuator's own end-to-end figure (setpoint published → torque received) sits
/// between the first hop and the chain. Histograms are made up front; recording never
/// allocates.
#[derive(Debug, Default)]
pub struct Hops {
    pub setpoint_to_torque: LatencyHistogram,
    pub torque_to_state: LatencyHistogram,
    pub setpoint_to_state: LatencyHistogram,
}

impl Hops {
    /// The hops by name, in chain order.
    pub fn named(&self) -> [(&'static str, &LatencyHistogram); 3] {
        [
            ("setpoint_to_torque", &self.setpoint_to_torque),
            ("torque_to_state", &self.torque_to_state),
            ("setpoint_to_state", &self.setpoint_to_state),
        ]
    }
}

/// What the observer hands back at the end.
#[derive(Debug, Default)]
pub struct Observed {
    /// Latency per hop (see [`Hops`]).
    pub hops: Hops,
    pub edges: Vec<Edge>,
    pub jumps: Vec<Jump>,
    pub losses: Vec<Loss>,
    /// Per role (planner, dynamics, actuator).
    pub resources: [Vec<ResourceSample>; 3],
    /// Messages received per stream (setpoint, torque, state, status).
    pub received: [u64; 4],
    /// Messages the observer itself missed (its queue overflowed), per stream.
    pub observer_gaps: [u64; 4],
    /// Jumps dropped from `jumps` beyond [`MAX_JUMPS_KEPT`] (still counted).
    pub jumps_not_listed: u64,
}

/// Jumps kept with details (all are counted).
pub const MAX_JUMPS_KEPT: usize = 1000;

/// Live counters for the progress line.
#[derive(Debug, Default)]
pub struct Live {
    pub jumps: AtomicU64,
    pub latches: AtomicU64,
    pub setpoints: AtomicU64,
}

/// The state the supervisor handed to a restarting actuator (the reference its first
/// state must equal).
pub type Handover = Arc<Mutex<Option<JointState>>>;

/// The running observer thread.
pub struct Observer {
    stop: Arc<AtomicBool>,
    pub live: Arc<Live>,
    pub handover: Handover,
    handle: Option<JoinHandle<anyhow::Result<Observed>>>,
}

fn subscriber<T: std::fmt::Debug + ZeroCopySend + 'static>(
    node: &Node<ipc::Service>,
    instance: &str,
    kind: ServiceKind,
) -> anyhow::Result<Subscriber<ipc::Service, T, ()>> {
    open_publish_subscribe::<T>(node, instance, kind)?
        .subscriber_builder()
        .buffer_size(microrobot_messages::ports::qos::SUBSCRIBER_BUFFER)
        .create()
        .map_err(|e| anyhow::anyhow!("{} subscriber: {e:?}", kind.stream_name()))
}

impl Observer {
    /// Opens the subscribers (before the pipeline starts, so nothing is missed) and
    /// starts the thread.
    pub fn start(instance: &str, bounds: Bounds) -> anyhow::Result<Self> {
        let stop = Arc::new(AtomicBool::new(false));
        let live = Arc::new(Live::default());
        let (ready_tx, ready_rx) = std::sync::mpsc::channel();
        let inst = instance.to_string();
        let handover: Handover = Arc::new(Mutex::new(None));
        let (s2, l2, h2) = (stop.clone(), live.clone(), handover.clone());
        let handle = std::thread::Builder::new()
            .name("soak-observer".into())
            .spawn(move || {
                let node_name = format!("microrobot-soak-observer.{inst}");
                let setup = (|| -> anyhow::Result<_> {
                    let node = microrobot_runtime::node::named_node(&node_name)?;
                    let sp = subscriber::<JointSetpoint>(&node, &inst, ServiceKind::Setpoint)?;
                    let tq = subscriber::<TorqueCommand>(&node, &inst, ServiceKind::Torque)?;
                    let st = subscriber::<JointState>(&node, &inst, ServiceKind::State)?;
                    let ss = subscriber::<ServiceStatus>(&node, &inst, ServiceKind::Status)?;
                    Ok((node, sp, tq, st, ss))
                })();
                let (_node, sp, tq, st, ss) = match setup {
                    Ok(v) => {
                        let _ = ready_tx.send(Ok(()));
                        v
                    }
                    Err(e) => {
                        let _ = ready_tx.send(Err(format!("{e:#}")));
                        return Err(e);
                    }
                };
                let mut checker = Checker::new(bounds, l2, h2);
                loop {
                    let stopping = s2.load(Ordering::SeqCst);
                    while let Ok(Some(s)) = sp.receive() {
                        let p = s.header().publisher_id().value();
                        checker.setpoint(&s, p);
                    }
                    while let Ok(Some(s)) = tq.receive() {
                        let p = s.header().publisher_id().value();
                        checker.torque(&s, p);
                    }
                    while let Ok(Some(s)) = st.receive() {
                        let p = s.header().publisher_id().value();
                        checker.state(&s, p);
                    }
                    while let Ok(Some(s)) = ss.receive() {
                        checker.status(&s);
                    }
                    if stopping {
                        break;
                    }
                    std::thread::sleep(Duration::from_millis(POLL_MS));
                }
                Ok(checker.out)
            })?;
        match ready_rx.recv() {
            Ok(Ok(())) => {}
            Ok(Err(e)) => anyhow::bail!("soak observer: {e}"),
            Err(_) => anyhow::bail!("soak observer thread ended at start"),
        }
        Ok(Self {
            stop,
            live,
            handover,
            handle: Some(handle),
        })
    }

    /// Stops the thread after a last drain and returns what it saw.
    pub fn finish(mut self) -> anyhow::Result<Observed> {
        self.stop.store(true, Ordering::SeqCst);
        match self.handle.take().map(|h| h.join()) {
            Some(Ok(r)) => r,
            Some(Err(_)) => anyhow::bail!("the soak observer thread panicked"),
            None => anyhow::bail!("the soak observer was already finished"),
        }
    }
}

/// The last message of a stream and the publisher it came from.
struct Last<T> {
    msg: T,
    publisher: u128,
}

/// The per-stream state of the checks (no I/O; fed one message at a time).
pub struct Checker {
    bounds: Bounds,
    live: Arc<Live>,
    handover: Handover,
    pub out: Observed,
    setpoint: Option<Last<JointSetpoint>>,
    /// Set on a new planner process: its first free setpoint is judged against the
    /// measured state.
    planner_started: bool,
    setpoint_hold: bool,
    torque: Option<Last<TorqueCommand>>,
    torque_stale: bool,
    state: Option<Last<JointState>>,
    /// The arm's measured acceleration between the last two states of one process.
    state_acc: [f64; MAX_JOINTS],
    /// The predecessor's last state, until the restarted actuator's first plant step.
    resumed_from: Option<JointState>,
    state_healthy: Option<bool>,
    state_safe: bool,
    /// Per role: last status (pid, lost, last resource sample time).
    status: [Option<(u32, u64, u64)>; 3],
    /// `(seq, stamp_ns)` of recent torques of the current torque publisher, at
    /// `seq % TORQUE_STAMPS`.
    torque_stamps: Box<[(u64, u64); TORQUE_STAMPS]>,
    /// The last `torque_seq` a state was timed for (a free-running actuator applies one
    /// torque over several plant steps; only the first state that applied it counts).
    timed_torque_seq: u64,
    /// The newest torque seq read from the current torque publisher.
    newest_torque_seq: Option<u64>,
    /// States (their torque seq and header) whose torque the observer has not read yet.
    pending_states: Vec<(u64, Header)>,
}

fn role_slot(role: ServiceRole) -> usize {
    microrobot_supervisor::monitor::slot(role)
}

impl Checker {
    pub fn new(bounds: Bounds, live: Arc<Live>, handover: Handover) -> Self {
        Self {
            bounds,
            live,
            handover,
            out: Observed::default(),
            setpoint: None,
            planner_started: false,
            setpoint_hold: false,
            torque: None,
            torque_stale: false,
            state: None,
            state_acc: [0.0; MAX_JOINTS],
            resumed_from: None,
            state_healthy: None,
            state_safe: false,
            status: [None; 3],
            torque_stamps: Box::new([(u64::MAX, 0); TORQUE_STAMPS]),
            timed_torque_seq: u64::MAX,
            newest_torque_seq: None,
            pending_states: Vec::with_capacity(PENDING_STATES),
        }
    }

    /// Times the hops a torque closes (see [`Hops`]).
    fn time_torque(&mut self, m: &TorqueCommand, new_publisher: bool) {
        if new_publisher {
            self.torque_stamps.fill((u64::MAX, 0));
        }
        if new_publisher {
            self.newest_torque_seq = None;
        }
        self.torque_stamps[(m.header.seq % TORQUE_STAMPS as u64) as usize] =
            (m.header.seq, m.header.stamp_ns);
        self.newest_torque_seq = Some(m.header.seq);
        if let Some(i) = self
            .pending_states
            .iter()
            .position(|(s, _)| *s == m.header.seq)
        {
            let (_, h) = self.pending_states.remove(i);
            self.record_state_hops(h, m.header.stamp_ns);
        }
        self.pending_states.retain(|(s, _)| *s > m.header.seq);
        if m.header.source_stamp_ns > 0 && m.header.stamp_ns >= m.header.source_stamp_ns {
            self.out
                .hops
                .setpoint_to_torque
                .record(m.header.stamp_ns - m.header.source_stamp_ns);
        }
    }

    /// Times the hops a state closes: only the first state that applied a torque, and
    /// only a torque of the current publisher. The observer drains the torque stream
    /// before the state stream, so a state may name a torque it has not read yet: that
    /// state waits in `pending_states` for its torque.
    fn time_state(&mut self, m: &JointState, new_publisher: bool) {
        if new_publisher {
            self.timed_torque_seq = u64::MAX;
            self.pending_states.clear();
        }
        let seq = m.torque_seq;
        if seq == u64::MAX || seq == self.timed_torque_seq {
            return;
        }
        self.timed_torque_seq = seq;
        let (kept_seq, torque_stamp) = self.torque_stamps[(seq % TORQUE_STAMPS as u64) as usize];
        if kept_seq == seq {
            self.record_state_hops(m.header, torque_stamp);
        } else if self.newest_torque_seq.is_none_or(|n| seq > n) {
            if self.pending_states.len() == PENDING_STATES {
                self.pending_states.remove(0);
            }
            self.pending_states.push((seq, m.header));
        }
    }

    fn record_state_hops(&mut self, h: Header, torque_stamp_ns: u64) {
        if h.stamp_ns >= torque_stamp_ns {
            self.out
                .hops
                .torque_to_state
                .record(h.stamp_ns - torque_stamp_ns);
        }
        if h.source_stamp_ns > 0 && h.stamp_ns >= h.source_stamp_ns {
            self.out
                .hops
                .setpoint_to_state
                .record(h.stamp_ns - h.source_stamp_ns);
        }
    }

    fn edge(&mut self, stamp_ns: u64, kind: EdgeKind) {
        if kind == EdgeKind::Latch {
            self.live.latches.fetch_add(1, Ordering::Relaxed);
        }
        self.out.edges.push(Edge { stamp_ns, kind });
    }

    /// Records `found`, each annotated with the wall time between the pair's two
    /// messages (far from one period: a host stall, or the catch-up after one).
    fn jumps_after(&mut self, mut found: Vec<Jump>, prev_stamp_ns: Option<u64>, stamp_ns: u64) {
        if let Some(p) = prev_stamp_ns {
            let gap_ms = (stamp_ns as f64 - p as f64) * 1e-6;
            for j in &mut found {
                j.context = format!("{}; {gap_ms:.3} ms after the previous message", j.context);
            }
        }
        self.jumps(found);
    }

    fn jumps(&mut self, mut found: Vec<Jump>) {
        if found.is_empty() {
            return;
        }
        self.live
            .jumps
            .fetch_add(found.len() as u64, Ordering::Relaxed);
        let room = MAX_JUMPS_KEPT.saturating_sub(self.out.jumps.len());
        if found.len() > room {
            self.out.jumps_not_listed += (found.len() - room) as u64;
            found.truncate(room);
        }
        self.out.jumps.append(&mut found);
    }

    pub fn setpoint(&mut self, m: &JointSetpoint, publisher: u128) {
        self.out.received[0] += 1;
        self.live.setpoints.fetch_add(1, Ordering::Relaxed);
        let mut found = Vec::new();
        let hold = m.flags & setpoint_flags::HOLD_FOR_SAFE_STATE != 0;
        match &self.setpoint {
            Some(last) if last.publisher == publisher => {
                let gap = m.header.seq.saturating_sub(last.msg.header.seq + 1);
                self.out.observer_gaps[0] += gap;
                if self.planner_started && !hold {
                    self.planner_start_check(m, &mut found);
                } else {
                    invariants::setpoint_pair(&self.bounds, &last.msg, m, &mut found);
                }
            }
            prev => {
                if prev.is_some() {
                    self.edge(m.header.stamp_ns, EdgeKind::NewSetpointPublisher);
                }
                self.planner_started = true;
                if !hold {
                    self.planner_start_check(m, &mut found);
                }
            }
        }
        if hold != self.setpoint_hold {
            self.setpoint_hold = hold;
            let k = if hold {
                EdgeKind::SetpointHold
            } else {
                EdgeKind::SetpointFree
            };
            self.edge(m.header.stamp_ns, k);
        }
        let prev = self.setpoint.as_ref().map(|l| l.msg.header.stamp_ns);
        self.jumps_after(found, prev, m.header.stamp_ns);
        self.setpoint = Some(Last { msg: *m, publisher });
    }

    /// A (re)started planner's first free setpoint against the newest measured state.
    fn planner_start_check(&mut self, m: &JointSetpoint, found: &mut Vec<Jump>) {
        self.planner_started = false;
        if let Some(s) = &self.state {
            let age = m.header.stamp_ns.saturating_sub(s.msg.header.stamp_ns) as f64 * 1e-9;
            invariants::setpoint_start(&self.bounds, &s.msg, &self.state_acc, age, m, found);
        }
    }

    pub fn torque(&mut self, m: &TorqueCommand, publisher: u128) {
        self.out.received[1] += 1;
        let new_publisher = self
            .torque
            .as_ref()
            .is_some_and(|l| l.publisher != publisher);
        self.time_torque(m, new_publisher);
        let mut found = Vec::new();
        match &self.torque {
            Some(last) if last.publisher == publisher => {
                let gap = m.header.seq.saturating_sub(last.msg.header.seq + 1);
                self.out.observer_gaps[1] += gap;
                // A command reaches the arm unblended only while the actuator follows
                // commands. Latched or holding on its own, it ignores them and blends
                // over `ramp_ms` when it follows them again; and dynamics switches
                // between feedback and feed-forward only when the measured state has
                // been missing for `stale_ms` (a dead or stalled actuator). There the
                // applied torque is what reaches the arm, and the state stream judges it.
                let switch = (last.msg.flags ^ m.flags) & torque_flags::STATE_STALE != 0;
                let followed = self.state_healthy != Some(false);
                if followed && !switch {
                    invariants::torque_pair(&self.bounds, &last.msg, m, &mut found);
                }
            }
            Some(_) => self.edge(m.header.stamp_ns, EdgeKind::NewTorquePublisher),
            None => {}
        }
        let stale = m.flags & torque_flags::STATE_STALE != 0;
        if stale != self.torque_stale {
            self.torque_stale = stale;
            let k = if stale {
                EdgeKind::TorqueStale
            } else {
                EdgeKind::TorqueFresh
            };
            self.edge(m.header.stamp_ns, k);
        }
        let prev = self.torque.as_ref().map(|l| l.msg.header.stamp_ns);
        self.jumps_after(found, prev, m.header.stamp_ns);
        self.torque = Some(Last { msg: *m, publisher });
    }

    pub fn state(&mut self, m: &JointState, publisher: u128) {
        self.out.received[2] += 1;
        let new_publisher = self
            .state
            .as_ref()
            .is_some_and(|l| l.publisher != publisher);
        self.time_state(m, new_publisher);
        let mut found = Vec::new();
        match &self.state {
            Some(last) if last.publisher == publisher => {
                let steps = m.header.seq.saturating_sub(last.msg.header.seq);
                let dt = steps.max(1) as f64 * self.bounds.period_s;
                for i in 0..self.bounds.dof {
                    self.state_acc[i] = (m.qd[i] - last.msg.qd[i]) / dt;
                }
                self.out.observer_gaps[2] += steps.saturating_sub(1);
                match self.resumed_from {
                    // The restarted actuator's first plant step: its applied torque
                    // against its predecessor's last one.
                    Some(prev) if steps == 1 => {
                        self.resumed_from = None;
                        invariants::applied_torque_resume(&self.bounds, &prev, m, &mut found);
                        let mut from = last.msg;
                        from.tau_applied = m.tau_applied;
                        invariants::state_pair(&self.bounds, &from, m, 1, &mut found);
                    }
                    Some(_) => self.resumed_from = None,
                    // The shutdown state of a clean stop: the backend went inactive
                    // (brakes on) without a plant step.
                    None if m.lifecycle == LifecycleState::Inactive as u32
                        && last.msg.lifecycle != LifecycleState::Inactive as u32 =>
                    {
                        invariants::state_shutdown(&self.bounds, &last.msg, m, &mut found)
                    }
                    None => invariants::state_pair(&self.bounds, &last.msg, m, steps, &mut found),
                }
            }
            Some(last) => {
                // The reference: what the supervisor handed over (it drained the dead
                // actuator's stream after its exit), else the last state seen here.
                let handed = self.handover.lock().ok().and_then(|mut h| h.take());
                let prev = handed.unwrap_or(last.msg);
                self.edge(m.header.stamp_ns, EdgeKind::NewStatePublisher);
                invariants::state_resume(&self.bounds, &prev, m, &mut found);
                self.resumed_from = Some(prev);
            }
            None => {}
        }
        let safe = m.flags & state_flags::SAFE_STATE != 0;
        if safe && !self.state_safe {
            self.edge(m.header.stamp_ns, EdgeKind::Latch);
        }
        self.state_safe = safe;
        let healthy = m.flags & (state_flags::SAFE_STATE | state_flags::COMMAND_STALE) == 0
            && m.lifecycle == LifecycleState::Active as u32;
        if self.state_healthy != Some(healthy) {
            // The very first state (before any torque) is not an edge.
            if self.state_healthy.is_some() {
                let k = if healthy {
                    EdgeKind::StateHealthy
                } else {
                    EdgeKind::StateUnhealthy
                };
                self.edge(m.header.stamp_ns, k);
            }
            self.state_healthy = Some(healthy);
        }
        let prev = self.state.as_ref().map(|l| l.msg.header.stamp_ns);
        self.jumps_after(found, prev, m.header.stamp_ns);
        self.state = Some(Last { msg: *m, publisher });
    }

    pub fn status(&mut self, m: &ServiceStatus) {
        self.out.received[3] += 1;
        let Some(role) = ServiceRole::from_wire(m.role) else {
            return;
        };
        let i = role_slot(role);
        let (lost_before, sampled_at) = match self.status[i] {
            Some((pid, lost, at)) if pid == m.pid => (lost, at),
            _ => (0, 0),
        };
        if m.lost_messages > lost_before {
            self.out.losses.push(Loss {
                stamp_ns: m.stamp_ns,
                role: role.name().to_string(),
                count: m.lost_messages - lost_before,
            });
        }
        let mut at = sampled_at;
        if m.stamp_ns.saturating_sub(sampled_at) >= RESOURCE_SAMPLE_NS {
            at = m.stamp_ns;
            self.out.resources[i].push(ResourceSample {
                stamp_ns: m.stamp_ns,
                pid: m.pid,
                rss_kib: m.rss_kib,
                cpu_time_ms: m.cpu_time_ms,
            });
        }
        self.status[i] = Some((m.pid, m.lost_messages.max(lost_before), at));
    }
}

/// `CLOCK_MONOTONIC` now (re-exported for the soak's own timeline).
pub fn now_ns() -> u64 {
    monotonic_ns()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn checker() -> Checker {
        let b = Bounds {
            dof: 1,
            period_s: 1e-3,
            tol: 0.5,
            vmax: [10.0; MAX_JOINTS],
            amax: [1e3; MAX_JOINTS],
            tau_max: [1e3; MAX_JOINTS],
            noise_q: 0.0,
            noise_qd: 0.0,
        };
        Checker::new(b, Arc::new(Live::default()), Arc::new(Mutex::new(None)))
    }

    /// A torque of `seq` for the setpoint published at `source_ns`, written at `stamp_ns`.
    fn torque(seq: u64, source_ns: u64, stamp_ns: u64) -> TorqueCommand {
        let mut t = TorqueCommand::default();
        t.header.seq = seq;
        t.header.tick = seq;
        t.header.source_stamp_ns = source_ns;
        t.header.stamp_ns = stamp_ns;
        t.setpoint_seq = seq;
        t.dof = 1;
        t
    }

    fn state(seq: u64, torque_seq: u64, source_ns: u64, stamp_ns: u64) -> JointState {
        let mut s = JointState::default();
        s.header.seq = seq;
        s.header.tick = torque_seq;
        s.header.source_stamp_ns = source_ns;
        s.header.stamp_ns = stamp_ns;
        s.torque_seq = torque_seq;
        s.lifecycle = LifecycleState::Active as u32;
        s.dof = 1;
        s
    }

    #[test]
    fn hops_are_timed_from_the_stamps_once_per_torque() {
        let mut c = checker();
        // Setpoints published at k ms; torque k 20 µs later; the state that applies it
        // 500 µs after the torque, then a second plant step on the same torque.
        for k in 1..=3u64 {
            let sp = k * 1_000_000;
            c.torque(&torque(k, sp, sp + 20_000), 1);
            c.state(&state(2 * k - 1, k, sp, sp + 520_000), 2);
            c.state(&state(2 * k, k, sp, sp + 1_020_000), 2);
        }
        let h = &c.out.hops;
        assert_eq!(h.setpoint_to_torque.len(), 3);
        assert_eq!(h.torque_to_state.len(), 3, "one state per torque is timed");
        assert_eq!(h.setpoint_to_state.len(), 3);
        let near = |got: u64, want: u64| got.abs_diff(want) <= want / 500;
        assert!(near(h.setpoint_to_torque.summary().max_ns, 20_000));
        assert!(near(h.torque_to_state.summary().max_ns, 500_000));
        assert!(near(h.setpoint_to_state.summary().p50_ns, 520_000));
    }

    #[test]
    fn a_state_read_before_its_torque_waits_for_it() {
        let mut c = checker();
        c.torque(&torque(1, 1_000_000, 1_030_000), 1);
        c.state(&state(1, 1, 1_000_000, 1_100_000), 2);
        // The observer reads state 2 (applying torque 2) before torque 2.
        c.state(&state(2, 2, 2_000_000, 2_200_000), 2);
        assert_eq!(c.out.hops.torque_to_state.len(), 1);
        c.torque(&torque(2, 2_000_000, 2_050_000), 1);
        assert_eq!(c.out.hops.torque_to_state.len(), 2);
        let max = c.out.hops.torque_to_state.summary().max_ns;
        assert!(max.abs_diff(150_000) <= 300, "{max}");
    }

    #[test]
    fn a_new_torque_publisher_forgets_the_old_ones_stamps() {
        let mut c = checker();
        c.torque(&torque(7, 1_000_000, 1_020_000), 1);
        // A restarted dynamics numbers from 1 again; a state naming seq 7 now means
        // nothing the observer can time.
        c.torque(&torque(1, 2_000_000, 2_020_000), 3);
        c.state(&state(1, 7, 1_000_000, 2_500_000), 2);
        assert_eq!(c.out.hops.torque_to_state.len(), 0);
        c.state(&state(2, 1, 2_000_000, 2_600_000), 2);
        assert_eq!(c.out.hops.torque_to_state.len(), 1);
    }
}
