//! `microrobot top`: a live table of a running pipeline's services from their status
//! stream: cycles/s, latency p50/p99 (planner: wake-up lateness, dynamics: setpoint →
//! torque, actuator: end-to-end), misses, lost, refused, stale, faults, lifecycle, and the
//! planner's e-stop latency (receipt of the last e-stop → its first braking setpoint).

use std::io::IsTerminal as _;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use anyhow::ensure;
use microrobot_messages::ServiceRole;
use serde::Serialize;

use crate::supervisor::monitor::StatusMonitor;
use crate::supervisor::summary::lifecycle_name;

/// Options of `microrobot top`.
#[derive(Debug, clap::Args)]
pub struct TopArgs {
    /// Instance name of the running pipeline.
    #[arg(long, default_value = "default", value_name = "NAME")]
    pub instance: String,
    /// Print one table (or JSON object) and exit.
    #[arg(long)]
    pub once: bool,
    /// JSON output (one object per refresh).
    #[arg(long)]
    pub json: bool,
    /// Refresh period in s.
    #[arg(long, default_value_t = 1.0, value_name = "DURATION", value_parser = crate::duration::parse)]
    pub interval: f64,
    /// Give up if no service reports within this many seconds.
    #[arg(long, default_value_t = 5.0, value_name = "DURATION", value_parser = crate::duration::parse)]
    pub timeout: f64,
}

/// One row of the table.
#[derive(Debug, Clone, Serialize)]
pub struct Row {
    pub service: &'static str,
    pub pid: u32,
    pub lifecycle: &'static str,
    pub ready: bool,
    pub cycles: u64,
    pub cycles_per_s: Option<f64>,
    pub latency_p50_us: f64,
    pub latency_p99_us: f64,
    pub latency_max_us: f64,
    pub deadline_misses: u64,
    pub lost_messages: u64,
    pub refused_messages: u64,
    pub stale_cycles: u64,
    pub faults: u64,
    /// Planner: e-stops executed, and receipt → first braking setpoint of the last one
    /// (µs; null before the first e-stop and for the other services).
    pub estops: u64,
    pub estop_latency_us: Option<f64>,
    pub motion_time_s: f64,
    pub cpu_time_ms: u32,
    pub rss_kib: u64,
    /// Seconds since this service's last status arrived.
    pub age_s: f64,
}

const ORDER: [ServiceRole; 3] = [
    ServiceRole::Planner,
    ServiceRole::Dynamics,
    ServiceRole::Actuator,
];

fn rows(monitor: &StatusMonitor) -> Vec<Row> {
    let mut out = Vec::new();
    for role in ORDER {
        let Some(seen) = monitor.latest[crate::supervisor::monitor::slot(role)] else {
            continue;
        };
        let st = seen.status;
        let us = |ns: u64| ns as f64 / 1000.0;
        out.push(Row {
            service: role.name(),
            pid: st.pid,
            lifecycle: lifecycle_name(st.lifecycle),
            ready: st.ready == 1,
            cycles: st.cycles,
            cycles_per_s: monitor.rate(role),
            latency_p50_us: us(st.latency.p50_ns),
            latency_p99_us: us(st.latency.p99_ns),
            latency_max_us: us(st.latency.max_ns),
            deadline_misses: st.deadline_misses,
            lost_messages: st.lost_messages,
            refused_messages: st.refused_messages,
            stale_cycles: st.stale_cycles,
            faults: st.faults,
            estops: st.estops,
            estop_latency_us: (st.estop_latency_ns > 0).then(|| us(st.estop_latency_ns)),
            motion_time_s: st.motion_time_s,
            cpu_time_ms: st.cpu_time_ms,
            rss_kib: st.rss_kib,
            age_s: seen.at.elapsed().as_secs_f64(),
        });
    }
    out
}

fn table(instance: &str, rows: &[Row]) -> String {
    let mut s = format!(
        "microrobot top — instance `{instance}`\n{:<9} {:>7} {:<11} {:>9} {:>9} {:>9} {:>7} {:>6} {:>7} {:>6} {:>6} {:>9} {:>11}\n",
        "service",
        "pid",
        "lifecycle",
        "cycles/s",
        "p50 µs",
        "p99 µs",
        "misses",
        "lost",
        "refused",
        "stale",
        "faults",
        "time s",
        "e-stop µs"
    );
    for r in rows {
        let rate = r
            .cycles_per_s
            .map(|v| format!("{v:.0}"))
            .unwrap_or_else(|| "-".into());
        let stale_mark = if r.age_s > 1.0 { " (silent)" } else { "" };
        let estop = r
            .estop_latency_us
            .map(|v| format!("{v:.1}"))
            .unwrap_or_else(|| "-".into());
        s.push_str(&format!(
            "{:<9} {:>7} {:<11} {:>9} {:>9.1} {:>9.1} {:>7} {:>6} {:>7} {:>6} {:>6} {:>9.2} {:>11}{stale_mark}\n",
            r.service,
            r.pid,
            r.lifecycle,
            rate,
            r.latency_p50_us,
            r.latency_p99_us,
            r.deadline_misses,
            r.lost_messages,
            r.refused_messages,
            r.stale_cycles,
            r.faults,
            r.motion_time_s,
            estop,
        ));
    }
    s
}

/// Shows the table until Ctrl-C (or once).
pub fn main(args: TopArgs) -> anyhow::Result<()> {
    ensure!(
        args.interval.is_finite() && args.interval >= 0.1,
        "--interval {}: must be at least 0.1 s",
        args.interval
    );
    ensure!(
        args.timeout.is_finite() && args.timeout > 0.0,
        "--timeout {}: must be a positive number of seconds",
        args.timeout
    );
    iceoryx2::prelude::set_log_level_from_env_or(iceoryx2::prelude::LogLevel::Error);
    let stop = Arc::new(AtomicBool::new(false));
    {
        let flag = stop.clone();
        ctrlc::set_handler(move || flag.store(true, Ordering::SeqCst))?;
    }
    let mut monitor = StatusMonitor::open(
        &args.instance,
        &format!("microrobot-top.{}.{}", args.instance, std::process::id()),
    )?;
    // First contact: something must report.
    let got = monitor.wait_for(Duration::from_secs_f64(args.timeout), |m| {
        m.latest.iter().any(Option::is_some)
    })?;
    ensure!(
        got,
        "no status from pipeline `{}` within {:.1} s: is it running? (`microrobot run --instance {}`)",
        args.instance,
        args.timeout,
        args.instance
    );
    // Every service reports at ~10 Hz: within a second all three are seen, twice
    // each (two statuses give a rate). A missing one shows as absent.
    let _ = monitor.wait_for(Duration::from_millis(1500), |m| {
        m.latest.iter().all(Option::is_some) && m.previous.iter().all(Option::is_some)
    })?;
    let clear = !args.json && !args.once && std::io::stdout().is_terminal();
    loop {
        monitor.poll()?;
        let rows = rows(&monitor);
        if args.json {
            let obj = serde_json::json!({ "instance": args.instance, "services": rows });
            println!("{obj}");
        } else {
            if clear {
                print!("\x1b[H\x1b[2J");
            }
            print!("{}", table(&args.instance, &rows));
        }
        if args.once || stop.load(Ordering::SeqCst) {
            return Ok(());
        }
        let next = Instant::now() + Duration::from_secs_f64(args.interval);
        while Instant::now() < next {
            if stop.load(Ordering::SeqCst) {
                return Ok(());
            }
            std::thread::sleep(Duration::from_millis(50));
        }
    }
}
