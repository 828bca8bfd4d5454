//! The bus tap that `microrobot record` and `microrobot view` share: subscribers on an
//! instance's five recorded streams (with the contract's QoS, so publishers never wait
//! for them: a full queue overwrites its oldest sample), a listener on each event
//! service, and a loop that sleeps in an iceoryx2 WaitSet on those listeners, a periodic
//! timerfd and the shutdown eventfd, and on every wake-up drains every subscriber.
//! Also the clock helpers both use to stamp messages with the wall clock.

use std::os::unix::fs::OpenOptionsExt as _;

use anyhow::{Context as _, Result, anyhow, ensure};
use iceoryx2::port::listener::Listener;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::*;
use microrobot_messages::{
    JointSetpoint, JointState, MotionCommand, ServiceKind, ServiceStatus, TorqueCommand,
    monotonic_ns, open_event, open_publish_subscribe, service_name,
};
use microrobot_runtime::{Shutdown, TimerFd, waitset};

use super::CONFIG_ATTACHMENT;

/// One received payload (the status boxed: it is rare and several times larger than
/// the cyclic payloads, which fill a consumer's queue).
#[derive(Debug, Clone)]
pub enum Payload {
    Setpoint(JointSetpoint),
    Torque(TorqueCommand),
    State(JointState),
    Command(MotionCommand),
    Status(Box<ServiceStatus>),
}

impl Payload {
    /// Index of the payload's stream in [`super::TOPICS`].
    pub fn topic(&self) -> usize {
        match self {
            Payload::Setpoint(_) => 0,
            Payload::Torque(_) => 1,
            Payload::State(_) => 2,
            Payload::Command(_) => 3,
            Payload::Status(_) => 4,
        }
    }

    /// The payload's sequence number and `CLOCK_MONOTONIC` stamp.
    pub fn seq_and_stamp(&self) -> (u64, u64) {
        match self {
            Payload::Setpoint(m) => (m.header.seq, m.header.stamp_ns),
            Payload::Torque(m) => (m.header.seq, m.header.stamp_ns),
            Payload::State(m) => (m.header.seq, m.header.stamp_ns),
            Payload::Command(m) => (m.seq, m.stamp_ns),
            Payload::Status(m) => (m.seq, m.stamp_ns),
        }
    }

    /// Whether the contract numbers this stream from 1 per publisher (every cyclic
    /// stream; motion commands carry their sender's stamp as `seq`).
    pub fn numbered_from_one(&self) -> bool {
        !matches!(self, Payload::Command(_))
    }

    /// The JSON form the recording's channel of this stream carries.
    pub fn json(&self) -> serde_json::Value {
        match self {
            Payload::Setpoint(m) => super::setpoint_json(m),
            Payload::Torque(m) => super::torque_json(m),
            Payload::State(m) => super::state_json(m),
            Payload::Command(m) => super::command_json(m),
            Payload::Status(m) => super::status_json(m),
        }
    }
}

/// A payload as the tap took it: from which publisher, and when (`CLOCK_MONOTONIC` ns).
#[derive(Debug, Clone)]
pub struct Received {
    pub payload: Payload,
    pub publisher: u128,
    pub recv_ns: u64,
}

/// Refuses an instance name the bus could not carry.
pub fn check_instance(name: &str) -> Result<()> {
    ensure!(
        (1..=64).contains(&name.len())
            && name
                .bytes()
                .all(|b| b.is_ascii_alphanumeric() || b == b'_' || b == b'-'),
        "--instance `{name}`: must be 1 to 64 characters of [A-Za-z0-9_-]"
    );
    Ok(())
}

fn subscriber<T>(
    node: &Node<ipc::Service>,
    instance: &str,
    kind: ServiceKind,
) -> Result<Subscriber<ipc::Service, T, ()>>
where
    T: std::fmt::Debug + ZeroCopySend + 'static,
{
    open_publish_subscribe::<T>(node, instance, kind)?
        .subscriber_builder()
        .buffer_size(microrobot_messages::ports::qos::SUBSCRIBER_BUFFER)
        .create()
        .map_err(|e| anyhow!("{} subscriber: {e:?}", service_name(instance, kind)))
}

fn listener(
    node: &Node<ipc::Service>,
    instance: &str,
    kind: ServiceKind,
) -> Result<Listener<ipc::Service>> {
    open_event(node, instance, kind)?
        .listener_builder()
        .create()
        .map_err(|e| anyhow!("{} listener: {e:?}", service_name(instance, kind)))
}

/// Takes every waiting sample of `sub` and hands each to `on`.
fn drain<T: std::fmt::Debug + ZeroCopySend + Copy + 'static>(
    sub: &Subscriber<ipc::Service, T, ()>,
    wrap: fn(T) -> Payload,
    on: &mut impl FnMut(Received),
) {
    while let Ok(Some(s)) = sub.receive() {
        let payload = wrap(*s);
        let publisher = s.header().publisher_id().value();
        drop(s);
        on(Received {
            payload,
            publisher,
            recv_ns: monotonic_ns(),
        });
    }
}

/// When [`BusTap::run`] wakes up to drain.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Wake {
    /// On every notification of a stream, and on the timer: each message is taken as
    /// soon as it is sent (the recorder, which must never let a queue overflow).
    OnEvents,
    /// On the timer only: the queues are drained in batches, with a fraction of the
    /// wake-ups (a viewer, whose timer period is far below a queue's depth in time).
    OnTimer,
}

/// The open ports of one instance's streams (see the module doc).
pub struct BusTap {
    sp: Subscriber<ipc::Service, JointSetpoint, ()>,
    tq: Subscriber<ipc::Service, TorqueCommand, ()>,
    st: Subscriber<ipc::Service, JointState, ()>,
    cm: Subscriber<ipc::Service, MotionCommand, ()>,
    ss: Subscriber<ipc::Service, ServiceStatus, ()>,
    listeners: Vec<Listener<ipc::Service>>,
    // Dropped last: the ports above belong to it.
    _node: Node<ipc::Service>,
}

impl BusTap {
    /// Opens the ports on `instance` as the node `<tool>.<instance>.<pid>` (the services
    /// are created with the contract's QoS if the pipeline is not up yet).
    pub fn open(instance: &str, tool: &str) -> Result<Self> {
        let node_name = format!("{tool}.{instance}.{}", std::process::id());
        let node = microrobot_runtime::node::named_node(&node_name)?;
        Ok(Self {
            sp: subscriber(&node, instance, ServiceKind::Setpoint)?,
            tq: subscriber(&node, instance, ServiceKind::Torque)?,
            st: subscriber(&node, instance, ServiceKind::State)?,
            cm: subscriber(&node, instance, ServiceKind::Command)?,
            ss: subscriber(&node, instance, ServiceKind::Status)?,
            listeners: ServiceKind::ALL
                .iter()
                .map(|k| listener(&node, instance, *k))
                .collect::<Result<Vec<_>>>()?,
            _node: node,
        })
    }

    /// Hands every waiting payload to `on`, stream by stream in pipeline order.
    pub fn drain(&self, on: &mut impl FnMut(Received)) {
        drain(&self.sp, Payload::Setpoint, on);
        drain(&self.tq, Payload::Torque, on);
        drain(&self.st, Payload::State, on);
        drain(&self.cm, Payload::Command, on);
        drain(&self.ss, |m| Payload::Status(Box::new(m)), on);
    }

    /// Sleeps until a stream is notified (with `wake`: [`Wake::OnEvents`]), `period_ns`
    /// passes or `shutdown` is requested; then drains every stream into `on` and asks
    /// `go_on` (with the time now) whether to wait again. Returns once `shutdown` is
    /// requested or `go_on` says no (the samples still queued then are the caller's to
    /// [`BusTap::drain`]).
    pub fn run(
        &self,
        shutdown: &Shutdown,
        wake: Wake,
        period_ns: u64,
        mut on: impl FnMut(Received),
        mut go_on: impl FnMut(u64) -> bool,
    ) -> Result<()> {
        let ws = waitset()?;
        let mut guards = Vec::new();
        if wake == Wake::OnEvents {
            for l in &self.listeners {
                guards.push(
                    ws.attach_notification(l)
                        .map_err(|e| anyhow!("waitset: {e:?}"))?,
                );
            }
        }
        let timer = TimerFd::new().context("timerfd")?;
        timer
            .arm_absolute(monotonic_ns() + period_ns, period_ns)
            .context("timerfd")?;
        let _g_timer = ws
            .attach_notification(&timer)
            .map_err(|e| anyhow!("waitset: {e:?}"))?;
        let _g_stop = ws
            .attach_notification(shutdown)
            .map_err(|e| anyhow!("waitset: {e:?}"))?;
        loop {
            ws.wait_and_process_once(|_| CallbackProgression::Continue)
                .map_err(|e| anyhow!("waitset: {e:?}"))?;
            for l in &self.listeners {
                let _ = l.try_wait(|_| {});
            }
            self.drain(&mut on);
            let _ = timer.read_expirations();
            if shutdown.is_requested() || !go_on(monotonic_ns()) {
                return Ok(());
            }
        }
    }
}

/// `CLOCK_REALTIME` ns of the `CLOCK_MONOTONIC` stamp `mono`, given
/// `realtime_minus_monotonic_ns` ([`clock_offset_ns`]), clamped to the u64 range.
pub fn wall_ns(mono: u64, offset: i64) -> u64 {
    (mono as i128 + offset as i128).clamp(0, u64::MAX as i128) as u64
}

/// `CLOCK_REALTIME` − `CLOCK_MONOTONIC` in ns, read as a tight pair (the monotonic
/// read between two realtime reads; the pair with the smallest gap of five).
pub fn clock_offset_ns() -> i64 {
    let realtime = || {
        std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| d.as_nanos() as i64)
    };
    let mut best: Option<(i64, i64)> = None;
    for _ in 0..5 {
        let a = realtime();
        let m = monotonic_ns() as i64;
        let b = realtime();
        let gap = b - a;
        let offset = a + gap / 2 - m;
        if best.is_none_or(|(g, _)| gap < g) {
            best = Some((gap, offset));
        }
    }
    best.map_or(0, |(_, o)| o)
}

/// The resolved config of `instance`'s run, from this user's private run directory,
/// never through a symlink; `None` when there is none (yet).
pub fn run_config(instance: &str) -> Option<Vec<u8>> {
    let p = microrobot_supervisor::instance::run_file(instance, CONFIG_ATTACHMENT).ok()?;
    let mut f = std::fs::OpenOptions::new()
        .read(true)
        .custom_flags(libc::O_NOFOLLOW | libc::O_CLOEXEC)
        .open(p)
        .ok()?;
    let mut data = Vec::new();
    std::io::Read::read_to_end(&mut f, &mut data).ok()?;
    Some(data)
}
