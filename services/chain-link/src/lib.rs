//! One link of the bare chain (`microrobot probe-chain`): the machine's floor for the
//! pipeline's end-to-end latency and CPU cost.
//!
//! Three processes of the slim binary `microrobot-chain-link`, with the pipeline's
//! real-time settings (CPU affinity, SCHED_FIFO, PM QoS, timer slack, mlockall; from the
//! config) and the pipeline's own bus hops: a *source* ticks on a timerfd at `rate_hz`
//! and publishes a [`JointSetpoint`], a *relay* woken by it publishes a
//! [`TorqueCommand`], and a *sink* woken by that records `receive time − setpoint
//! publish time` and answers with a [`JointState`], the feedback the source and the relay
//! take from their state queues at each wake-up (polled, as the planner and the dynamics
//! do: it wakes nobody). Each waits on the same [`Reactor`] and notifies through the same
//! iceoryx2 event services as the pipeline, and does no other work. The links run from a
//! binary as slim as the services' (the runtime and the messages, nothing of the CLI),
//! so the chain locks as little memory and touches as little code per wake-up as the
//! services do at best: the difference between this chain and `microrobot run` is what
//! the services' own work costs.

use std::io::Write;

use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::service::ipc;
use microrobot_messages::{
    Header, JointSetpoint, JointState, LatencySummary, ServiceKind, TorqueCommand, monotonic_ns,
    open_event, open_publish_subscribe,
};
use microrobot_runtime::config::PipelineConfig;
use microrobot_runtime::node::named_node;
use microrobot_runtime::stats::LatencyHistogram;
use microrobot_runtime::{PeriodicClock, Reactor};
use serde::{Deserialize, Serialize};

/// The slim binary that runs one link.
pub const BINARY: &str = "microrobot-chain-link";

/// One process of the chain.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Link {
    /// Ticks on the timer and publishes a setpoint (the planner's place).
    Source,
    /// Woken by the setpoint, publishes a torque command (the dynamics' place).
    Relay,
    /// Woken by the torque command, records the end-to-end latency (the actuator's place).
    Sink,
}

impl Link {
    /// The link's name on the command line and in reports.
    pub fn name(self) -> &'static str {
        match self {
            Link::Source => "source",
            Link::Relay => "relay",
            Link::Sink => "sink",
        }
    }

    /// The link named `s`.
    pub fn from_name(s: &str) -> Option<Self> {
        [Link::Source, Link::Relay, Link::Sink]
            .into_iter()
            .find(|l| l.name() == s)
    }
}

/// Percentiles of a link's latency histogram, ns (a [`LatencySummary`] that crosses a
/// pipe as JSON).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct LatencyNs {
    pub count: u64,
    pub p50_ns: u64,
    pub p99_ns: u64,
    pub p999_ns: u64,
    pub p9999_ns: u64,
    pub max_ns: u64,
}

impl From<LatencySummary> for LatencyNs {
    fn from(s: LatencySummary) -> Self {
        Self {
            count: s.count,
            p50_ns: s.p50_ns,
            p99_ns: s.p99_ns,
            p999_ns: s.p999_ns,
            p9999_ns: s.p9999_ns,
            max_ns: s.max_ns,
        }
    }
}

impl From<LatencyNs> for LatencySummary {
    fn from(s: LatencyNs) -> Self {
        Self {
            count: s.count,
            p50_ns: s.p50_ns,
            p99_ns: s.p99_ns,
            p999_ns: s.p999_ns,
            p9999_ns: s.p9999_ns,
            max_ns: s.max_ns,
        }
    }
}

/// What one link reports on its stdout when it ends (one JSON line).
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct LinkReport {
    pub link: Link,
    /// Wake-ups that found work (ticks, messages).
    pub wakes: u64,
    /// CPU time (user + system) of the loop, seconds.
    pub cpu_s: f64,
    /// Wall time of the loop, seconds.
    pub wall_s: f64,
    /// Source: lateness of each tick. Sink: end-to-end latency. `None`: no sample.
    pub latency: Option<LatencyNs>,
    /// Source: ticks more than one period late.
    pub deadline_misses: u64,
    /// Relay, sink: sequence gaps seen.
    pub lost_messages: u64,
    /// Source: setpoints published. Relay, sink: messages taken.
    pub messages: u64,
    /// Relay, sink: stopped after [`SILENCE_GUARD_NS`] without a message, before the
    /// last one came (the chain broke; its figures mean nothing).
    pub stopped_on_silence: bool,
}

/// A relay or sink that hears nothing for this long stops waiting (5 s: a generous guard,
/// so a broken chain ends instead of hanging).
pub const SILENCE_GUARD_NS: u64 = 5_000_000_000;

/// What the relay and the sink do with a wake-up's samples.
#[allow(clippy::large_enum_variant)] // one value per process, built once
enum Hop {
    /// Answer each setpoint with a torque command, after taking the states.
    Relay {
        sub: Subscriber<ipc::Service, JointSetpoint, ()>,
        states: Subscriber<ipc::Service, JointState, ()>,
        publisher: Publisher<ipc::Service, TorqueCommand, ()>,
        notifier: Notifier<ipc::Service>,
    },
    /// Record each torque command's end-to-end latency and answer it with a state.
    Sink {
        sub: Subscriber<ipc::Service, TorqueCommand, ()>,
        publisher: Publisher<ipc::Service, JointState, ()>,
        notifier: Notifier<ipc::Service>,
    },
}

/// The sequence numbers a relay or sink has taken.
#[derive(Default)]
struct Tally {
    last_seq: u64,
    /// Sequence gaps seen.
    lost: u64,
    messages: u64,
}

impl Tally {
    /// Counts the message headed `h`.
    fn count(&mut self, h: &Header) {
        self.messages += 1;
        self.lost += h.seq.saturating_sub(self.last_seq.saturating_add(1));
        self.last_seq = h.seq;
    }
}

impl Hop {
    /// Answers every queued message (the relay takes its states first when `first_pass`).
    fn take(&self, first_pass: bool, tally: &mut Tally, hist: &mut LatencyHistogram) {
        match self {
            Hop::Relay {
                sub,
                states,
                publisher,
                notifier,
            } => {
                if first_pass {
                    take_states(states);
                }
                while let Ok(Some(s)) = sub.receive() {
                    let h = s.header;
                    drop(s);
                    tally.count(&h);
                    let out = TorqueCommand {
                        header: answer_to(&h),
                        ..Default::default()
                    };
                    if publisher.send_copy(out).is_ok() {
                        let _ = notifier.notify();
                    }
                }
            }
            Hop::Sink {
                sub,
                publisher,
                notifier,
            } => {
                while let Ok(Some(s)) = sub.receive() {
                    let now = monotonic_ns();
                    let h = s.header;
                    drop(s);
                    hist.record(now.saturating_sub(h.source_stamp_ns));
                    tally.count(&h);
                    let out = JointState {
                        header: answer_to(&h),
                        ..Default::default()
                    };
                    if publisher.send_copy(out).is_ok() {
                        let _ = notifier.notify();
                    }
                }
            }
        }
    }
}

/// The header of the message answering one headed `h`: its sequence number, tick and
/// source stamp, stamped now.
fn answer_to(h: &Header) -> Header {
    Header {
        seq: h.seq,
        tick: h.tick,
        stamp_ns: monotonic_ns(),
        source_stamp_ns: h.source_stamp_ns,
    }
}

/// Empties the state queue, copying each state out, as the planner and the dynamics do
/// at each wake-up.
fn take_states(states: &Subscriber<ipc::Service, JointState, ()>) {
    while let Ok(Some(s)) = states.receive() {
        std::hint::black_box(*s);
    }
}

/// A port of the chain, or an error naming it.
fn port<T, E: std::fmt::Debug>(r: Result<T, E>, what: &str) -> anyhow::Result<T> {
    r.map_err(|e| anyhow::anyhow!("{what}: {e:?}"))
}

/// CPU time of this process, seconds.
fn cpu_time_s() -> f64 {
    microrobot_runtime::stats::cpu_time_ns() as f64 * 1e-9
}

/// Says `ready` on stdout: the link's ports exist (the parent starts the next link).
fn say_ready() {
    let mut out = std::io::stdout().lock();
    let _ = writeln!(out, "ready");
    let _ = out.flush();
}

/// Runs `link` of the chain `instance` at `cfg.rate_hz` for `duration_s` (the source's
/// ticks; the others until the last one arrives or [`SILENCE_GUARD_NS`] pass without a
/// message) with
/// the config's real-time settings, and returns its report. Prints `ready` once its
/// ports exist. Dies with its parent.
pub fn run(
    link: Link,
    instance: &str,
    cfg: &PipelineConfig,
    duration_s: f64,
) -> anyhow::Result<LinkReport> {
    // SAFETY: plain prctl.
    unsafe { libc::prctl(libc::PR_SET_PDEATHSIG, libc::SIGKILL, 0, 0, 0) };
    iceoryx2::prelude::set_log_level_from_env_or(iceoryx2::prelude::LogLevel::Error);
    let rt_cfg = cfg.service_realtime();
    let mut rt = microrobot_runtime::rt::prepare(&rt_cfg);
    let node = named_node(&format!("{instance}.{}", link.name()))?;
    let sp = open_publish_subscribe::<JointSetpoint>(&node, instance, ServiceKind::Setpoint)?;
    let sp_event = open_event(&node, instance, ServiceKind::Setpoint)?;
    let tq = open_publish_subscribe::<TorqueCommand>(&node, instance, ServiceKind::Torque)?;
    let tq_event = open_event(&node, instance, ServiceKind::Torque)?;
    let st = open_publish_subscribe::<JointState>(&node, instance, ServiceKind::State)?;
    let st_event = open_event(&node, instance, ServiceKind::State)?;
    let period_ns = cfg.period_ns();
    let end_ticks = (duration_s * cfg.rate_hz).round().max(1.0) as u64;
    let mut hist = LatencyHistogram::new();
    let mut wakes = 0u64;
    let mut misses = 0u64;
    let mut messages = 0u64;
    let mut lost = 0u64;
    let mut stopped_on_silence = false;
    let (cpu0, wall0, cpu1, wall1);
    match link {
        Link::Source => {
            let publisher = port(sp.publisher_builder().create(), "publisher")?;
            let notifier = port(sp_event.notifier_builder().create(), "notifier")?;
            let states = port(st.subscriber_builder().create(), "state subscriber")?;
            // Give the others' subscribers a moment to connect to the new publisher.
            std::thread::sleep(std::time::Duration::from_millis(100));
            say_ready();
            let PeriodicClock { timer, mut ticker } =
                PeriodicClock::start(period_ns, rt_cfg.overrun)?;
            let mut reactor = Reactor::new()?;
            let on_timer = reactor.add(&timer)?;
            microrobot_runtime::rt::enter_cycle(&rt_cfg, &mut rt);
            (cpu0, wall0) = (cpu_time_s(), monotonic_ns());
            // One setpoint per tick, as the planner: catch-up ticks back to back.
            let mut seq = 0u64;
            while seq < end_ticks {
                if !reactor.wait()?.contains(on_timer) {
                    continue;
                }
                let now = monotonic_ns();
                ticker.on_expirations(timer.read_expirations());
                wakes += 1;
                while seq < end_ticks
                    && let Some(t) = ticker.next_tick()
                {
                    hist.record(now.saturating_sub(t.ideal_ns));
                    take_states(&states);
                    seq += 1;
                    let mut msg = JointSetpoint::default();
                    msg.header.seq = seq;
                    msg.header.tick = t.index;
                    msg.header.stamp_ns = monotonic_ns();
                    msg.header.source_stamp_ns = msg.header.stamp_ns;
                    if publisher.send_copy(msg).is_ok() {
                        messages += 1;
                        let _ = notifier.notify();
                    }
                }
            }
            misses = ticker.deadline_misses;
            (cpu1, wall1) = (cpu_time_s(), monotonic_ns());
            // Let the last message through before the publisher goes away.
            std::thread::sleep(std::time::Duration::from_millis(50));
        }
        Link::Relay | Link::Sink => {
            let (listener, hop) = if link == Link::Relay {
                let hop = Hop::Relay {
                    sub: port(sp.subscriber_builder().create(), "subscriber")?,
                    states: port(st.subscriber_builder().create(), "state subscriber")?,
                    publisher: port(tq.publisher_builder().create(), "publisher")?,
                    notifier: port(tq_event.notifier_builder().create(), "notifier")?,
                };
                (port(sp_event.listener_builder().create(), "listener")?, hop)
            } else {
                let hop = Hop::Sink {
                    sub: port(tq.subscriber_builder().create(), "subscriber")?,
                    publisher: port(st.publisher_builder().create(), "state publisher")?,
                    notifier: port(st_event.notifier_builder().create(), "state notifier")?,
                };
                (port(tq_event.listener_builder().create(), "listener")?, hop)
            };
            say_ready();
            let mut reactor = Reactor::new()?;
            let on_event = reactor.add(&listener)?;
            microrobot_runtime::rt::enter_cycle(&rt_cfg, &mut rt);
            (cpu0, wall0) = (cpu_time_s(), monotonic_ns());
            let mut tally = Tally::default();
            let mut heard_ns = monotonic_ns();
            while tally.last_seq < end_ticks {
                // An empty wake-up is the timeout or a signal (a stop and continue, a
                // debugger attaching): only the silence since the last message counts.
                let ready = reactor.wait_ms(1_000)?;
                if !ready.contains(on_event) {
                    if monotonic_ns().saturating_sub(heard_ns) >= SILENCE_GUARD_NS {
                        stopped_on_silence = true;
                        break;
                    }
                    continue;
                }
                heard_ns = monotonic_ns();
                wakes += 1;
                // The services' drain rule (`Inbox::drain`): the messages, then the
                // wake-ups, then the messages that came meanwhile.
                for pass in 0..2 {
                    if pass == 1 {
                        let _ = listener.try_wait(|_| {});
                    }
                    hop.take(pass == 0, &mut tally, &mut hist);
                }
            }
            (cpu1, wall1) = (cpu_time_s(), monotonic_ns());
            (messages, lost) = (tally.messages, tally.lost);
        }
    }
    drop(rt);
    Ok(LinkReport {
        link,
        wakes,
        cpu_s: cpu1 - cpu0,
        wall_s: wall1.saturating_sub(wall0) as f64 * 1e-9,
        latency: (!hist.is_empty()).then(|| LatencyNs::from(hist.summary())),
        deadline_misses: misses,
        lost_messages: lost,
        messages,
        stopped_on_silence,
    })
}
