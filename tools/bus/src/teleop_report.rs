//! `microrobot teleop-report`: listens to a running teleop pipeline for a while
//! (master samples, setpoints, measured states) and reports what a surgeon's
//! console is judged by: tremor attenuation in the 8–12 Hz band (dB), the voluntary
//! motion's gain and phase lag, the motion-scaling error, the latency from a master
//! sample to the first setpoint after it (p50/p99), and the tool tracking error of
//! the (simulated) arm against its setpoints.
//!
//! Method: over the longest stretch with the clutch engaged and valid samples (minus
//! the first `--settle` seconds), the scaled hand displacement R·(h − h₀)/ratio and
//! the tool displacement FK(q_setpoint) − p₀ are sampled on the setpoint grid, and
//! both are fitted per axis by least squares to sines at the voluntary and tremor
//! frequencies (plus offset and trend). Gains are tool/hand amplitude ratios.

// Per-axis loops index several series in step; an index reads clearest.
#![allow(clippy::needless_range_loop)]

use std::path::PathBuf;
use std::time::{Duration, Instant};

use anyhow::{Context, bail, ensure};
use iceoryx2::prelude::*;
use microrobot_messages::{
    JointSetpoint, JointState, MasterPose, ServiceKind, open_publish_subscribe, setpoint_flags,
};
use microrobot_model::{JointVector, ModelData, Robot, forward_kinematics};
use microrobot_planner::TeleopConfig;
use microrobot_runtime::config::{OwnedSection as _, PipelineConfig};
use microrobot_teleop::TremorFilter;
use nalgebra::{Rotation3, SMatrix, SVector, Vector3};
use serde::Serialize;

/// Options of `microrobot teleop-report`.
#[derive(Debug, Clone, clap::Args)]
pub struct TeleopReportArgs {
    /// Instance name of the running pipeline.
    #[arg(long, default_value = "default", value_name = "NAME")]
    pub instance: String,
    /// The pipeline's config (robot, `[teleop]` ratio and frame).
    #[arg(long, default_value_os_t = microrobot_command_line::config_path::default_config(), value_name = "FILE")]
    pub config: PathBuf,
    /// How long to listen (s).
    #[arg(long, default_value_t = 10.0, value_name = "DURATION", value_parser = microrobot_command_line::duration::parse)]
    pub duration: f64,
    /// Seconds at the start of the engaged stretch left out (filter transient).
    #[arg(long, default_value_t = 1.0, value_name = "DURATION", value_parser = microrobot_command_line::duration::parse_or_zero)]
    pub settle: f64,
    /// Voluntary frequency (Hz); default: the strongest hand motion in 0.2–2 Hz.
    #[arg(long, value_name = "HZ")]
    pub voluntary_hz: Option<f64>,
    /// Tremor frequency (Hz); default: the strongest hand motion in 8–12 Hz.
    #[arg(long, value_name = "HZ")]
    pub tremor_hz: Option<f64>,
    /// JSON output.
    #[arg(long)]
    pub json: bool,
    /// Verdict: the tremor must be attenuated by at least this much (dB).
    #[arg(long, default_value_t = 20.0, value_name = "DB")]
    pub min_tremor_attenuation_db: f64,
    /// Verdict: |voluntary gain| at most this much (dB).
    #[arg(long, default_value_t = 1.0, value_name = "DB")]
    pub max_voluntary_gain_db: f64,
    /// Verdict: the final displacement error at most this much (%).
    #[arg(long, default_value_t = 5.0, value_name = "PCT")]
    pub max_displacement_error_pct: f64,
    /// Verdict: master sample → setpoint latency p99 at most this much (µs; not judged
    /// unless given).
    #[arg(long, value_name = "US")]
    pub max_latency_p99_us: Option<f64>,
}

/// Below this amplitude (mm, scaled hand) a motion component is taken as absent and
/// not judged: its gain would be the ratio of two noises.
const PRESENT_MM: f64 = 0.01;

/// One line of the verdict: what was measured against which threshold.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Check {
    pub name: &'static str,
    pub measured: String,
    pub threshold: String,
    /// `None`: not judged (the motion component was absent, or no threshold given).
    pub pass: Option<bool>,
}

/// The report's verdict: every check that could be judged passed.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Verdict {
    pub pass: bool,
    pub checks: Vec<Check>,
}

/// Judges `r` against the thresholds of `args`.
pub fn verdict(r: &TeleopReport, args: &TeleopReportArgs) -> Verdict {
    let mut checks = Vec::new();
    let tremor_present = r.tremor.hand_scaled_amplitude_mm >= PRESENT_MM;
    checks.push(Check {
        name: "tremor attenuation",
        measured: format!(
            "{:.1} dB at {:.2} Hz",
            r.tremor_attenuation_db, r.tremor.frequency_hz
        ),
        threshold: format!(">= {:.1} dB", args.min_tremor_attenuation_db),
        pass: tremor_present.then_some(r.tremor_attenuation_db >= args.min_tremor_attenuation_db),
    });
    // A sine is the hand's motion if it is not a small projection of a displacement
    // (a ramp and hold fits a 1 Hz sine of a few % of its size).
    let voluntary_present = r.voluntary.hand_scaled_amplitude_mm >= PRESENT_MM
        && r.voluntary.hand_scaled_amplitude_mm >= 0.25 * r.final_hand_scaled_displacement_mm.abs();
    checks.push(Check {
        name: "voluntary gain",
        measured: format!(
            "{:+.2} dB at {:.2} Hz",
            r.voluntary.gain_db, r.voluntary.frequency_hz
        ),
        threshold: format!("|gain| <= {:.2} dB", args.max_voluntary_gain_db),
        pass: voluntary_present.then_some(r.voluntary.gain_db.abs() <= args.max_voluntary_gain_db),
    });
    // A hold after a displacement: judged when the hand moved and then stayed (no
    // voluntary sine, whose final phase makes the end point arbitrary).
    let displaced = r.final_hand_scaled_displacement_mm.abs() >= PRESENT_MM && !voluntary_present;
    checks.push(Check {
        name: "final displacement error",
        measured: format!("{:.2} %", r.final_displacement_error_pct),
        threshold: format!("<= {:.1} %", args.max_displacement_error_pct),
        pass: displaced
            .then_some(r.final_displacement_error_pct <= args.max_displacement_error_pct),
    });
    checks.push(Check {
        name: "latency p99",
        measured: format!("{:.0} µs", r.latency_us.p99),
        threshold: args
            .max_latency_p99_us
            .map_or("not set".into(), |t| format!("<= {t:.0} µs")),
        pass: args.max_latency_p99_us.map(|t| r.latency_us.p99 <= t),
    });
    Verdict {
        pass: checks.iter().all(|c| c.pass != Some(false)),
        checks,
    }
}

/// Percentiles of a set of values.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize)]
pub struct Percentiles {
    pub count: usize,
    pub p50: f64,
    pub p99: f64,
    pub max: f64,
}

fn percentiles(mut v: Vec<f64>) -> Percentiles {
    if v.is_empty() {
        return Percentiles::default();
    }
    v.sort_by(f64::total_cmp);
    let at = |q: f64| v[((v.len() - 1) as f64 * q).round() as usize];
    Percentiles {
        count: v.len(),
        p50: at(0.5),
        p99: at(0.99),
        max: v[v.len() - 1],
    }
}

/// Gain and phase of the tool's motion against the scaled hand's at one frequency.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize)]
pub struct Transfer {
    pub frequency_hz: f64,
    /// Scaled hand amplitude on the dominant axis (mm).
    pub hand_scaled_amplitude_mm: f64,
    /// Tool amplitude on that axis (mm).
    pub tool_amplitude_mm: f64,
    /// 20·log10(tool / scaled hand), dB.
    pub gain_db: f64,
    /// Tool phase behind the hand (deg).
    pub phase_lag_deg: f64,
}

/// The figures of one report.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct TeleopReport {
    pub master_samples: usize,
    pub setpoints: usize,
    /// Length of the analysed engaged stretch (s).
    pub analysed_s: f64,
    pub voluntary: Transfer,
    pub tremor: Transfer,
    /// Tremor attenuation (dB, positive) = −tremor gain.
    pub tremor_attenuation_db: f64,
    /// The filter's own attenuation at 8, 10, 12 Hz (dB, positive), from its coefficients.
    pub filter_attenuation_db_8_10_12_hz: [f64; 3],
    /// The filter's own phase lag at the voluntary frequency (deg).
    pub filter_phase_lag_deg_at_voluntary: f64,
    /// |voluntary gain − 1| in percent: how far the tool's motion is from hand / ratio.
    pub scaling_error_pct: f64,
    /// At the end of the stretch (mean of its last 0.5 s): |tool − hand/ratio| / |hand/ratio| (%).
    pub final_displacement_error_pct: f64,
    /// Final scaled hand displacement (mm), the reference of the line above.
    pub final_hand_scaled_displacement_mm: f64,
    /// Master sample → first setpoint stamped after it (µs).
    pub latency_us: Percentiles,
    /// |FK(measured q) − FK(setpoint q)| of the simulated arm (µm).
    pub tracking_error_um: Percentiles,
    /// Setpoints carrying each teleop flag.
    pub flag_counts: FlagCounts,
}

/// How many setpoints carried each teleop flag.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize)]
pub struct FlagCounts {
    pub teleop: usize,
    pub clutch_open: usize,
    pub master_stale: usize,
    pub workspace_edge: usize,
    pub singularity: usize,
    pub flip_refused: usize,
    pub input_refused: usize,
    pub limited: usize,
}

fn count_flags(sp: &[JointSetpoint]) -> FlagCounts {
    let c = |bit: u32| sp.iter().filter(|s| s.flags & bit != 0).count();
    FlagCounts {
        teleop: c(setpoint_flags::TELEOP),
        clutch_open: c(setpoint_flags::TELEOP_CLUTCH_OPEN),
        master_stale: c(setpoint_flags::TELEOP_MASTER_STALE),
        workspace_edge: c(setpoint_flags::TELEOP_WORKSPACE_EDGE),
        singularity: c(setpoint_flags::TELEOP_SINGULARITY),
        flip_refused: c(setpoint_flags::TELEOP_FLIP_REFUSED),
        input_refused: c(setpoint_flags::TELEOP_INPUT_REFUSED),
        limited: c(setpoint_flags::TELEOP_LIMITED),
    }
}

/// Least-squares fit of `y(t)` to a·sin + b·cos at each of `freqs` plus offset and
/// trend; returns (amplitude, phase rad) per frequency (phase of a·sin + b·cos).
fn fit2(t: &[f64], y: &[f64], freqs: [f64; 2]) -> [(f64, f64); 2] {
    let mut ata = SMatrix::<f64, 6, 6>::zeros();
    let mut aty = SVector::<f64, 6>::zeros();
    let t0 = t.first().copied().unwrap_or(0.0);
    for (ti, yi) in t.iter().zip(y) {
        let w = 2.0 * std::f64::consts::PI;
        let (s1, c1) = (w * freqs[0] * ti).sin_cos();
        let (s2, c2) = (w * freqs[1] * ti).sin_cos();
        let row = SVector::<f64, 6>::from([s1, c1, s2, c2, 1.0, ti - t0]);
        ata += row * row.transpose();
        aty += row * *yi;
    }
    let x = ata
        .cholesky()
        .map(|c| c.solve(&aty))
        .unwrap_or_else(SVector::zeros);
    [
        ((x[0] * x[0] + x[1] * x[1]).sqrt(), x[1].atan2(x[0])),
        ((x[2] * x[2] + x[3] * x[3]).sqrt(), x[3].atan2(x[2])),
    ]
}

/// Strongest single frequency of `y` among `candidates` (single-sine fits).
fn strongest(t: &[f64], y: &[[f64; 3]], candidates: impl Iterator<Item = f64>) -> f64 {
    let mut best = (0.0, 0.0);
    for f in candidates {
        let mut a = 0.0;
        for k in 0..3 {
            let yk: Vec<f64> = y.iter().map(|v| v[k]).collect();
            a += fit2(t, &yk, [f, f * 1.37 + 0.11])[0].0;
        }
        if a > best.1 {
            best = (f, a);
        }
    }
    best.0
}

fn wrap_deg(mut d: f64) -> f64 {
    while d > 180.0 {
        d -= 360.0;
    }
    while d <= -180.0 {
        d += 360.0;
    }
    d
}

/// The figures from captured streams (pure; used by the CLI and the tests).
pub fn analyse(
    robot: &Robot,
    cfg: &PipelineConfig,
    master: &[MasterPose],
    setpoints: &[JointSetpoint],
    states: &[JointState],
    settle_s: f64,
    freqs: (Option<f64>, Option<f64>),
) -> anyhow::Result<TeleopReport> {
    let mut r = TeleopReport {
        master_samples: master.len(),
        setpoints: setpoints.len(),
        flag_counts: count_flags(setpoints),
        ..Default::default()
    };
    let teleop = TeleopConfig::from_pipeline(cfg)?;
    let filter = TremorFilter::butterworth(
        teleop.filter_order as usize,
        teleop.filter_cutoff_hz,
        cfg.rate_hz,
    )
    .map_err(|e| anyhow::anyhow!("[teleop] filter: {e}"))?;
    r.filter_attenuation_db_8_10_12_hz = [8.0, 10.0, 12.0].map(|f| -filter.response(f).gain_db);

    // Latency: each master sample to the first setpoint stamped at or after it.
    let mut lat = Vec::with_capacity(master.len());
    for m in master {
        let i = setpoints.partition_point(|s| s.header.stamp_ns < m.stamp_ns);
        if let Some(s) = setpoints.get(i) {
            lat.push((s.header.stamp_ns - m.stamp_ns) as f64 / 1e3);
        }
    }
    r.latency_us = percentiles(lat);

    let mut data = ModelData::new(robot);
    let dof = robot.dof();
    let mut tool = |q: &[f64; 8]| {
        let mut v = JointVector::zeros();
        for i in 0..dof {
            v[i] = q[i];
        }
        forward_kinematics(robot, &mut data, &v).translation.vector
    };
    // Tracking: measured state against the setpoint of the same tick.
    let mut track = Vec::with_capacity(states.len());
    for s in states {
        let i = setpoints.partition_point(|p| p.header.tick < s.header.tick);
        if let Some(p) = setpoints.get(i)
            && p.header.tick == s.header.tick
        {
            track.push((tool(&s.q) - tool(&p.q)).norm() * 1e6);
        }
    }
    r.tracking_error_um = percentiles(track);

    // The longest engaged stretch of valid master samples.
    // A gap of more than 100 ms (a device restart, the history sample of an earlier
    // run) ends a stretch, as the planner's master timeout would.
    let valid = |i: usize| {
        let m = &master[i];
        m.clutch == 1
            && m.is_valid()
            && (i == 0 || m.stamp_ns.saturating_sub(master[i - 1].stamp_ns) <= 100_000_000)
    };
    let (mut best, mut run_start) = ((0usize, 0usize), None);
    for i in 0..master.len() {
        match (valid(i), run_start) {
            (true, None) => run_start = Some(i),
            (false, Some(s)) => {
                if i - s > best.1 - best.0 {
                    best = (s, i);
                }
                run_start = None;
            }
            _ => {}
        }
    }
    if let Some(s) = run_start
        && master.len() - s > best.1 - best.0
    {
        best = (s, master.len());
    }
    let stretch = &master[best.0..best.1];
    if stretch.len() < 2 {
        bail!("no engaged stretch of valid master samples was captured");
    }
    let t = &teleop;
    let frame = Rotation3::from_euler_angles(t.frame_rpy[0], t.frame_rpy[1], t.frame_rpy[2]);
    let h0 = Vector3::from(stretch[0].position);
    let (start_ns, end_ns) = (stretch[0].stamp_ns, stretch[stretch.len() - 1].stamp_ns);
    let sp: Vec<&JointSetpoint> = setpoints
        .iter()
        .filter(|s| s.header.stamp_ns >= start_ns && s.header.stamp_ns <= end_ns)
        .collect();
    ensure!(sp.len() > 10, "too few setpoints in the engaged stretch");
    let p0 = tool(&sp[0].q);
    let settle_ns = start_ns + (settle_s * 1e9) as u64;
    let (mut ts, mut hand, mut tl) = (Vec::new(), Vec::new(), Vec::new());
    for s in &sp {
        if s.header.stamp_ns < settle_ns {
            continue;
        }
        // The newest master sample at the setpoint's time (what the planner used).
        let i = stretch.partition_point(|m| m.stamp_ns <= s.header.stamp_ns);
        let m = &stretch[i.saturating_sub(1)];
        let hs = frame * (Vector3::from(m.position) - h0) / t.ratio;
        ts.push((s.header.stamp_ns - start_ns) as f64 * 1e-9);
        hand.push([hs.x, hs.y, hs.z]);
        let d = tool(&s.q) - p0;
        tl.push([d.x, d.y, d.z]);
    }
    ensure!(
        ts.len() > 100,
        "the engaged stretch is shorter than --settle"
    );
    r.analysed_s = ts[ts.len() - 1] - ts[0];
    let fv = freqs
        .0
        .unwrap_or_else(|| strongest(&ts, &hand, (4..=40).map(|k| k as f64 * 0.05)));
    let ft = freqs
        .1
        .unwrap_or_else(|| strongest(&ts, &hand, (80..=120).map(|k| k as f64 * 0.1)));
    let mut fits = [[(0.0, 0.0); 2]; 3];
    let mut fits_tool = [[(0.0, 0.0); 2]; 3];
    for k in 0..3 {
        let hk: Vec<f64> = hand.iter().map(|v| v[k]).collect();
        let tk: Vec<f64> = tl.iter().map(|v| v[k]).collect();
        fits[k] = fit2(&ts, &hk, [fv, ft]);
        fits_tool[k] = fit2(&ts, &tk, [fv, ft]);
    }
    let transfer = |j: usize, f: f64| {
        let k = (0..3)
            .max_by(|a, b| fits[*a][j].0.total_cmp(&fits[*b][j].0))
            .unwrap_or(0);
        let (ha, hp) = fits[k][j];
        let (ta, tp) = fits_tool[k][j];
        Transfer {
            frequency_hz: f,
            hand_scaled_amplitude_mm: ha * 1e3,
            tool_amplitude_mm: ta * 1e3,
            gain_db: 20.0 * (ta / ha).log10(),
            phase_lag_deg: -wrap_deg((tp - hp).to_degrees()),
        }
    };
    r.voluntary = transfer(0, fv);
    r.tremor = transfer(1, ft);
    r.tremor_attenuation_db = -r.tremor.gain_db;
    r.filter_phase_lag_deg_at_voluntary = filter.phase_lag_deg(fv);
    r.scaling_error_pct = (10f64.powf(r.voluntary.gain_db / 20.0) - 1.0).abs() * 100.0;
    // Final displacement: mean over the last 0.5 s.
    let last = ts[ts.len() - 1];
    let (mut hs, mut tsum, mut n) = (Vector3::zeros(), Vector3::zeros(), 0.0);
    for i in 0..ts.len() {
        if ts[i] >= last - 0.5 {
            hs += Vector3::from(hand[i]);
            tsum += Vector3::from(tl[i]);
            n += 1.0;
        }
    }
    let (hs, tsum) = (hs / n, tsum / n);
    r.final_hand_scaled_displacement_mm = hs.norm() * 1e3;
    r.final_displacement_error_pct = if hs.norm() > 0.0 {
        (tsum - hs).norm() / hs.norm() * 100.0
    } else {
        0.0
    };
    Ok(r)
}

fn subscriber<T: std::fmt::Debug + ZeroCopySend + 'static>(
    node: &Node<ipc::Service>,
    inst: &str,
    kind: ServiceKind,
) -> anyhow::Result<iceoryx2::port::subscriber::Subscriber<ipc::Service, T, ()>> {
    open_publish_subscribe::<T>(node, inst, kind)?
        .subscriber_builder()
        .buffer_size(microrobot_messages::ports::qos::SUBSCRIBER_BUFFER)
        .create()
        .map_err(|e| anyhow::anyhow!("{kind:?} subscriber: {e:?}"))
}

/// Captures for `--duration` seconds, then prints the report.
pub fn main(args: TeleopReportArgs) -> anyhow::Result<()> {
    ensure!(
        args.duration.is_finite() && args.duration > 0.0,
        "--duration {}: must be > 0 s",
        args.duration
    );
    ensure!(
        args.settle.is_finite() && args.settle >= 0.0,
        "--settle {}: must be >= 0 s",
        args.settle
    );
    let cfg = microrobot_config::load(&args.config).map_err(anyhow::Error::new)?;
    let robot = Robot::from_file(&cfg.robot)
        .map_err(|e| anyhow::anyhow!("{}: {e}", cfg.robot.display()))?;
    set_log_level_from_env_or(LogLevel::Error);
    let inst = args.instance.as_str();
    let node_name = format!("microrobot-teleop-report.{inst}.{}", std::process::id());
    let node = microrobot_runtime::node::named_node(&node_name)?;
    let ms = subscriber::<MasterPose>(&node, inst, ServiceKind::Master)?;
    let ss = subscriber::<JointSetpoint>(&node, inst, ServiceKind::Setpoint)?;
    let st = subscriber::<JointState>(&node, inst, ServiceKind::State)?;
    let (mut master, mut sp, mut states) = (Vec::new(), Vec::new(), Vec::new());
    let end = Instant::now() + Duration::from_secs_f64(args.duration);
    while Instant::now() < end {
        while let Ok(Some(s)) = ms.receive() {
            master.push(*s);
        }
        while let Ok(Some(s)) = ss.receive() {
            sp.push(*s);
        }
        while let Ok(Some(s)) = st.receive() {
            states.push(*s);
        }
        std::thread::sleep(Duration::from_millis(2));
    }
    let r = analyse(
        &robot,
        &cfg,
        &master,
        &sp,
        &states,
        args.settle,
        (args.voluntary_hz, args.tremor_hz),
    )
    .context("teleop report")?;
    let v = verdict(&r, &args);
    if args.json {
        let mut obj = serde_json::to_value(&r)?;
        if let Some(m) = obj.as_object_mut() {
            m.insert("verdict".into(), serde_json::to_value(&v)?);
        }
        println!("{obj}");
    } else {
        println!(
            "teleop report of `{inst}` ({:.1} s analysed, {} master samples, {} setpoints)",
            r.analysed_s, r.master_samples, r.setpoints
        );
        println!(
            "  tremor {:.2} Hz: attenuation {:.1} dB (hand/ratio {:.4} mm -> tool {:.5} mm); filter alone: {:.1} / {:.1} / {:.1} dB at 8 / 10 / 12 Hz",
            r.tremor.frequency_hz,
            r.tremor_attenuation_db,
            r.tremor.hand_scaled_amplitude_mm,
            r.tremor.tool_amplitude_mm,
            r.filter_attenuation_db_8_10_12_hz[0],
            r.filter_attenuation_db_8_10_12_hz[1],
            r.filter_attenuation_db_8_10_12_hz[2]
        );
        println!(
            "  voluntary {:.2} Hz: gain {:+.2} dB, phase lag {:.1} deg (filter alone {:.1} deg); scaling error {:.2} %",
            r.voluntary.frequency_hz,
            r.voluntary.gain_db,
            r.voluntary.phase_lag_deg,
            r.filter_phase_lag_deg_at_voluntary,
            r.scaling_error_pct
        );
        println!(
            "  final displacement: hand/ratio {:.4} mm, error {:.2} %",
            r.final_hand_scaled_displacement_mm, r.final_displacement_error_pct
        );
        println!(
            "  latency master sample -> setpoint: p50 {:.0} us, p99 {:.0} us ({} samples)",
            r.latency_us.p50, r.latency_us.p99, r.latency_us.count
        );
        println!(
            "  tool tracking error of the arm: p50 {:.2} um, p99 {:.2} um, max {:.2} um",
            r.tracking_error_um.p50, r.tracking_error_um.p99, r.tracking_error_um.max
        );
        let f = &r.flag_counts;
        let named = [
            ("teleop", f.teleop),
            ("clutch open", f.clutch_open),
            ("master stale", f.master_stale),
            ("workspace edge", f.workspace_edge),
            ("singularity", f.singularity),
            ("configuration flip refused", f.flip_refused),
            ("input refused", f.input_refused),
            ("limited", f.limited),
        ];
        println!(
            "  setpoint flags (setpoints carrying each flag, % of the {} setpoints seen):",
            r.setpoints
        );
        for (name, n) in named {
            if n > 0 {
                println!(
                    "    {name:<27} {n:>7}  {:5.1} %",
                    100.0 * n as f64 / r.setpoints.max(1) as f64
                );
            }
        }
    }
    if !args.json {
        println!("  verdict:");
        for c in &v.checks {
            println!(
                "    {:<26} {:<22} {:<20} {}",
                c.name,
                c.measured,
                c.threshold,
                match c.pass {
                    Some(true) => "pass",
                    Some(false) => "FAIL",
                    None => "not judged",
                }
            );
        }
        println!("  result: {}", if v.pass { "PASS" } else { "FAIL" });
    }
    if !v.pass {
        return Err(microrobot_command_line::exit::with_code(
            microrobot_runtime::exit_code::JOB_FAILED,
        )(anyhow::anyhow!(
            "teleop report: a check failed (see the verdict)"
        )));
    }
    Ok(())
}
