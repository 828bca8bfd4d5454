//! The soak report: the fault timeline (detect / recover per injected kill, kill
//! windows), lost messages inside and outside them, latches, jumps, resources with
//! their growth per hour, the pipeline against the timer floor, and the verdict; as
//! JSON and markdown. Analysis only (no I/O besides [`Report::write`]).

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::Path;

use anyhow::Context as _;
use serde::{Deserialize, Serialize};

use super::observer::{Edge, EdgeKind, Loss, Observed, ResourceSample};
use microrobot_bus_tools::invariants::Jump;
use microrobot_supervisor::summary::{Percentiles, Summary};

/// After a fault has recovered, lost messages are still attributed to it for this long
/// (statuses arrive at ~10 Hz and count a gap when the next message comes).
pub const WINDOW_MARGIN_NS: u64 = 1_000_000_000;
/// A fault not recovered within this time counts as unrecovered.
pub const RECOVER_TIMEOUT_NS: u64 = 60_000_000_000;

/// One injected fault, as the soak did it: a `kill -9`, or a stall (SIGSTOP, then
/// SIGCONT after `stall_ms` unless the supervisor found the service hung and killed it).
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Kill {
    pub role: String,
    pub pid: u32,
    pub stamp_ns: u64,
    /// `kill` or `stall`.
    #[serde(default = "kind_kill")]
    pub kind: String,
    /// A stall's length as injected (ms).
    #[serde(default)]
    pub stall_ms: Option<f64>,
    /// When the supervisor declared the stalled service hung (and killed it).
    #[serde(default)]
    pub hung_at_ns: Option<u64>,
}

fn kind_kill() -> String {
    "kill".into()
}

/// One injected fault and what the pipeline did about it.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct FaultRecord {
    pub role: String,
    pub pid: u32,
    /// `kill` or `stall`.
    #[serde(default = "kind_kill")]
    pub kind: String,
    /// Stall → the supervisor declared the service hung (`supervisor.hung_ms`).
    #[serde(default)]
    pub hung_detect_ms: Option<f64>,
    /// Since the start of the soak.
    pub at_s: f64,
    /// Kill → first stale/fault flag on a stream.
    pub detect_ms: Option<f64>,
    /// What was seen first.
    pub detected_by: Option<String>,
    /// Kill → the actuator follows fresh torques again and the planner no longer holds.
    pub recover_ms: Option<f64>,
    pub recovered: bool,
}

/// min / p50 / max of a list of times.
#[derive(Debug, Clone, Copy, Default, Serialize, Deserialize)]
pub struct Spread {
    pub count: usize,
    pub min: f64,
    pub p50: f64,
    pub max: f64,
}

impl Spread {
    fn of(mut v: Vec<f64>) -> Self {
        if v.is_empty() {
            return Self::default();
        }
        v.sort_by(f64::total_cmp);
        Self {
            count: v.len(),
            min: v[0],
            p50: v[v.len() / 2],
            max: v[v.len() - 1],
        }
    }
}

/// A jump as listed in the report.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct JumpEvent {
    pub at_s: f64,
    #[serde(flatten)]
    pub jump: Jump,
    pub in_kill_window: bool,
}

/// Resources of one service over the run.
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
pub struct Resources {
    pub processes: usize,
    pub rss_max_kib: u64,
    /// Linear fit of RSS over time after warm-up, pooled over the service's processes.
    pub rss_growth_kib_per_h: Option<f64>,
    /// Mean CPU over the run, % of one core (pooled slope of cpu_time).
    pub cpu_pct_of_one_core: Option<f64>,
    /// (t s, pid, RSS KiB, CPU % of one core since the previous row of the same pid).
    pub table: Vec<(f64, u32, u64, Option<f64>)>,
}

/// The timer floor measured alongside (the same figures as `microrobot run --floor-probe`).
pub use microrobot_supervisor::summary::Floor;

/// Pass/fail and why.
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
pub struct Verdict {
    pub pass: bool,
    pub faults_injected: usize,
    pub faults_recovered: usize,
    pub unrecovered_faults: usize,
    pub jumps: u64,
    pub lost_outside_kill_windows: u64,
    pub lost_setpoints_outside_kill_windows: u64,
    pub latches_without_fault: usize,
    pub pipeline_exit_code: u8,
    pub reasons: Vec<String>,
}

/// Everything the soak reports.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Report {
    pub command: String,
    pub started_utc: String,
    pub duration_s: f64,
    pub rate_hz: f64,
    pub kill_every_s: Option<f64>,
    pub random_commands: bool,
    pub cpu_load_threads: usize,
    pub seed: u64,
    pub load_average_start: String,
    pub load_average_end: String,
    /// How the continuity thresholds are derived (see `microrobot_bus_tools::invariants`).
    pub thresholds: BTreeMap<String, String>,
    pub verdict: Verdict,
    pub e2e_latency_us: Percentiles,
    /// The latency split by hop, from the messages' own stamps (see
    /// `soak::observer::Hops`), in chain order.
    #[serde(default)]
    pub hop_budget_us: Vec<(String, Percentiles)>,
    /// Per hop, `(latency_us, count)` of every non-empty histogram bucket (drawn as
    /// `latency_histogram.png`; not in the JSON).
    #[serde(skip)]
    pub hop_histograms: Vec<(String, Vec<(f64, u64)>)>,
    pub planner_lateness_us: Percentiles,
    pub deadline_misses: u64,
    pub floor: Option<Floor>,
    /// Planner lateness p99 / floor lateness p99.
    pub lateness_p99_vs_floor: Option<f64>,
    pub lost_inside_kill_windows: u64,
    pub lost_outside_kill_windows: u64,
    /// Their `stamp_ns` is relative to the start of the soak.
    pub losses_outside_kill_windows: Vec<Loss>,
    /// Messages the soak's own observer missed (not the pipeline's), per stream.
    pub observer_gaps: BTreeMap<String, u64>,
    pub messages_observed: BTreeMap<String, u64>,
    pub faults: Vec<FaultRecord>,
    pub detect_ms: Spread,
    pub recover_ms: Spread,
    /// Stall → the supervisor's hung verdict, over the stalls it caught.
    #[serde(default)]
    pub hung_detect_ms: Spread,
    #[serde(default)]
    pub stall_every_s: Option<f64>,
    #[serde(default)]
    pub stall_ms: Option<f64>,
    /// The supervisor's `hung_ms`: stalls at least this long must be caught as hung.
    #[serde(default)]
    pub hung_ms: Option<f64>,
    pub latches: usize,
    pub latches_with_fault: usize,
    pub latches_without_fault_at_s: Vec<f64>,
    pub jumps_total: u64,
    pub jumps: Vec<JumpEvent>,
    pub commands: BTreeMap<String, u64>,
    pub resources: BTreeMap<String, Resources>,
    /// `microrobot run`'s summary of the same run.
    pub pipeline: Summary,
}

/// Re-bins hdrhistogram buckets `(value_ns, count)` into 1 µs bins, every bin from the
/// first to the last (empty ones as 0) while that is at most 100 000 bins; beyond, only
/// the non-empty ones.
fn microsecond_bins(buckets: &[(u64, u64)]) -> Vec<(f64, u64)> {
    let mut bins = BTreeMap::<u64, u64>::new();
    for &(ns, n) in buckets {
        *bins.entry(ns / 1000).or_default() += n;
    }
    let (Some((&lo, _)), Some((&hi, _))) = (bins.first_key_value(), bins.last_key_value()) else {
        return Vec::new();
    };
    if hi - lo > 100_000 {
        return bins.into_iter().map(|(us, n)| (us as f64, n)).collect();
    }
    (lo..=hi)
        .map(|us| (us as f64, bins.get(&us).copied().unwrap_or(0)))
        .collect()
}

/// Inputs of [`Report::build`] besides what was observed.
pub struct Facts {
    pub command: String,
    pub started_utc: String,
    pub duration_s: f64,
    pub rate_hz: f64,
    pub kill_every_s: Option<f64>,
    pub random_commands: bool,
    pub cpu_load_threads: usize,
    pub seed: u64,
    pub load_average_start: String,
    pub load_average_end: String,
    pub thresholds: BTreeMap<String, String>,
    pub t0_ns: u64,
    /// End of the run under test (the last supervision poll, before the stop).
    pub end_ns: u64,
    pub kills: Vec<Kill>,
    pub stall_every_s: Option<f64>,
    pub stall_ms: Option<f64>,
    pub hung_ms: f64,
    pub floor: Option<Floor>,
    pub commands: BTreeMap<String, u64>,
    pub exit_code: u8,
}

fn is_detection(k: EdgeKind) -> bool {
    matches!(
        k,
        EdgeKind::StateUnhealthy | EdgeKind::TorqueStale | EdgeKind::SetpointHold | EdgeKind::Latch
    )
}

/// The health after each edge: (stamp, kind, all well: the actuator follows fresh
/// torques, dynamics has fresh state, the planner does not mirror a held arm).
fn timeline(edges: &[Edge]) -> Vec<(u64, EdgeKind, bool)> {
    let mut sorted = edges.to_vec();
    sorted.sort_by_key(|e| e.stamp_ns);
    let (mut healthy, mut hold, mut stale) = (false, false, false);
    sorted
        .iter()
        .map(|e| {
            match e.kind {
                EdgeKind::StateHealthy => healthy = true,
                EdgeKind::StateUnhealthy | EdgeKind::Latch => healthy = false,
                EdgeKind::SetpointHold => hold = true,
                EdgeKind::SetpointFree => hold = false,
                EdgeKind::TorqueStale => stale = true,
                EdgeKind::TorqueFresh => stale = false,
                _ => {}
            }
            (e.stamp_ns, e.kind, healthy && !hold && !stale)
        })
        .collect()
}

/// The edge that shows the restarted process of `role` publishing.
fn new_publisher(role: &str) -> Option<EdgeKind> {
    match role {
        "planner" => Some(EdgeKind::NewSetpointPublisher),
        "dynamics" => Some(EdgeKind::NewTorquePublisher),
        "actuator" => Some(EdgeKind::NewStatePublisher),
        _ => None,
    }
}

/// Detect and recover times of every kill; the kill windows `[kill, recovered + margin]`.
pub fn analyse_faults(
    kills: &[Kill],
    edges: &[Edge],
    t0_ns: u64,
    end_ns: u64,
) -> (Vec<FaultRecord>, Vec<(u64, u64)>) {
    let tl = timeline(edges);
    let mut records = Vec::new();
    let mut windows = Vec::new();
    for (n, k) in kills.iter().enumerate() {
        let until = kills
            .get(n + 1)
            .map_or(end_ns, |next| next.stamp_ns)
            .min(k.stamp_ns + RECOVER_TIMEOUT_NS);
        let after: Vec<_> = tl
            .iter()
            .filter(|e| e.0 > k.stamp_ns && e.0 <= until)
            .collect();
        let detect = after.iter().find(|e| is_detection(e.1));
        // Recovered: the restarted process publishes, and from then on (at the first
        // moment) everything is well again. A stall the supervisor did not kill has no
        // restart: the process itself carries on once it is continued.
        let restarted = new_publisher(&k.role)
            .and_then(|kind| after.iter().find(|e| e.1 == kind))
            .map(|e| e.0)
            .or_else(|| {
                (k.kind == "stall" && k.hung_at_ns.is_none())
                    .then(|| detect.map(|d| d.0))
                    .flatten()
            });
        let recover = match (detect, restarted) {
            (Some(d), Some(r)) => {
                let from = d.0.max(r);
                let well_at = tl.iter().rev().find(|e| e.0 <= from).is_some_and(|e| e.2);
                if well_at {
                    Some(from)
                } else {
                    after.iter().find(|e| e.0 > from && e.2).map(|e| e.0)
                }
            }
            (Some(_), None) => None,
            // Nothing flagged: recovered if well when the next kill (or the end) came.
            (None, _) => {
                let last = tl.iter().rev().find(|e| e.0 <= until);
                last.filter(|e| e.2).map(|_| k.stamp_ns)
            }
        };
        let ms = |t: u64| t.saturating_sub(k.stamp_ns) as f64 * 1e-6;
        records.push(FaultRecord {
            role: k.role.clone(),
            pid: k.pid,
            kind: k.kind.clone(),
            hung_detect_ms: k.hung_at_ns.map(ms),
            at_s: k.stamp_ns.saturating_sub(t0_ns) as f64 * 1e-9,
            detect_ms: detect.map(|d| ms(d.0)),
            detected_by: detect.map(|d| format!("{:?}", d.1)),
            recover_ms: recover.filter(|_| detect.is_some()).map(ms),
            recovered: recover.is_some(),
        });
        windows.push((k.stamp_ns, recover.map_or(until, |r| r + WINDOW_MARGIN_NS)));
    }
    (records, windows)
}

fn in_windows(t: u64, windows: &[(u64, u64)]) -> bool {
    windows.iter().any(|(a, b)| t >= *a && t <= *b)
}

/// Pooled within-process least-squares slope of `y` over `t` (s), skipping each
/// process's first `warmup_s`: one slope shared by all processes of a service (a
/// restart resets RSS and CPU time, a pooled fit ignores those steps).
pub fn pooled_slope(samples: &[(u32, f64, f64)], warmup_s: f64) -> Option<f64> {
    let mut groups: BTreeMap<u32, Vec<(f64, f64)>> = BTreeMap::new();
    for &(pid, t, y) in samples {
        groups.entry(pid).or_default().push((t, y));
    }
    let (mut sxy, mut sxx) = (0.0, 0.0);
    for pts in groups.values() {
        let t_first = pts.first()?.0;
        let kept: Vec<_> = pts.iter().filter(|p| p.0 - t_first >= warmup_s).collect();
        if kept.len() < 2 {
            continue;
        }
        let n = kept.len() as f64;
        let tm = kept.iter().map(|p| p.0).sum::<f64>() / n;
        let ym = kept.iter().map(|p| p.1).sum::<f64>() / n;
        for p in &kept {
            sxy += (p.0 - tm) * (p.1 - ym);
            sxx += (p.0 - tm) * (p.0 - tm);
        }
    }
    (sxx > 0.0).then(|| sxy / sxx)
}

fn resources(samples: &[ResourceSample], t0_ns: u64, duration_s: f64) -> Resources {
    let t = |s: &ResourceSample| s.stamp_ns.saturating_sub(t0_ns) as f64 * 1e-9;
    let warmup = (0.25 * duration_s).min(60.0);
    let rss: Vec<_> = samples
        .iter()
        .map(|s| (s.pid, t(s), s.rss_kib as f64))
        .collect();
    let cpu: Vec<_> = samples
        .iter()
        .map(|s| (s.pid, t(s), s.cpu_time_ms as f64))
        .collect();
    let mut pids: Vec<u32> = samples.iter().map(|s| s.pid).collect();
    pids.dedup();
    let mut pid_set = pids.clone();
    pid_set.sort_unstable();
    pid_set.dedup();
    // About 12 rows over the run.
    let step = (duration_s / 12.0).max(5.0);
    let mut table = Vec::new();
    let mut next = 0.0;
    let mut prev: Option<&ResourceSample> = None;
    for s in samples {
        if t(s) + 1e-9 < next && !std::ptr::eq(s, samples.last().unwrap_or(s)) {
            continue;
        }
        next = t(s) + step;
        let cpu_pct = prev
            .filter(|p| p.pid == s.pid && s.stamp_ns > p.stamp_ns)
            .map(|p| {
                (s.cpu_time_ms as f64 - p.cpu_time_ms as f64)
                    / ((s.stamp_ns - p.stamp_ns) as f64 * 1e-9)
                    / 10.0
            });
        table.push((t(s), s.pid, s.rss_kib, cpu_pct));
        prev = Some(s);
    }
    Resources {
        processes: pid_set.len(),
        rss_max_kib: samples.iter().map(|s| s.rss_kib).max().unwrap_or(0),
        rss_growth_kib_per_h: pooled_slope(&rss, warmup).map(|s| s * 3600.0),
        cpu_pct_of_one_core: pooled_slope(&cpu, 0.0).map(|s| s / 10.0),
        table,
    }
}

const STREAMS: [&str; 4] = ["setpoint", "torque", "state", "status"];
const ROLES: [&str; 3] = ["planner", "dynamics", "actuator"];

impl Report {
    /// Builds the report from what the observer saw and the run's summary.
    pub fn build(facts: Facts, obs: Observed, pipeline: Summary) -> Self {
        let (faults, windows) = analyse_faults(&facts.kills, &obs.edges, facts.t0_ns, facts.end_ns);
        let at_s = |t: u64| t.saturating_sub(facts.t0_ns) as f64 * 1e-9;
        let (mut lost_in, mut lost_out, mut lost_sp_out) = (0, 0, 0);
        let mut losses_out = Vec::new();
        for l in &obs.losses {
            if in_windows(l.stamp_ns, &windows) {
                lost_in += l.count;
            } else {
                lost_out += l.count;
                // The dynamics service subscribes to setpoints (and states); the
                // actuator to torques; the planner to states.
                if l.role == "dynamics" {
                    lost_sp_out += l.count;
                }
                // Listed with its time since the start of the soak.
                let mut rel = l.clone();
                rel.stamp_ns = l.stamp_ns.saturating_sub(facts.t0_ns);
                losses_out.push(rel);
            }
        }
        let latch_times: Vec<u64> = obs
            .edges
            .iter()
            .filter(|e| e.kind == EdgeKind::Latch)
            .map(|e| e.stamp_ns)
            .collect();
        let latches_without: Vec<f64> = latch_times
            .iter()
            .filter(|t| !in_windows(**t, &windows))
            .map(|t| at_s(*t))
            .collect();
        let jumps_total = obs.jumps.len() as u64 + obs.jumps_not_listed;
        let jumps: Vec<JumpEvent> = obs
            .jumps
            .iter()
            .map(|j| JumpEvent {
                at_s: at_s(j.stamp_ns),
                jump: j.clone(),
                in_kill_window: in_windows(j.stamp_ns, &windows),
            })
            .collect();
        let floor = facts.floor.clone();
        let ratio = floor
            .as_ref()
            .filter(|f| f.p99_for_planner() > 0.0)
            .map(|f| pipeline.planner_lateness_us.p99 / f.p99_for_planner());
        let mut res = BTreeMap::new();
        for (i, name) in ROLES.iter().enumerate() {
            res.insert(
                name.to_string(),
                resources(&obs.resources[i], facts.t0_ns, facts.duration_s),
            );
        }
        let recovered = faults.iter().filter(|f| f.recovered).count();
        let mut v = Verdict {
            faults_injected: faults.len(),
            faults_recovered: recovered,
            unrecovered_faults: faults.len() - recovered,
            jumps: jumps_total,
            lost_outside_kill_windows: lost_out,
            lost_setpoints_outside_kill_windows: lost_sp_out,
            latches_without_fault: latches_without.len(),
            pipeline_exit_code: facts.exit_code,
            ..Default::default()
        };
        if v.unrecovered_faults > 0 {
            v.reasons.push(format!(
                "{} injected fault(s) not recovered",
                v.unrecovered_faults
            ));
        }
        let missed_hung = facts
            .kills
            .iter()
            .filter(|k| {
                k.kind == "stall"
                    && k.stall_ms.is_some_and(|ms| ms >= facts.hung_ms)
                    && k.hung_at_ns.is_none()
            })
            .count();
        if missed_hung > 0 {
            v.reasons.push(format!(
                "{missed_hung} stall(s) of at least supervisor.hung_ms ({} ms) not caught as hung",
                facts.hung_ms
            ));
        }
        if v.jumps > 0 {
            v.reasons.push(format!("{} jump(s)", v.jumps));
        }
        if v.lost_outside_kill_windows > 0 {
            v.reasons.push(format!(
                "{} message(s) lost outside the kill windows",
                v.lost_outside_kill_windows
            ));
        }
        if v.latches_without_fault > 0 {
            v.reasons.push(format!(
                "{} safe-state latch(es) without an injected fault",
                v.latches_without_fault
            ));
        }
        if facts.exit_code != 0 {
            v.reasons.push(format!(
                "the pipeline ended with exit code {}",
                facts.exit_code
            ));
        }
        v.pass = v.reasons.is_empty();
        Self {
            command: facts.command,
            started_utc: facts.started_utc,
            duration_s: facts.duration_s,
            rate_hz: facts.rate_hz,
            kill_every_s: facts.kill_every_s,
            random_commands: facts.random_commands,
            cpu_load_threads: facts.cpu_load_threads,
            seed: facts.seed,
            load_average_start: facts.load_average_start,
            load_average_end: facts.load_average_end,
            thresholds: facts.thresholds,
            verdict: v,
            e2e_latency_us: pipeline.e2e_latency_us,
            hop_budget_us: obs
                .hops
                .named()
                .iter()
                .map(|(k, h)| (k.to_string(), Percentiles::from(&h.summary())))
                .collect(),
            hop_histograms: obs
                .hops
                .named()
                .iter()
                .map(|(k, h)| (k.to_string(), microsecond_bins(&h.buckets())))
                .collect(),
            planner_lateness_us: pipeline.planner_lateness_us,
            deadline_misses: pipeline.deadline_misses,
            floor,
            lateness_p99_vs_floor: ratio,
            lost_inside_kill_windows: lost_in,
            lost_outside_kill_windows: lost_out,
            losses_outside_kill_windows: losses_out,
            observer_gaps: STREAMS
                .iter()
                .zip(obs.observer_gaps)
                .map(|(k, v)| (k.to_string(), v))
                .collect(),
            messages_observed: STREAMS
                .iter()
                .zip(obs.received)
                .map(|(k, v)| (k.to_string(), v))
                .collect(),
            detect_ms: Spread::of(faults.iter().filter_map(|f| f.detect_ms).collect()),
            recover_ms: Spread::of(faults.iter().filter_map(|f| f.recover_ms).collect()),
            hung_detect_ms: Spread::of(faults.iter().filter_map(|f| f.hung_detect_ms).collect()),
            stall_every_s: facts.stall_every_s,
            stall_ms: facts.stall_ms,
            hung_ms: Some(facts.hung_ms),
            faults,
            latches: latch_times.len(),
            latches_with_fault: latch_times.len() - latches_without.len(),
            latches_without_fault_at_s: latches_without,
            jumps_total,
            jumps,
            commands: facts.commands,
            resources: res,
            pipeline,
        }
    }

    /// Writes `report.json` and `report.md` into `dir`.
    pub fn write(&self, dir: &Path) -> anyhow::Result<()> {
        std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
        let json = serde_json::to_string_pretty(self).context("cannot serialise the report")?;
        let p = dir.join("report.json");
        std::fs::write(&p, json + "\n").with_context(|| format!("cannot write {}", p.display()))?;
        let p = dir.join("report.md");
        std::fs::write(&p, self.markdown("Soak report"))
            .with_context(|| format!("cannot write {}", p.display()))?;
        if self.hop_histograms.iter().any(|(_, b)| !b.is_empty()) {
            self.draw_histogram(&dir.join("latency_histogram.png"))?;
        }
        Ok(())
    }

    /// A LinuxCNC-style latency histogram per hop: latency in 1 µs bins against
    /// log10(1 + messages in the bin), so the rare tail shows beside the mode.
    fn draw_histogram(&self, path: &Path) -> anyhow::Result<()> {
        use microrobot_study::plot::{Panel, Series, draw};
        let panels: Vec<Panel> = self
            .hop_histograms
            .iter()
            .enumerate()
            .map(|(i, (hop, buckets))| Panel {
                title: hop.replace('_', " "),
                x_label: "latency (µs)".into(),
                y_label: "log10(1 + messages)".into(),
                series: vec![Series {
                    label: String::new(),
                    color: i,
                    points: buckets
                        .iter()
                        .map(|&(us, n)| (us, (n as f64 + 1.0).log10()))
                        .collect(),
                }],
                scatter: false,
                equal_axes: false,
            })
            .collect();
        let rows = panels.len().max(1);
        draw(
            path,
            (1200, 80 + 300 * rows as u32),
            (rows, 1),
            "Latency histogram per hop",
            &panels,
        )
    }

    /// The report as markdown under the heading `title`.
    pub fn markdown(&self, title: &str) -> String {
        let mut s = String::new();
        let p = |x: &Percentiles| {
            format!(
                "{:.1} | {:.1} | {:.1} | {:.1} | {:.1}",
                x.p50, x.p99, x.p999, x.p9999, x.max
            )
        };
        let v = &self.verdict;
        let _ = writeln!(s, "# {title}\n");
        let _ = writeln!(s, "Command (started {} UTC):\n", self.started_utc);
        let _ = writeln!(s, "```\n{}\n```\n", self.command);
        let _ = writeln!(
            s,
            "{:.0} s at {} Hz; kills every {}; stalls every {}; random commands {}; CPU load threads {}; seed {}. \
             Load average at start `{}`, at end `{}`.\n",
            self.duration_s,
            self.rate_hz,
            self.kill_every_s
                .map_or("never".to_string(), |k| format!("{k} s")),
            match (self.stall_every_s, self.stall_ms) {
                (Some(e), Some(ms)) => format!("{e} s ({ms} ms each)"),
                _ => "never".to_string(),
            },
            if self.random_commands { "on" } else { "off" },
            self.cpu_load_threads,
            self.seed,
            self.load_average_start,
            self.load_average_end
        );
        let _ = writeln!(
            s,
            "**Verdict: {}**{}\n",
            if v.pass { "PASS" } else { "FAIL" },
            if v.reasons.is_empty() {
                String::new()
            } else {
                format!(" — {}", v.reasons.join("; "))
            }
        );
        let _ = writeln!(s, "| check | value |\n|---|---|");
        let _ = writeln!(
            s,
            "| faults injected / recovered | {} / {} |",
            v.faults_injected, v.faults_recovered
        );
        let _ = writeln!(s, "| jumps | {} |", v.jumps);
        let _ = writeln!(
            s,
            "| lost messages outside / inside kill windows | {} / {} |",
            self.lost_outside_kill_windows, self.lost_inside_kill_windows
        );
        let _ = writeln!(
            s,
            "| safe-state latches (with an injected fault / without) | {} ({} / {}) |",
            self.latches, self.latches_with_fault, v.latches_without_fault
        );
        let _ = writeln!(
            s,
            "| time to detect, ms (min / p50 / max) | {:.1} / {:.1} / {:.1} |",
            self.detect_ms.min, self.detect_ms.p50, self.detect_ms.max
        );
        let _ = writeln!(
            s,
            "| time to recover, ms (min / p50 / max) | {:.1} / {:.1} / {:.1} |",
            self.recover_ms.min, self.recover_ms.p50, self.recover_ms.max
        );
        let _ = writeln!(
            s,
            "| stalls caught as hung by the supervisor, ms after the stop (count: min / p50 / max; hung_ms {}) | {}: {:.1} / {:.1} / {:.1} |\n",
            self.hung_ms.map_or("-".to_string(), |h| format!("{h}")),
            self.hung_detect_ms.count,
            self.hung_detect_ms.min,
            self.hung_detect_ms.p50,
            self.hung_detect_ms.max
        );
        let _ = writeln!(s, "## Latency and lateness (µs)\n");
        let _ = writeln!(
            s,
            "| | p50 | p99 | p99.9 | p99.99 | max | deadline misses |\n|---|---|---|---|---|---|---|"
        );
        let _ = writeln!(
            s,
            "| end-to-end (setpoint publish → torque at the actuator) | {} | |",
            p(&self.e2e_latency_us)
        );
        for (hop, x) in &self.hop_budget_us {
            let what = match hop.as_str() {
                "setpoint_to_torque" => "hop: setpoint publish → torque publish (dynamics)",
                "torque_to_state" => "hop: torque publish → state publish (actuator)",
                "setpoint_to_state" => "chain: setpoint publish → state publish",
                other => other,
            };
            let _ = writeln!(s, "| {what} | {} | |", p(x));
        }
        let _ = writeln!(
            s,
            "| planner lateness (wake-up − ideal tick) | {} | {} |",
            p(&self.planner_lateness_us),
            self.deadline_misses
        );
        match &self.floor {
            Some(f) => {
                let _ = writeln!(
                    s,
                    "| bare timer loop (floor, same run) | {} | {} |\n",
                    p(&f.lateness_us),
                    f.deadline_misses
                );
                if f.window_p99_us.len() > 1 {
                    let w = &f.window_p99_us;
                    let mut sorted = w.clone();
                    sorted.sort_by(f64::total_cmp);
                    let _ = writeln!(
                        s,
                        "The planner restarted {} times, and its p99 is the largest of its {} \
                         processes' p99s. The floor's p99 in the same {} windows (split at \
                         each planner kill): min {:.1}, median {:.1}, max {:.1} µs; the \
                         planner is held against the largest, the figure of the same kind.\n",
                        w.len() - 1,
                        w.len(),
                        w.len(),
                        sorted[0],
                        sorted[sorted.len() / 2],
                        sorted[sorted.len() - 1]
                    );
                }
                if let Some(r) = self.lateness_p99_vs_floor {
                    let _ = writeln!(
                        s,
                        "Planner lateness p99 = {r:.2} × the floor's p99 ({:.1} µs).\n",
                        f.p99_for_planner()
                    );
                }
            }
            None => {
                let _ = writeln!(s, "\n(no floor: the probe did not finish)\n");
            }
        }
        let _ = writeln!(
            s,
            "Percentiles of services that restarted are the largest of their processes' \
             (each process reports its own histogram).\n"
        );
        let _ = writeln!(s, "## Faults\n");
        if self.faults.is_empty() {
            let _ = writeln!(s, "None injected.\n");
        } else {
            let _ = writeln!(
                s,
                "| # | t (s) | fault | detect (ms) | seen first | hung verdict (ms) | recover (ms) | recovered |\n|---|---|---|---|---|---|---|---|"
            );
            for (i, f) in self.faults.iter().enumerate() {
                let o = |x: Option<f64>| x.map_or("-".to_string(), |v| format!("{v:.1}"));
                let _ = writeln!(
                    s,
                    "| {} | {:.1} | {} {} (pid {}) | {} | {} | {} | {} | {} |",
                    i + 1,
                    f.at_s,
                    f.kind,
                    f.role,
                    f.pid,
                    o(f.detect_ms),
                    f.detected_by.as_deref().unwrap_or("-"),
                    o(f.hung_detect_ms),
                    o(f.recover_ms),
                    if f.recovered { "yes" } else { "NO" }
                );
            }
            let _ = writeln!(
                s,
                "\nDetect: the first stale/fault flag on a stream after the kill or stop. Hung \
                 verdict: a stalled service's silence judged by the supervisor, which kills it \
                 and restarts it. Recover: the \
                 actuator follows fresh torque commands again and the planner no longer mirrors \
                 the held arm (the soak sends the Reset a latched actuator needs).\n"
            );
        }
        let _ = writeln!(s, "## Jumps ({})\n", self.jumps_total);
        for (k, v) in &self.thresholds {
            let _ = writeln!(s, "- {k}: {v}");
        }
        let _ = writeln!(s);
        if !self.jumps.is_empty() {
            let _ = writeln!(
                s,
                "| t (s) | stream | field | joint | size | bound | pair | in kill window |\n|---|---|---|---|---|---|---|---|"
            );
            for j in self.jumps.iter().take(50) {
                let _ = writeln!(
                    s,
                    "| {:.3} | {} | {} | {} | {:.3e} | {:.3e} | {} | {} |",
                    j.at_s,
                    j.jump.stream,
                    j.jump.field,
                    j.jump.joint,
                    j.jump.size,
                    j.jump.bound,
                    j.jump.context,
                    j.in_kill_window
                );
            }
            if self.jumps.len() > 50 {
                let _ = writeln!(s, "\n({} more in report.json)", self.jumps.len() - 50);
            }
            let _ = writeln!(s);
        }
        let _ = writeln!(s, "## Lost messages\n");
        let _ = writeln!(
            s,
            "Sequence gaps counted by the services: {} inside kill windows, {} outside. \
             The soak's own observer missed {:?} (its queue, not the pipeline).\n",
            self.lost_inside_kill_windows, self.lost_outside_kill_windows, self.observer_gaps
        );
        for l in self.losses_outside_kill_windows.iter().take(20) {
            let _ = writeln!(
                s,
                "- {} lost {} at {:.1} s",
                l.role,
                l.count,
                l.stamp_ns as f64 * 1e-9
            );
        }
        let _ = writeln!(s, "## Resources\n");
        let _ = writeln!(
            s,
            "| service | processes | RSS max (KiB) | RSS growth (KiB/h, after warm-up) | CPU (% of one core) |\n|---|---|---|---|---|"
        );
        for (name, r) in &self.resources {
            let _ = writeln!(
                s,
                "| {name} | {} | {} | {} | {} |",
                r.processes,
                r.rss_max_kib,
                r.rss_growth_kib_per_h
                    .map_or("-".to_string(), |g| format!("{g:+.1}")),
                r.cpu_pct_of_one_core
                    .map_or("-".to_string(), |c| format!("{c:.2}"))
            );
        }
        let _ = writeln!(s);
        for (name, r) in &self.resources {
            let _ = writeln!(
                s,
                "{name} over time:\n\n| t (s) | pid | RSS (KiB) | CPU % since the previous row |\n|---|---|---|---|"
            );
            for (t, pid, rss, cpu) in &r.table {
                let _ = writeln!(
                    s,
                    "| {t:.0} | {pid} | {rss} | {} |",
                    cpu.map_or("-".to_string(), |c| format!("{c:.2}"))
                );
            }
            let _ = writeln!(s);
        }
        let _ = writeln!(
            s,
            "Commands: {:?}. Messages observed: {:?}.",
            self.commands, self.messages_observed
        );
        s
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn dynamics_killed_at_1s() -> Kill {
        Kill {
            role: "dynamics".into(),
            pid: 7,
            stamp_ns: 1_000_000_000,
            kind: kind_kill(),
            stall_ms: None,
            hung_at_ns: None,
        }
    }

    fn e(ms: u64, kind: EdgeKind) -> Edge {
        Edge {
            stamp_ns: ms * 1_000_000,
            kind,
        }
    }

    #[test]
    fn a_kill_is_detected_at_the_first_flag_and_recovered_when_healthy_and_free() {
        let edges = vec![
            e(10, EdgeKind::StateHealthy),
            e(1050, EdgeKind::StateUnhealthy),
            e(1150, EdgeKind::NewTorquePublisher),
            e(1200, EdgeKind::Latch),
            e(1210, EdgeKind::SetpointHold),
            e(1500, EdgeKind::StateHealthy),
            e(1501, EdgeKind::SetpointFree),
        ];
        let kills = vec![dynamics_killed_at_1s()];
        let (f, w) = analyse_faults(&kills, &edges, 0, 10_000_000_000);
        assert_eq!(f.len(), 1);
        assert!((f[0].detect_ms.unwrap() - 50.0).abs() < 1e-9);
        assert!(
            (f[0].recover_ms.unwrap() - 501.0).abs() < 1e-9,
            "{:?}",
            f[0]
        );
        assert!(f[0].recovered);
        assert_eq!(w[0], (1_000_000_000, 1_501_000_000 + WINDOW_MARGIN_NS));
        // Without the final edges it never recovers, and the window runs to the end.
        let (f, w) = analyse_faults(&kills, &edges[..5], 0, 10_000_000_000);
        assert!(!f[0].recovered);
        assert_eq!(w[0].1, 10_000_000_000);
    }

    /// A restart quicker than the watchdogs flags nothing: the fault counts as
    /// recovered when all is well at the end of the run, and the stop's own edges
    /// (after `end_ns`) are not taken for its detection.
    #[test]
    fn an_unflagged_restart_is_recovered_and_the_stop_is_not_its_symptom() {
        let edges = vec![
            e(10, EdgeKind::StateHealthy),
            e(1040, EdgeKind::NewTorquePublisher),
            // The orderly stop after the run: services leave Active.
            e(3010, EdgeKind::StateUnhealthy),
        ];
        let kills = vec![dynamics_killed_at_1s()];
        let (f, _) = analyse_faults(&kills, &edges, 0, 3_000_000_000);
        assert!(f[0].recovered, "{:?}", f[0]);
        assert_eq!(f[0].detect_ms, None);
        // Taking the stop into the run (the old end) reads it as an unrecovered fault.
        let (f, _) = analyse_faults(&kills, &edges, 0, 3_020_000_000);
        assert!(!f[0].recovered);
    }

    /// A short stall the supervisor did not kill recovers without a restart, once the
    /// continued process has everything well again; a stall caught as hung recovers like
    /// a kill, with its restart.
    #[test]
    fn a_stall_recovers_with_or_without_the_supervisors_kill() {
        let edges = vec![
            e(10, EdgeKind::StateHealthy),
            e(1060, EdgeKind::TorqueStale),
            e(1300, EdgeKind::TorqueFresh),
        ];
        let stall = Kill {
            kind: "stall".into(),
            stall_ms: Some(300.0),
            ..dynamics_killed_at_1s()
        };
        let (f, _) = analyse_faults(std::slice::from_ref(&stall), &edges, 0, 10_000_000_000);
        assert_eq!(f[0].kind, "stall");
        assert!((f[0].detect_ms.unwrap() - 60.0).abs() < 1e-9, "{:?}", f[0]);
        assert!(
            (f[0].recover_ms.unwrap() - 300.0).abs() < 1e-9,
            "{:?}",
            f[0]
        );
        assert_eq!(f[0].hung_detect_ms, None);
        // A kill with the same edges has no restart: not recovered.
        let (f, _) = analyse_faults(&[dynamics_killed_at_1s()], &edges, 0, 10_000_000_000);
        assert!(!f[0].recovered);
        // Caught as hung at +520 ms and restarted: recovered at the restart's first torque.
        let hung = Kill {
            stall_ms: Some(2000.0),
            hung_at_ns: Some(1_520_000_000),
            ..stall
        };
        let edges = vec![
            e(10, EdgeKind::StateHealthy),
            e(1060, EdgeKind::TorqueStale),
            e(1600, EdgeKind::NewTorquePublisher),
            e(1610, EdgeKind::TorqueFresh),
        ];
        let (f, _) = analyse_faults(&[hung], &edges, 0, 10_000_000_000);
        assert!(
            (f[0].hung_detect_ms.unwrap() - 520.0).abs() < 1e-9,
            "{:?}",
            f[0]
        );
        assert!(
            (f[0].recover_ms.unwrap() - 610.0).abs() < 1e-9,
            "{:?}",
            f[0]
        );
    }

    #[test]
    fn the_pooled_slope_ignores_restart_steps() {
        // Two processes, each growing 1 per s, the second starting lower.
        let mut s = Vec::new();
        for k in 0..10 {
            s.push((1, k as f64, 100.0 + k as f64));
            s.push((2, 20.0 + k as f64, 10.0 + k as f64));
        }
        let slope = pooled_slope(&s, 0.0).unwrap();
        assert!((slope - 1.0).abs() < 1e-12, "{slope}");
        // A flat one is flat.
        let flat: Vec<_> = (0..10).map(|k| (1, k as f64, 5.0)).collect();
        assert_eq!(pooled_slope(&flat, 0.0), Some(0.0));
    }
}
