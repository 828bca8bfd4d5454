//! The run summary: per-service counters from the final statuses (summed over restarts),
//! the headline figures, and its JSON form (`--summary-json`).

use std::collections::BTreeMap;
use std::fmt::Write as _;

use microrobot_messages::{
    HopLatency, LatencySummary, LifecycleState, MAX_JOINTS, ProgramEnd, ProgramState, ServiceRole,
    ServiceStatus,
};
use serde::{Deserialize, Serialize};

use super::monitor::slot;

/// Latency percentiles in µs.
#[derive(Debug, Clone, Copy, Default, Serialize, Deserialize)]
pub struct Percentiles {
    pub count: u64,
    pub p50: f64,
    pub p99: f64,
    pub p999: f64,
    pub p9999: f64,
    pub max: f64,
    /// The exact mean, where the sender keeps the sum of its samples (absent otherwise).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mean: Option<f64>,
}

/// The exact mean in µs of `count` samples summing to `sum_ns`; `None` when there are
/// none or the sender kept no sum (every sample is at least 1 ns, so a sum of 0 with
/// samples means "not kept").
fn mean_us(count: u64, sum_ns: u64) -> Option<f64> {
    (count > 0 && sum_ns > 0).then(|| sum_ns as f64 / count as f64 / 1000.0)
}

impl Percentiles {
    /// `l` with the exact mean of its samples, whose sum is `sum_ns`.
    pub fn with_sum(l: &LatencySummary, sum_ns: u64) -> Self {
        Self {
            mean: mean_us(l.count, sum_ns),
            ..Self::from(l)
        }
    }
}

impl From<&LatencySummary> for Percentiles {
    fn from(l: &LatencySummary) -> Self {
        let us = |ns: u64| ns as f64 / 1000.0;
        Self {
            count: l.count,
            p50: us(l.p50_ns),
            p99: us(l.p99_ns),
            p999: us(l.p999_ns),
            p9999: us(l.p9999_ns),
            max: us(l.max_ns),
            mean: None,
        }
    }
}

/// One hop of the latency budget in µs: count, percentiles and the exact mean.
#[derive(Debug, Clone, Copy, Default, Serialize, Deserialize)]
pub struct HopStats {
    pub count: u64,
    pub p50: f64,
    pub p99: f64,
    pub p999: f64,
    pub max: f64,
    /// Exact (from the sum of the samples); 0 when the hop has no sample.
    pub mean: f64,
}

impl From<&HopLatency> for HopStats {
    fn from(h: &HopLatency) -> Self {
        let us = |ns: u64| ns as f64 / 1000.0;
        Self {
            count: h.count,
            p50: us(h.p50_ns),
            p99: us(h.p99_ns),
            p999: us(h.p999_ns),
            max: us(h.max_ns),
            mean: mean_us(h.count, h.sum_ns).unwrap_or(0.0),
        }
    }
}

/// The pipeline's latency split by hop, as the services measure it in their control
/// cycles (see `ServiceStatus::hops`), in chain order. Three hops make up the
/// end-to-end latency (setpoint stamp → torque taken by the actuator), each sample of it
/// exactly, so their means add up to its mean: `setpoint_to_dynamics_us`,
/// `dynamics_compute_us` and `torque_to_actuator_us`. The other two sit beside it: the
/// planner's wake-up → its setpoint sent (the setpoint's stamp, where the end-to-end
/// latency starts, is taken at the start of its computation), and the actuator's plant
/// step → its state sent.
#[derive(Debug, Clone, Copy, Default, Serialize, Deserialize)]
pub struct HopBudget {
    /// Planner: wake-up for a tick → its setpoint sent.
    pub planner_wake_to_setpoint_us: HopStats,
    /// Setpoint stamp → the dynamics awake for it.
    pub setpoint_to_dynamics_us: HopStats,
    /// Dynamics awake → torque stamp (in lockstep, its wait for the measured state too).
    pub dynamics_compute_us: HopStats,
    /// Torque stamp → the actuator awake and holding it.
    pub torque_to_actuator_us: HopStats,
    /// Actuator: plant step (the backend's write and read) → its state sent.
    pub actuator_step_to_state_us: HopStats,
}

impl HopStats {
    /// The end-to-end row of the budget from the actuator's status (its `latency`,
    /// with the exact mean from `latency_sum_ns`).
    pub fn end_to_end(actuator: &ServiceStatus) -> Self {
        Self::from(&Percentiles::with_sum(
            &actuator.latency,
            actuator.latency_sum_ns,
        ))
    }
}

impl From<&Percentiles> for HopStats {
    /// The budget's row of a latency's percentiles (mean 0 where no sum was kept).
    fn from(p: &Percentiles) -> Self {
        Self {
            count: p.count,
            p50: p.p50,
            p99: p.p99,
            p999: p.p999,
            max: p.max,
            mean: p.mean.unwrap_or(0.0),
        }
    }
}

impl HopBudget {
    /// From the per-role totals' hops (planner, dynamics, actuator).
    pub fn from_statuses(
        planner: &ServiceStatus,
        dynamics: &ServiceStatus,
        actuator: &ServiceStatus,
    ) -> Self {
        Self {
            planner_wake_to_setpoint_us: HopStats::from(&planner.hops[0]),
            setpoint_to_dynamics_us: HopStats::from(&dynamics.hops[0]),
            dynamics_compute_us: HopStats::from(&dynamics.hops[1]),
            torque_to_actuator_us: HopStats::from(&actuator.hops[0]),
            actuator_step_to_state_us: HopStats::from(&actuator.hops[1]),
        }
    }
}

impl HopBudget {
    /// The budget as a table (µs): the hops inside the end-to-end latency marked `+`,
    /// their total `=` the end-to-end row `e2e`, the other two hops beside them.
    pub fn render(&self, e2e: &HopStats, s: &mut String) {
        let _ = writeln!(
            s,
            "  latency by hop (µs)                {:>9} {:>9} {:>9} {:>9} {:>9} {:>9}",
            "count", "p50", "p99", "p99.9", "max", "mean"
        );
        let rows = [
            (
                "  planner wake → setpoint sent",
                &self.planner_wake_to_setpoint_us,
            ),
            ("+ setpoint → dynamics awake", &self.setpoint_to_dynamics_us),
            ("+ dynamics compute → torque", &self.dynamics_compute_us),
            ("+ torque → actuator received", &self.torque_to_actuator_us),
            ("= end-to-end", e2e),
            (
                "  actuator step → state sent",
                &self.actuator_step_to_state_us,
            ),
        ];
        for (name, x) in rows {
            let _ = writeln!(
                s,
                "    {name:<32} {:>9} {:>9.1} {:>9.1} {:>9.1} {:>9.1} {:>9.1}",
                x.count, x.p50, x.p99, x.p999, x.max, x.mean
            );
        }
    }
}

/// One service over the whole run.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct ServiceSummary {
    pub cycles: u64,
    pub deadline_misses: u64,
    pub skipped_ticks: u64,
    pub lost_messages: u64,
    pub refused_messages: u64,
    pub stale_cycles: u64,
    pub clamped_cycles: u64,
    pub faults: u64,
    pub commands_accepted: u64,
    pub commands_refused: u64,
    pub restarts: u32,
    /// Lifecycle of the last status seen (`finalized` after a clean stop).
    pub last_lifecycle: String,
    /// How the (last) process ended: `exit code 0`, `killed by signal 9`, ...
    pub exit: String,
    pub cpu_time_ms: u64,
    /// CPU time over the run's wall time, % of one core (startup included).
    pub cpu_percent: f64,
    pub rss_kib: u64,
    /// The service's own latency (planner: lateness, dynamics: setpoint→torque, actuator: end-to-end).
    pub latency_us: Percentiles,
}

/// The motion program's outcome, from the planner's last status.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct ProgramSummary {
    /// `pending`, `running`, `finished`, `abandoned` or `not_run`.
    pub state: String,
    /// Why it was abandoned or not run, in words (null otherwise).
    pub end_reason: Option<String>,
    /// Program time reached (s).
    pub time_s: f64,
}

impl ProgramSummary {
    /// From the planner's status.
    pub fn from_status(p: &ServiceStatus) -> Self {
        let state = ProgramState::from_wire(p.program_state).unwrap_or(ProgramState::None);
        let end = ProgramEnd::from_wire(p.program_end).unwrap_or(ProgramEnd::None);
        Self {
            state: state.name().to_string(),
            end_reason: (end != ProgramEnd::None).then(|| end.describe().to_string()),
            time_s: p.motion_time_s,
        }
    }
}

/// One joint's figures, in the units of its type: a revolute joint's in rad and
/// N·m, a prismatic joint's in m and N (the other pair is absent).
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
pub struct JointSummary {
    pub name: String,
    /// "revolute" or "prismatic".
    pub kind: String,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub tracking_error_max_rad: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub tracking_error_max_m: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub peak_torque_nm: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub peak_force_n: Option<f64>,
}

impl JointSummary {
    fn new(name: &str, prismatic: bool, tracking_error: f64, peak_effort: f64) -> Self {
        let mut j = JointSummary {
            name: name.to_string(),
            ..JointSummary::default()
        };
        if prismatic {
            j.kind = "prismatic".into();
            j.tracking_error_max_m = Some(tracking_error);
            j.peak_force_n = Some(peak_effort);
        } else {
            j.kind = "revolute".into();
            j.tracking_error_max_rad = Some(tracking_error);
            j.peak_torque_nm = Some(peak_effort);
        }
        j
    }

    fn prismatic(&self) -> bool {
        self.kind == "prismatic"
    }
}

/// Everything `microrobot run` reports at the end.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Summary {
    pub instance: String,
    /// True exactly when the job asked for ran to its end (`exit_code` 0).
    pub exit_ok: bool,
    pub exit_code: u8,
    /// Every reason the run failed, one sentence each (empty when `exit_ok`).
    #[serde(default)]
    pub failures: Vec<String>,
    /// The motion program's outcome (null when the run had no program).
    #[serde(default)]
    pub program: Option<ProgramSummary>,
    /// Why the run stopped: program_done, duration, interrupted, service_failed, timeout.
    pub stop_reason: String,
    pub rate_hz: f64,
    pub lockstep: bool,
    pub feedback: bool,
    pub wall_time_s: f64,
    /// The planner's program (motion) time at the end.
    pub program_time_s: f64,
    pub cycles: BTreeMap<String, u64>,
    /// Planner ticks that started more than one period late.
    pub deadline_misses: u64,
    /// Sequence gaps seen by every subscriber, summed.
    pub lost_messages: u64,
    pub refused_messages: u64,
    pub stale_cycles: u64,
    pub faults: u64,
    pub restarts: u32,
    /// Torque received by the actuator − publish time of its setpoint.
    pub e2e_latency_us: Percentiles,
    /// The latency budget by hop (see [`HopBudget`]).
    #[serde(default)]
    pub hops: HopBudget,
    /// Planner wake-up − ideal tick time.
    pub planner_lateness_us: Percentiles,
    /// Per joint, its tracking error and peak effort keyed in its type's units.
    #[serde(default)]
    pub joints: Vec<JointSummary>,
    /// max |q_measured − q_setpoint| per joint (rad); only when every joint is
    /// revolute (else see `joints`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub tracking_error_max_rad: Option<Vec<f64>>,
    /// max |τ| commanded per joint (N·m); only when every joint is revolute.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub peak_torque_nm: Option<Vec<f64>>,
    /// E-stop commands the planner executed.
    pub estops: u64,
    /// Receipt of the last e-stop command → its first braking setpoint (µs; null: none).
    pub estop_latency_us: Option<f64>,
    /// The largest such time of the run (µs; null: no e-stop).
    pub estop_latency_max_us: Option<f64>,
    pub services: BTreeMap<String, ServiceSummary>,
    /// The three services' CPU time over the wall time, % of one core.
    pub cpu_percent_total: f64,
    /// The bare timer loop run alongside (`--floor-probe`), null without it.
    pub floor: Option<Floor>,
    pub run_dir: String,
}

/// The machine's timer floor measured in the same run: a bare timerfd loop at the same
/// rate with the same real-time settings, lateness and misses defined as the planner's.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Floor {
    pub ticks: u64,
    pub lateness_us: Percentiles,
    pub deadline_misses: u64,
    /// Soak with planner kills: the floor's lateness p99 in each window between two
    /// planner kills, and the largest of them. A planner that restarted reports the
    /// largest p99 of its processes, so this is the floor's figure of the same kind.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub window_p99_us: Vec<f64>,
}

impl Floor {
    /// The floor's p99 to hold a planner p99 against: the largest per-window p99 when
    /// the planner restarted (its figure is the largest of its processes'), else the
    /// whole run's.
    pub fn p99_for_planner(&self) -> f64 {
        if self.window_p99_us.len() > 1 {
            self.window_p99_us.iter().copied().fold(0.0, f64::max)
        } else {
            self.lateness_us.p99
        }
    }
}

/// Adds the counters of `s` (one process's last status) into `acc` (over restarts):
/// counters summed, peaks and latency percentiles as the larger of both.
pub fn fold(acc: &mut ServiceStatus, s: &ServiceStatus) {
    acc.role = s.role;
    acc.lifecycle = s.lifecycle;
    acc.pid = s.pid;
    acc.cycles += s.cycles;
    acc.deadline_misses += s.deadline_misses;
    acc.skipped_ticks += s.skipped_ticks;
    acc.lost_messages += s.lost_messages;
    acc.refused_messages += s.refused_messages;
    acc.stale_cycles += s.stale_cycles;
    acc.clamped_cycles += s.clamped_cycles;
    acc.faults += s.faults;
    acc.commands_accepted += s.commands_accepted;
    acc.commands_refused += s.commands_refused;
    acc.motion_time_s = s.motion_time_s;
    acc.program_done = s.program_done;
    acc.program_state = s.program_state;
    acc.program_end = s.program_end;
    acc.cpu_time_ms = acc.cpu_time_ms.saturating_add(s.cpu_time_ms);
    acc.rss_kib = acc.rss_kib.max(s.rss_kib);
    acc.estops += s.estops;
    if s.estop_latency_ns > 0 {
        acc.estop_latency_ns = s.estop_latency_ns;
    }
    acc.estop_latency_max_ns = acc.estop_latency_max_ns.max(s.estop_latency_max_ns);
    acc.latency_sum_ns = acc.latency_sum_ns.saturating_add(s.latency_sum_ns);
    for (a, b) in acc.hops.iter_mut().zip(&s.hops) {
        a.count += b.count;
        a.sum_ns = a.sum_ns.saturating_add(b.sum_ns);
        a.p50_ns = a.p50_ns.max(b.p50_ns);
        a.p99_ns = a.p99_ns.max(b.p99_ns);
        a.p999_ns = a.p999_ns.max(b.p999_ns);
        a.max_ns = a.max_ns.max(b.max_ns);
    }
    let (a, b) = (&mut acc.latency, &s.latency);
    a.count += b.count;
    a.p50_ns = a.p50_ns.max(b.p50_ns);
    a.p99_ns = a.p99_ns.max(b.p99_ns);
    a.p999_ns = a.p999_ns.max(b.p999_ns);
    a.p9999_ns = a.p9999_ns.max(b.p9999_ns);
    a.max_ns = a.max_ns.max(b.max_ns);
    for j in 0..MAX_JOINTS {
        acc.tracking_error_max[j] = acc.tracking_error_max[j].max(s.tracking_error_max[j]);
        acc.peak_torque[j] = acc.peak_torque[j].max(s.peak_torque[j]);
    }
}

/// Lower-case lifecycle name.
pub fn lifecycle_name(v: u32) -> &'static str {
    match LifecycleState::from_wire(v) {
        Some(LifecycleState::Unconfigured) => "unconfigured",
        Some(LifecycleState::Inactive) => "inactive",
        Some(LifecycleState::Active) => "active",
        Some(LifecycleState::Fault) => "fault",
        Some(LifecycleState::Finalized) => "finalized",
        None => "unknown",
    }
}

/// Inputs of [`Summary::build`] besides the per-role totals.
pub struct RunFacts {
    pub instance: String,
    pub exit_code: u8,
    pub failures: Vec<String>,
    pub program: Option<ProgramSummary>,
    pub stop_reason: String,
    pub rate_hz: f64,
    pub lockstep: bool,
    pub feedback: bool,
    pub wall_time_s: f64,
    pub dof: usize,
    /// Each joint's name and whether it is prismatic.
    pub joints: Vec<(String, bool)>,
    pub run_dir: String,
}

/// `cpu_ms` of CPU time over `wall_s` of wall time, in % of one core.
fn percent_of(cpu_ms: f64, wall_s: f64) -> f64 {
    if wall_s > 0.0 {
        cpu_ms / (wall_s * 1e3) * 100.0
    } else {
        0.0
    }
}

impl Summary {
    /// Builds the summary from per-role totals (index: [`slot`]), restart counts and exits.
    pub fn build(
        facts: RunFacts,
        totals: &[Option<ServiceStatus>; 3],
        restarts: &[u32; 3],
        exits: &[String; 3],
    ) -> Self {
        let dof = facts.dof.min(MAX_JOINTS);
        let mut services = BTreeMap::new();
        let mut cycles = BTreeMap::new();
        let role_of = [
            ServiceRole::Planner,
            ServiceRole::Dynamics,
            ServiceRole::Actuator,
        ];
        for role in role_of {
            let i = slot(role);
            let st = totals[i].unwrap_or_default();
            cycles.insert(role.name().to_string(), st.cycles);
            services.insert(
                role.name().to_string(),
                ServiceSummary {
                    cycles: st.cycles,
                    deadline_misses: st.deadline_misses,
                    skipped_ticks: st.skipped_ticks,
                    lost_messages: st.lost_messages,
                    refused_messages: st.refused_messages,
                    stale_cycles: st.stale_cycles,
                    clamped_cycles: st.clamped_cycles,
                    faults: st.faults,
                    commands_accepted: st.commands_accepted,
                    commands_refused: st.commands_refused,
                    restarts: restarts[i],
                    last_lifecycle: if totals[i].is_some() {
                        lifecycle_name(st.lifecycle).to_string()
                    } else {
                        "no status".to_string()
                    },
                    exit: exits[i].clone(),
                    cpu_time_ms: st.cpu_time_ms as u64,
                    cpu_percent: percent_of(st.cpu_time_ms as f64, facts.wall_time_s),
                    rss_kib: st.rss_kib,
                    latency_us: Percentiles::with_sum(&st.latency, st.latency_sum_ns),
                },
            );
        }
        let get = |role: ServiceRole| totals[slot(role)].unwrap_or_default();
        let (planner, dynamics, actuator) = (
            get(ServiceRole::Planner),
            get(ServiceRole::Dynamics),
            get(ServiceRole::Actuator),
        );
        let sum = |f: fn(&ServiceStatus) -> u64| totals.iter().flatten().map(f).sum::<u64>();
        // Tracking error: the actuator's when it reports any (it sees setpoints), else dynamics'.
        let tracking_src = if actuator.tracking_error_max[..dof].iter().any(|v| *v > 0.0) {
            &actuator
        } else {
            &dynamics
        };
        let all_revolute = !facts.joints.iter().any(|(_, p)| *p);
        Self {
            instance: facts.instance,
            exit_ok: facts.exit_code == 0,
            exit_code: facts.exit_code,
            failures: facts.failures,
            program: facts.program,
            stop_reason: facts.stop_reason,
            rate_hz: facts.rate_hz,
            lockstep: facts.lockstep,
            feedback: facts.feedback,
            wall_time_s: facts.wall_time_s,
            program_time_s: planner.motion_time_s,
            cycles,
            deadline_misses: planner.deadline_misses,
            lost_messages: sum(|s| s.lost_messages),
            refused_messages: sum(|s| s.refused_messages),
            stale_cycles: sum(|s| s.stale_cycles),
            faults: sum(|s| s.faults),
            restarts: restarts.iter().sum(),
            e2e_latency_us: Percentiles::with_sum(&actuator.latency, actuator.latency_sum_ns),
            hops: HopBudget::from_statuses(&planner, &dynamics, &actuator),
            planner_lateness_us: Percentiles::with_sum(&planner.latency, planner.latency_sum_ns),
            joints: (0..dof)
                .map(|i| {
                    let (name, prismatic) = facts
                        .joints
                        .get(i)
                        .map_or((format!("j{}", i + 1), false), |(n, p)| (n.clone(), *p));
                    JointSummary::new(
                        &name,
                        prismatic,
                        tracking_src.tracking_error_max[i],
                        dynamics.peak_torque[i],
                    )
                })
                .collect(),
            tracking_error_max_rad: all_revolute
                .then(|| tracking_src.tracking_error_max[..dof].to_vec()),
            peak_torque_nm: all_revolute.then(|| dynamics.peak_torque[..dof].to_vec()),
            estops: planner.estops,
            estop_latency_us: (planner.estop_latency_ns > 0)
                .then(|| planner.estop_latency_ns as f64 / 1e3),
            estop_latency_max_us: (planner.estop_latency_max_ns > 0)
                .then(|| planner.estop_latency_max_ns as f64 / 1e3),
            cpu_percent_total: percent_of(
                totals.iter().flatten().map(|s| s.cpu_time_ms as f64).sum(),
                facts.wall_time_s,
            ),
            services,
            floor: None,
            run_dir: facts.run_dir,
        }
    }

    /// The latency budget by hop as a table, with the run's end-to-end row.
    fn render_hops(&self, s: &mut String) {
        let h = &self.hops;
        let e = &self.e2e_latency_us;
        h.render(&HopStats::from(e), s);
        let untaken = h.dynamics_compute_us.count.saturating_sub(e.count);
        if untaken > 0 {
            let _ = writeln!(
                s,
                "    ({untaken} torque(s) the dynamics published were not taken by the actuator: in flight at the stop, lost or refused; the + rows count them, the end-to-end row does not)"
            );
        }
    }

    /// The human-readable summary.
    pub fn render(&self) -> String {
        let mut s = String::new();
        let _ = writeln!(
            s,
            "microrobot run `{}`: {} after {:.2} s wall, program time {:.3} s, {} Hz{}{}",
            self.instance,
            self.stop_reason.replace('_', " "),
            self.wall_time_s,
            self.program_time_s,
            self.rate_hz,
            if self.lockstep { ", lockstep" } else { "" },
            if self.feedback {
                ", feedback on"
            } else {
                ", feed-forward only"
            },
        );
        let _ = writeln!(
            s,
            "  {:<9} {:>9} {:>7} {:>6} {:>7} {:>6} {:>6} {:>8} {:>9} {:>9} {:>9}  exit",
            "service",
            "cycles",
            "misses",
            "lost",
            "refused",
            "stale",
            "faults",
            "restarts",
            "p50 µs",
            "p99 µs",
            "max µs"
        );
        for name in ["planner", "dynamics", "actuator"] {
            if let Some(v) = self.services.get(name) {
                let _ = writeln!(
                    s,
                    "  {:<9} {:>9} {:>7} {:>6} {:>7} {:>6} {:>6} {:>8} {:>9.1} {:>9.1} {:>9.1}  {} ({})",
                    name,
                    v.cycles,
                    v.deadline_misses,
                    v.lost_messages,
                    v.refused_messages,
                    v.stale_cycles,
                    v.faults,
                    v.restarts,
                    v.latency_us.p50,
                    v.latency_us.p99,
                    v.latency_us.max,
                    v.exit,
                    v.last_lifecycle,
                );
            }
        }
        let p = |x: &Percentiles| {
            format!(
                "p50 {:.1} / p99 {:.1} / p99.9 {:.1} / max {:.1} µs",
                x.p50, x.p99, x.p999, x.max
            )
        };
        let _ = writeln!(s, "  end-to-end latency: {}", p(&self.e2e_latency_us));
        self.render_hops(&mut s);
        let _ = writeln!(s, "  planner lateness:   {}", p(&self.planner_lateness_us));
        if let Some(f) = &self.floor {
            let _ = writeln!(
                s,
                "  timer floor:        {} ({} misses in {} ticks of a bare timer loop; the planner missed {})",
                p(&f.lateness_us),
                f.deadline_misses,
                f.ticks,
                self.deadline_misses
            );
        }
        let _ = writeln!(
            s,
            "  CPU:                {:.2} % of one core in total (planner {:.2}, dynamics {:.2}, actuator {:.2})",
            self.cpu_percent_total,
            self.services.get("planner").map_or(0.0, |v| v.cpu_percent),
            self.services.get("dynamics").map_or(0.0, |v| v.cpu_percent),
            self.services.get("actuator").map_or(0.0, |v| v.cpu_percent),
        );
        // Each joint in its type's unit: mrad and N·m, or mm and N.
        let all_revolute = !self.joints.iter().any(JointSummary::prismatic);
        let list = |f: &dyn Fn(&JointSummary) -> String| {
            self.joints.iter().map(f).collect::<Vec<_>>().join(", ")
        };
        if all_revolute {
            let _ = writeln!(
                s,
                "  tracking error max: [{}] mrad",
                list(&|j| format!("{:.4}", j.tracking_error_max_rad.unwrap_or(0.0) * 1e3))
            );
            let _ = writeln!(
                s,
                "  peak torque:        [{}] N·m",
                list(&|j| format!("{:.3}", j.peak_torque_nm.unwrap_or(0.0)))
            );
        } else {
            let _ = writeln!(
                s,
                "  tracking error max: [{}]",
                list(
                    &|j| match (j.tracking_error_max_rad, j.tracking_error_max_m) {
                        (Some(r), _) => format!("{:.4} mrad", r * 1e3),
                        (_, m) => format!("{:.4} mm", m.unwrap_or(0.0) * 1e3),
                    }
                )
            );
            let _ = writeln!(
                s,
                "  peak torque/force:  [{}]",
                list(&|j| match (j.peak_torque_nm, j.peak_force_n) {
                    (Some(t), _) => format!("{t:.3} N·m"),
                    (_, f) => format!("{:.3} N", f.unwrap_or(0.0)),
                })
            );
        }
        if let (Some(last), Some(max)) = (self.estop_latency_us, self.estop_latency_max_us) {
            let _ = writeln!(
                s,
                "  e-stops {}: command → first braking setpoint {:.1} µs (last), {:.1} µs (max)",
                self.estops, last, max
            );
        }
        let _ = writeln!(
            s,
            "  deadline misses {}, lost messages {}, logs in {}",
            self.deadline_misses, self.lost_messages, self.run_dir
        );
        if let Some(p) = &self.program {
            let _ = writeln!(
                s,
                "  program:            {} at {:.3} s{}",
                p.state.replace('_', " "),
                p.time_s,
                p.end_reason
                    .as_deref()
                    .map(|r| format!(" ({r})"))
                    .unwrap_or_default()
            );
        }
        let _ = write!(
            s,
            "  result: {}",
            if self.exit_ok {
                "ok".to_string()
            } else if self.failures.is_empty() {
                format!("FAILED (exit code {})", self.exit_code)
            } else {
                format!(
                    "FAILED (exit code {}): {}",
                    self.exit_code,
                    self.failures.join("; ")
                )
            }
        );
        s
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn facts(joints: &[(&str, bool)]) -> RunFacts {
        RunFacts {
            instance: "t".into(),
            exit_code: 0,
            failures: Vec::new(),
            program: None,
            stop_reason: "program_done".into(),
            rate_hz: 1000.0,
            lockstep: true,
            feedback: true,
            wall_time_s: 1.0,
            dof: joints.len(),
            joints: joints.iter().map(|(n, p)| (n.to_string(), *p)).collect(),
            run_dir: "/tmp".into(),
        }
    }

    #[test]
    fn hops_are_summed_over_restarts_with_exact_means() {
        let hop = |count, sum_ns, max_ns| HopLatency {
            count,
            sum_ns,
            p50_ns: max_ns / 2,
            p99_ns: max_ns,
            p999_ns: max_ns,
            max_ns,
        };
        let dynamics = ServiceStatus {
            hops: [hop(2, 30_000, 20_000), hop(2, 10_000, 6_000)],
            ..ServiceStatus::default()
        };
        let again = ServiceStatus {
            hops: [hop(1, 3_000, 3_000), hop(1, 2_000, 2_000)],
            ..dynamics
        };
        let mut acc = ServiceStatus::default();
        fold(&mut acc, &dynamics);
        fold(&mut acc, &again);
        assert_eq!(acc.hops[0], hop(3, 33_000, 20_000));
        let actuator = ServiceStatus {
            latency: LatencySummary {
                count: 3,
                max_ns: 40_000,
                ..LatencySummary::default()
            },
            latency_sum_ns: 60_000,
            hops: [hop(3, 15_000, 9_000), HopLatency::default()],
            ..ServiceStatus::default()
        };
        let totals = [None, Some(acc), Some(actuator)];
        let exits = [String::new(), String::new(), String::new()];
        let s = Summary::build(facts(&[("a", false)]), &totals, &[0, 1, 0], &exits);
        let json = serde_json::to_value(&s).expect("json");
        let h = &json["hops"];
        assert_eq!(h["setpoint_to_dynamics_us"]["count"], 3);
        assert_eq!(h["setpoint_to_dynamics_us"]["mean"], 11.0);
        assert_eq!(h["dynamics_compute_us"]["mean"], 4.0);
        assert_eq!(h["torque_to_actuator_us"]["mean"], 5.0);
        assert_eq!(json["e2e_latency_us"]["mean"], 20.0);
        // No sample: the hop is there with zeros.
        assert_eq!(h["planner_wake_to_setpoint_us"]["count"], 0);
        assert_eq!(h["actuator_step_to_state_us"]["mean"], 0.0);
        let text = s.render();
        assert!(text.contains("= end-to-end"), "{text}");
        assert!(!text.contains("not taken"), "{text}");
    }

    #[test]
    fn a_prismatic_joint_is_summarised_in_m_and_n() {
        let mut dynamics = ServiceStatus::default();
        dynamics.peak_torque[0] = 2.0;
        dynamics.peak_torque[1] = 150.0;
        dynamics.tracking_error_max[1] = 0.002;
        let totals = [None, Some(dynamics), None];
        let exits = [String::new(), String::new(), String::new()];
        let rrp = Summary::build(
            facts(&[("yaw", false), ("boom", true)]),
            &totals,
            &[0; 3],
            &exits,
        );
        let json = serde_json::to_value(&rrp).expect("json");
        assert!(json.get("peak_torque_nm").is_none(), "{json}");
        assert!(json.get("tracking_error_max_rad").is_none(), "{json}");
        let boom = &json["joints"][1];
        assert_eq!(boom["kind"], "prismatic");
        assert_eq!(boom["peak_force_n"], 150.0);
        assert_eq!(boom["tracking_error_max_m"], 0.002);
        assert!(
            boom.get("peak_torque_nm").is_none() && boom.get("tracking_error_max_rad").is_none()
        );
        assert_eq!(json["joints"][0]["peak_torque_nm"], 2.0);
        let text = rrp.render();
        assert!(text.contains("2.000 N·m, 150.000 N"), "{text}");
        assert!(text.contains("2.0000 mm"), "{text}");
        // An all-revolute arm keeps its per-joint arrays.
        let rr = Summary::build(
            facts(&[("a", false), ("b", false)]),
            &totals,
            &[0; 3],
            &exits,
        );
        let json = serde_json::to_value(&rr).expect("json");
        assert_eq!(json["peak_torque_nm"][1], 150.0);
        assert!(rr.render().contains("[2.000, 150.000] N·m"));
    }
}
