//! `microrobot probe-chain`: the machine's floor for the pipeline's end-to-end latency
//! and CPU cost, measured the way [`microrobot_supervisor::run`]'s `--floor-probe` measures the timer
//! floor for lateness.
//!
//! Three processes, started from this binary, with the pipeline's real-time settings
//! (CPU affinity, SCHED_FIFO, PM QoS, timer slack, mlockall; from the config) and the
//! pipeline's own bus hops: a *source* ticks on a timerfd at `rate_hz` and publishes a
//! [`JointSetpoint`], a *relay* woken by it publishes a [`TorqueCommand`], and a *sink*
//! woken by that records `receive time − setpoint publish time`. Each waits on the same
//! [`Reactor`] and notifies through the same iceoryx2 event services as the pipeline,
//! and does no other work. The difference between this chain and `microrobot run` at
//! the same rate is what the services' own work costs; the chain itself is what the
//! machine, kernel and iceoryx2 cost.

use std::io::{BufRead, BufReader, Write};
use std::path::PathBuf;
use std::process::{Command, Stdio};

use anyhow::Context as _;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::service::ipc;
use microrobot_messages::{
    JointSetpoint, ServiceKind, TorqueCommand, monotonic_ns, open_event, open_publish_subscribe,
};
use microrobot_runtime::config::PipelineConfig;
use microrobot_runtime::node::named_node;
use microrobot_runtime::stats::LatencyHistogram;
use microrobot_runtime::{PeriodicClock, Reactor};
use serde::{Deserialize, Serialize};

use microrobot_supervisor::summary::Percentiles;

/// Arguments of `microrobot probe-chain`.
#[derive(Debug, Clone, clap::Args)]
pub struct ProbeChainArgs {
    /// Pipeline config whose real-time settings and rate the chain uses.
    #[arg(long, default_value_os_t = microrobot_command_line::config_path::default_config())]
    pub config: PathBuf,
    /// Tick rate in Hz (overrides `rate_hz`).
    #[arg(long)]
    pub rate_hz: Option<f64>,
    /// How long the source ticks (e.g. 60s, 10m).
    #[arg(long, default_value = "60s", value_parser = microrobot_command_line::duration::parse)]
    pub duration: f64,
    /// Also write the result as JSON to this file (as `run --summary-json`; `--json`
    /// is an alias).
    #[arg(long = "summary-json", visible_alias = "json", value_name = "FILE")]
    pub json: Option<PathBuf>,
    /// Internal: run one link of the chain (the parent starts these).
    #[arg(long, value_enum, hide = true)]
    pub link: Option<Link>,
    /// Internal: the chain's instance name.
    #[arg(long, hide = true)]
    pub instance: Option<String>,
}

/// One process of the chain.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Link {
    /// Ticks on the timer and publishes a setpoint (the planner's place).
    Source,
    /// Woken by the setpoint, publishes a torque command (the dynamics' place).
    Relay,
    /// Woken by the torque command, records the end-to-end latency (the actuator's place).
    Sink,
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
    /// Source: lateness of each tick (µs). Sink: end-to-end latency (µs).
    pub latency_us: Option<Percentiles>,
    /// Source: ticks more than one period late.
    pub deadline_misses: u64,
    /// Relay, sink: sequence gaps seen.
    pub lost_messages: u64,
}

/// The chain's result (`--json`).
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct ChainReport {
    pub rate_hz: f64,
    pub duration_s: f64,
    /// Source publish → sink receive, µs.
    pub e2e_latency_us: Percentiles,
    /// Source wake-up − ideal tick, µs (what the planner's lateness is measured against).
    pub source_lateness_us: Percentiles,
    pub deadline_misses: u64,
    pub lost_messages: u64,
    /// Per link, percent of one core.
    pub cpu_percent: Vec<(Link, f64)>,
    /// The three links together, percent of one core.
    pub cpu_percent_total: f64,
    /// CPU per wake-up, µs, averaged over the three links.
    pub cpu_per_wake_us: f64,
    pub links: Vec<LinkReport>,
}

/// Runs the probe (parent) or one link (child).
pub fn main(args: ProbeChainArgs) -> anyhow::Result<()> {
    let mut cfg = microrobot_config::load(&args.config)
        .with_context(|| format!("config {}", args.config.display()))?;
    if let Some(r) = args.rate_hz {
        if !(r.is_finite() && (1.0..=20_000.0).contains(&r)) {
            anyhow::bail!("--rate-hz {r}: must be within 1..=20000");
        }
        cfg.rate_hz = r;
    }
    match (args.link, &args.instance) {
        (Some(link), Some(instance)) => run_link(link, instance, &cfg, args.duration),
        (None, _) => run_parent(&args, &cfg),
        (Some(_), None) => anyhow::bail!("--link needs --instance"),
    }
}

fn run_parent(args: &ProbeChainArgs, cfg: &PipelineConfig) -> anyhow::Result<()> {
    let exe = std::env::current_exe().context("own executable")?;
    let instance = format!("chainprobe{}", std::process::id());
    let rt = cfg.service_realtime();
    eprintln!(
        "chain probe: source → relay → sink at {} Hz for {} s; CPUs {:?}, {}, mlockall {}",
        cfg.rate_hz,
        args.duration,
        rt.cpu_affinity,
        match rt.sched_fifo_priority {
            0 => "SCHED_OTHER".to_string(),
            p => format!("SCHED_FIFO {p}"),
        },
        rt.mlockall
    );
    let mut children = Vec::new();
    // Sink first, source last: each link is listening before anyone sends to it.
    for link in [Link::Sink, Link::Relay, Link::Source] {
        let mut child = Command::new(&exe)
            .arg("probe-chain")
            .arg("--config")
            .arg(&args.config)
            .arg("--rate-hz")
            .arg(cfg.rate_hz.to_string())
            .arg("--duration")
            .arg(args.duration.to_string())
            .arg("--link")
            .arg(link_name(link))
            .arg("--instance")
            .arg(&instance)
            .stdout(Stdio::piped())
            .spawn()
            .with_context(|| format!("start the {} link", link_name(link)))?;
        let stdout = child.stdout.take().context("child stdout")?;
        let mut lines = BufReader::new(stdout).lines();
        match lines.next() {
            Some(Ok(l)) if l == "ready" => {}
            other => {
                let _ = child.kill();
                anyhow::bail!(
                    "the {} link did not become ready: {other:?}",
                    link_name(link)
                );
            }
        }
        children.push((link, child, lines));
    }
    let mut links = Vec::new();
    for (link, mut child, mut lines) in children {
        let line = lines.next().transpose().context("read a link's report")?;
        let status = child.wait().context("wait for a link")?;
        let line = line.with_context(|| {
            format!(
                "the {} link ended without a report ({status})",
                link_name(link)
            )
        })?;
        let report: LinkReport = serde_json::from_str(&line)
            .with_context(|| format!("the {} link's report `{line}`", link_name(link)))?;
        links.push(report);
    }
    links.sort_by_key(|l| l.link as u8);
    let report = summarise(cfg.rate_hz, args.duration, links)?;
    print_report(&report);
    if let Some(path) = &args.json {
        std::fs::write(path, serde_json::to_string_pretty(&report)? + "\n")
            .with_context(|| format!("write {}", path.display()))?;
    }
    Ok(())
}

fn link_name(link: Link) -> &'static str {
    match link {
        Link::Source => "source",
        Link::Relay => "relay",
        Link::Sink => "sink",
    }
}

fn summarise(rate_hz: f64, duration_s: f64, links: Vec<LinkReport>) -> anyhow::Result<ChainReport> {
    let find = |l: Link| {
        links
            .iter()
            .find(|r| r.link == l)
            .with_context(|| format!("no report from the {} link", link_name(l)))
    };
    let source = find(Link::Source)?;
    let sink = find(Link::Sink)?;
    let pct = |r: &LinkReport| {
        if r.wall_s > 0.0 {
            100.0 * r.cpu_s / r.wall_s
        } else {
            0.0
        }
    };
    let cpu_percent: Vec<(Link, f64)> = links.iter().map(|r| (r.link, pct(r))).collect();
    let wakes: u64 = links.iter().map(|r| r.wakes).sum();
    let cpu: f64 = links.iter().map(|r| r.cpu_s).sum();
    Ok(ChainReport {
        rate_hz,
        duration_s,
        e2e_latency_us: sink.latency_us.context("the sink recorded nothing")?,
        source_lateness_us: source.latency_us.context("the source recorded nothing")?,
        deadline_misses: source.deadline_misses,
        lost_messages: links.iter().map(|r| r.lost_messages).sum(),
        cpu_percent_total: cpu_percent.iter().map(|(_, p)| p).sum(),
        cpu_percent,
        cpu_per_wake_us: if wakes > 0 {
            1e6 * cpu / wakes as f64
        } else {
            0.0
        },
        links,
    })
}

fn print_report(r: &ChainReport) {
    let p = |x: &Percentiles| {
        format!(
            "p50 {:.1} µs, p99 {:.1} µs, p99.9 {:.1} µs, max {:.1} µs ({} samples)",
            x.p50, x.p99, x.p999, x.max, x.count
        )
    };
    println!(
        "end-to-end (source publish → sink receive): {}",
        p(&r.e2e_latency_us)
    );
    println!("source lateness: {}", p(&r.source_lateness_us));
    println!(
        "deadline misses {}, lost messages {}",
        r.deadline_misses, r.lost_messages
    );
    let per: Vec<String> = r
        .cpu_percent
        .iter()
        .map(|(l, c)| format!("{} {c:.2} %", link_name(*l)))
        .collect();
    println!(
        "CPU: {} = {:.2} % of one core; {:.1} µs per wake-up",
        per.join(", "),
        r.cpu_percent_total,
        r.cpu_per_wake_us
    );
}

/// What the relay and the sink do with a wake-up's samples.
#[allow(clippy::large_enum_variant)] // one value per process, built once
enum Hop {
    /// Answer each setpoint with a torque command.
    Relay {
        sub: Subscriber<ipc::Service, JointSetpoint, ()>,
        publisher: Publisher<ipc::Service, TorqueCommand, ()>,
        notifier: Notifier<ipc::Service>,
    },
    /// Record each torque command's end-to-end latency.
    Sink {
        sub: Subscriber<ipc::Service, TorqueCommand, ()>,
    },
}

/// A port of the chain, or an error naming it.
fn port<T, E: std::fmt::Debug>(r: Result<T, E>, what: &str) -> anyhow::Result<T> {
    r.map_err(|e| anyhow::anyhow!("{what}: {e:?}"))
}

/// CPU time of this process, seconds.
fn cpu_time_s() -> f64 {
    microrobot_runtime::stats::cpu_time_ns() as f64 * 1e-9
}

fn run_link(
    link: Link,
    instance: &str,
    cfg: &PipelineConfig,
    duration_s: f64,
) -> anyhow::Result<()> {
    // Stop with the parent.
    // SAFETY: plain prctl.
    unsafe { libc::prctl(libc::PR_SET_PDEATHSIG, libc::SIGKILL, 0, 0, 0) };
    iceoryx2::prelude::set_log_level_from_env_or(iceoryx2::prelude::LogLevel::Error);
    let rt_cfg = cfg.service_realtime();
    let mut rt = microrobot_runtime::rt::prepare(&rt_cfg);
    let node = named_node(&format!("{instance}.{}", link_name(link)))?;
    let sp = open_publish_subscribe::<JointSetpoint>(&node, instance, ServiceKind::Setpoint)?;
    let sp_event = open_event(&node, instance, ServiceKind::Setpoint)?;
    let tq = open_publish_subscribe::<TorqueCommand>(&node, instance, ServiceKind::Torque)?;
    let tq_event = open_event(&node, instance, ServiceKind::Torque)?;
    let period_ns = cfg.period_ns();
    let end_ticks = (duration_s * cfg.rate_hz).round().max(1.0) as u64;
    let mut hist = LatencyHistogram::new();
    let mut wakes = 0u64;
    let mut lost = 0u64;
    let mut misses = 0u64;
    let ready = || {
        let mut out = std::io::stdout().lock();
        let _ = writeln!(out, "ready");
        let _ = out.flush();
    };
    let (cpu0, wall0, cpu1, wall1);
    match link {
        Link::Source => {
            let publisher = port(sp.publisher_builder().create(), "publisher")?;
            let notifier = port(sp_event.notifier_builder().create(), "notifier")?;
            // Give the others' subscribers a moment to connect to the new publisher.
            std::thread::sleep(std::time::Duration::from_millis(100));
            ready();
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
                    seq += 1;
                    let mut msg = JointSetpoint::default();
                    msg.header.seq = seq;
                    msg.header.tick = t.index;
                    msg.header.stamp_ns = monotonic_ns();
                    msg.header.source_stamp_ns = msg.header.stamp_ns;
                    if publisher.send_copy(msg).is_ok() {
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
                    publisher: port(tq.publisher_builder().create(), "publisher")?,
                    notifier: port(tq_event.notifier_builder().create(), "notifier")?,
                };
                (port(sp_event.listener_builder().create(), "listener")?, hop)
            } else {
                let hop = Hop::Sink {
                    sub: port(tq.subscriber_builder().create(), "subscriber")?,
                };
                (port(tq_event.listener_builder().create(), "listener")?, hop)
            };
            ready();
            let mut reactor = Reactor::new()?;
            let on_event = reactor.add(&listener)?;
            microrobot_runtime::rt::enter_cycle(&rt_cfg, &mut rt);
            (cpu0, wall0) = (cpu_time_s(), monotonic_ns());
            let mut last_seq = 0u64;
            // A generous guard: stop if nothing arrives for 5 s.
            while last_seq < end_ticks {
                let ready = reactor.wait_ms(5_000)?;
                if ready.is_empty() {
                    break;
                }
                if !ready.contains(on_event) {
                    continue;
                }
                let _ = listener.try_wait(|_| {});
                wakes += 1;
                match &hop {
                    Hop::Relay {
                        sub,
                        publisher,
                        notifier,
                    } => {
                        while let Ok(Some(s)) = sub.receive() {
                            let h = s.header;
                            drop(s);
                            lost += h.seq.saturating_sub(last_seq + 1);
                            last_seq = h.seq;
                            let mut out = TorqueCommand::default();
                            out.header.seq = h.seq;
                            out.header.tick = h.tick;
                            out.header.stamp_ns = monotonic_ns();
                            out.header.source_stamp_ns = h.source_stamp_ns;
                            if publisher.send_copy(out).is_ok() {
                                let _ = notifier.notify();
                            }
                        }
                    }
                    Hop::Sink { sub } => {
                        while let Ok(Some(s)) = sub.receive() {
                            let now = monotonic_ns();
                            let h = s.header;
                            drop(s);
                            hist.record(now.saturating_sub(h.source_stamp_ns));
                            lost += h.seq.saturating_sub(last_seq + 1);
                            last_seq = h.seq;
                        }
                    }
                }
            }
            (cpu1, wall1) = (cpu_time_s(), monotonic_ns());
        }
    }
    let cpu_s = cpu1 - cpu0;
    let wall_s = wall1.saturating_sub(wall0) as f64 * 1e-9;
    drop(rt);
    let report = LinkReport {
        link,
        wakes,
        cpu_s,
        wall_s,
        latency_us: (!hist.is_empty()).then(|| Percentiles::from(&hist.summary())),
        deadline_misses: misses,
        lost_messages: lost,
    };
    let mut out = std::io::stdout().lock();
    writeln!(out, "{}", serde_json::to_string(&report)?)?;
    out.flush()?;
    Ok(())
}
