//! `microrobot probe-chain`: the machine's floor for the pipeline's end-to-end latency
//! and CPU cost, measured the way `microrobot run --floor-probe` measures the timer
//! floor for lateness.
//!
//! It starts three processes of the slim binary `microrobot-chain-link` (sink, relay,
//! source; see [`microrobot_chain_link`]): the pipeline's bus hops, payloads and
//! real-time settings, no work; each reports one JSON line at its end, and this sums
//! them up. The difference between this chain and `microrobot run` at the same rate is
//! what the services' own work costs; the chain itself is what the machine, kernel and
//! iceoryx2 cost.

use std::io::{BufRead, BufReader};
use std::path::PathBuf;
use std::process::{Command, Stdio};

use anyhow::Context as _;
use microrobot_chain_link::{Link, LinkReport};
use microrobot_messages::LatencySummary;
use microrobot_runtime::config::PipelineConfig;
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
}

/// One link's report in the chain's result: its [`LinkReport`] with the latency in µs.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct LinkSummary {
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
    /// Source: setpoints published. Relay, sink: messages taken.
    pub messages: u64,
}

impl From<LinkReport> for LinkSummary {
    fn from(r: LinkReport) -> Self {
        Self {
            link: r.link,
            wakes: r.wakes,
            cpu_s: r.cpu_s,
            wall_s: r.wall_s,
            latency_us: r
                .latency
                .map(|l| Percentiles::from(&LatencySummary::from(l))),
            deadline_misses: r.deadline_misses,
            lost_messages: r.lost_messages,
            messages: r.messages,
        }
    }
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
    /// Source: ticks more than one period late.
    pub deadline_misses: u64,
    /// Setpoints the source published that never reached the sink as torque commands.
    pub lost_messages: u64,
    /// Per link, percent of one core.
    pub cpu_percent: Vec<(Link, f64)>,
    /// The three links together, percent of one core.
    pub cpu_percent_total: f64,
    /// CPU per wake-up, µs, averaged over the three links.
    pub cpu_per_wake_us: f64,
    pub links: Vec<LinkSummary>,
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
    run_chain(&args, &cfg)
}

fn run_chain(args: &ProbeChainArgs, cfg: &PipelineConfig) -> anyhow::Result<()> {
    let exe = microrobot_supervisor::binaries::locate_chain_link()?;
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
            .arg("--config")
            .arg(&args.config)
            .arg("--rate-hz")
            .arg(cfg.rate_hz.to_string())
            .arg("--duration")
            .arg(args.duration.to_string())
            .arg("--link")
            .arg(link.name())
            .arg("--instance")
            .arg(&instance)
            .stdout(Stdio::piped())
            .spawn()
            .with_context(|| format!("start the {} link", link.name()))?;
        let stdout = child.stdout.take().context("child stdout")?;
        let mut lines = BufReader::new(stdout).lines();
        match lines.next() {
            Some(Ok(l)) if l == "ready" => {}
            other => {
                let _ = child.kill();
                anyhow::bail!("the {} link did not become ready: {other:?}", link.name());
            }
        }
        children.push((link, child, lines));
    }
    let mut links = Vec::new();
    for (link, mut child, mut lines) in children {
        let line = lines.next().transpose().context("read a link's report")?;
        let status = child.wait().context("wait for a link")?;
        let line = line.with_context(|| {
            format!("the {} link ended without a report ({status})", link.name())
        })?;
        let report: LinkReport = serde_json::from_str(&line)
            .with_context(|| format!("the {} link's report `{line}`", link.name()))?;
        if report.stopped_on_silence {
            anyhow::bail!(
                "the {} link heard nothing for {} s and stopped after {} messages: the chain broke, its figures mean nothing",
                link.name(),
                microrobot_chain_link::SILENCE_GUARD_NS / 1_000_000_000,
                report.messages
            );
        }
        links.push(LinkSummary::from(report));
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

fn summarise(
    rate_hz: f64,
    duration_s: f64,
    links: Vec<LinkSummary>,
) -> anyhow::Result<ChainReport> {
    let find = |l: Link| {
        links
            .iter()
            .find(|r| r.link == l)
            .with_context(|| format!("no report from the {} link", l.name()))
    };
    let source = find(Link::Source)?;
    let sink = find(Link::Sink)?;
    let pct = |r: &LinkSummary| {
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
        lost_messages: source.messages.saturating_sub(sink.messages),
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
        .map(|(l, c)| format!("{} {c:.2} %", l.name()))
        .collect();
    println!(
        "CPU: {} = {:.2} % of one core; {:.1} µs per wake-up",
        per.join(", "),
        r.cpu_percent_total,
        r.cpu_per_wake_us
    );
}
