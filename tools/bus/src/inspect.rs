//! Looking at a running arm from the outside, as `ros2 node list` / `topic echo` /
//! `topic hz` do: `microrobot list` (running instances), `echo <stream>` (each message as
//! a JSON line), `hz <stream>` (rate and period statistics from the publishers' stamps)
//! and `logs <role>` (a service's log file). None of them creates a bus service: an
//! instance that is not running is an error, not an empty stream.

use std::io::{BufRead as _, Seek as _, Write as _};
use std::path::PathBuf;
use std::time::{Duration, Instant};

use anyhow::{Context as _, Result, anyhow};
use microrobot_messages::{
    JointSetpoint, JointState, MasterPose, MotionCommand, ServiceKind, ServiceStatus,
    TorqueCommand, open_publish_subscribe, service_name,
};
use serde_json::{Value, json};

use crate::recording;
use microrobot_command_line::exit::with_code;
use microrobot_supervisor::instance;

/// The streams `echo` and `hz` take, by their bus names.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Stream {
    Setpoint,
    Torque,
    State,
    Command,
    Status,
    Master,
}

impl Stream {
    fn kind(self) -> ServiceKind {
        match self {
            Stream::Setpoint => ServiceKind::Setpoint,
            Stream::Torque => ServiceKind::Torque,
            Stream::State => ServiceKind::State,
            Stream::Command => ServiceKind::Command,
            Stream::Status => ServiceKind::Status,
            Stream::Master => ServiceKind::Master,
        }
    }
}

/// Options of `microrobot echo`.
#[derive(Debug, clap::Args)]
pub struct EchoArgs {
    /// The stream to print.
    #[arg(value_enum)]
    pub stream: Stream,
    /// Instance name of the running pipeline.
    #[arg(long, default_value = "default", value_name = "NAME")]
    pub instance: String,
    /// Exit after this many messages.
    #[arg(long, short = 'n', value_name = "N")]
    pub count: Option<u64>,
    /// Print every Nth message only (1 kHz is a lot of lines).
    #[arg(long, default_value_t = 1, value_name = "N")]
    pub every: u64,
    /// Exit after this long (default: until Ctrl-C or the pipeline ends).
    #[arg(long, value_name = "DURATION", value_parser = microrobot_command_line::duration::parse)]
    pub duration: Option<f64>,
}

/// Options of `microrobot hz`.
#[derive(Debug, clap::Args)]
pub struct HzArgs {
    /// The stream to measure.
    #[arg(value_enum)]
    pub stream: Stream,
    /// Instance name of the running pipeline.
    #[arg(long, default_value = "default", value_name = "NAME")]
    pub instance: String,
    /// Length of each measuring window; one line per window.
    #[arg(long, default_value = "1s", value_name = "DURATION", value_parser = microrobot_command_line::duration::parse)]
    pub window: f64,
    /// Exit after this long (default: until Ctrl-C or the pipeline ends).
    #[arg(long, value_name = "DURATION", value_parser = microrobot_command_line::duration::parse)]
    pub duration: Option<f64>,
}

/// Options of `microrobot logs`.
#[derive(Debug, clap::Args)]
pub struct LogsArgs {
    /// `planner`, `dynamics`, `actuator` or `recorder`.
    #[arg(value_parser = ["planner", "dynamics", "actuator", "recorder"])]
    pub role: String,
    /// Instance name.
    #[arg(long, default_value = "default", value_name = "NAME")]
    pub instance: String,
    /// Print only the last N lines.
    #[arg(long, short = 'n', value_name = "N")]
    pub lines: Option<usize>,
    /// Keep printing what is appended (until Ctrl-C).
    #[arg(long, short)]
    pub follow: bool,
}

/// Options of `microrobot list`.
#[derive(Debug, clap::Args)]
pub struct ListArgs {
    /// One JSON object per instance.
    #[arg(long)]
    pub json: bool,
    /// Remove the run directories of instances that no longer run.
    #[arg(long)]
    pub clean: bool,
}

/// One message as received: its JSON form, sequence number and publisher stamp.
struct Seen {
    json: Value,
    stamp_ns: u64,
}

fn seen_setpoint(m: &JointSetpoint) -> Seen {
    Seen {
        json: recording::setpoint_json(m),
        stamp_ns: m.header.stamp_ns,
    }
}
fn seen_torque(m: &TorqueCommand) -> Seen {
    Seen {
        json: recording::torque_json(m),
        stamp_ns: m.header.stamp_ns,
    }
}
fn seen_state(m: &JointState) -> Seen {
    Seen {
        json: recording::state_json(m),
        stamp_ns: m.header.stamp_ns,
    }
}
fn seen_command(m: &MotionCommand) -> Seen {
    Seen {
        json: recording::command_json(m),
        stamp_ns: m.stamp_ns,
    }
}
fn seen_status(m: &ServiceStatus) -> Seen {
    Seen {
        json: recording::status_json(m),
        stamp_ns: m.stamp_ns,
    }
}
fn seen_master(m: &MasterPose) -> Seen {
    Seen {
        json: json!({
            "seq": m.seq,
            "stamp_ns": m.stamp_ns,
            "device_stamp_ns": m.device_stamp_ns,
            "position": m.position,
            "orientation": m.orientation,
            "clutch": m.clutch,
            "grip": m.grip,
        }),
        stamp_ns: m.stamp_ns,
    }
}

/// Refuses an instance with no live process (so nothing here creates its services).
pub fn require_running(name: &str) -> Result<()> {
    if instance::live_nodes(name).is_empty() {
        return Err(with_code(microrobot_runtime::exit_code::FAILURE)(anyhow!(
            "no pipeline instance `{name}` is running (see `microrobot list`)"
        )));
    }
    Ok(())
}

/// Calls `on` for every message of `stream` until it returns false, `until` passes or
/// the instance stops running.
fn tap(
    name: &str,
    stream: Stream,
    until: Option<Instant>,
    mut on: impl FnMut(Seen) -> bool,
) -> Result<()> {
    require_running(name)?;
    iceoryx2::prelude::set_log_level_from_env_or(iceoryx2::prelude::LogLevel::Error);
    let node = microrobot_runtime::node::named_node(&format!(
        "microrobot-tap.{name}.{}",
        std::process::id()
    ))?;
    macro_rules! run_tap {
        ($t:ty, $wrap:expr) => {{
            let sub = open_publish_subscribe::<$t>(&node, name, stream.kind())?
                .subscriber_builder()
                .buffer_size(microrobot_messages::ports::qos::SUBSCRIBER_BUFFER)
                .create()
                .map_err(|e| anyhow!("{} subscriber: {e:?}", service_name(name, stream.kind())))?;
            let mut last_alive_check = Instant::now();
            loop {
                while let Ok(Some(s)) = sub.receive() {
                    if !on($wrap(&*s)) {
                        return Ok(());
                    }
                }
                if until.is_some_and(|u| Instant::now() >= u) {
                    return Ok(());
                }
                if last_alive_check.elapsed() >= Duration::from_secs(1) {
                    last_alive_check = Instant::now();
                    if instance::live_nodes(name).is_empty() {
                        // No service of the instance is left: the pipeline ended.
                        eprintln!("instance `{name}` stopped");
                        return Ok(());
                    }
                }
                std::thread::sleep(Duration::from_millis(1));
            }
        }};
    }
    match stream {
        Stream::Setpoint => run_tap!(JointSetpoint, seen_setpoint),
        Stream::Torque => run_tap!(TorqueCommand, seen_torque),
        Stream::State => run_tap!(JointState, seen_state),
        Stream::Command => run_tap!(MotionCommand, seen_command),
        Stream::Status => run_tap!(ServiceStatus, seen_status),
        Stream::Master => run_tap!(MasterPose, seen_master),
    }
}

fn deadline(d: Option<f64>) -> Option<Instant> {
    d.map(|s| Instant::now() + Duration::from_secs_f64(s))
}

/// `microrobot echo`.
pub fn echo(args: EchoArgs) -> Result<()> {
    anyhow::ensure!(args.every >= 1, "--every: must be at least 1");
    let mut n = 0u64;
    let mut printed = 0u64;
    let stdout = std::io::stdout();
    let mut out = stdout.lock();
    let mut err = None;
    tap(&args.instance, args.stream, deadline(args.duration), |m| {
        n += 1;
        if !(n - 1).is_multiple_of(args.every) {
            return true;
        }
        if let Err(e) = writeln!(out, "{}", m.json) {
            err = Some(e);
            return false;
        }
        printed += 1;
        args.count.is_none_or(|c| printed < c)
    })?;
    match err {
        Some(e) => Err(e).context("writing stdout"),
        None => Ok(()),
    }
}

/// Rate and period statistics of one window of stamps (ns), as `ros2 topic hz` prints.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HzWindow {
    pub messages: usize,
    pub rate_hz: f64,
    pub min_ms: f64,
    pub max_ms: f64,
    pub std_ms: f64,
}

/// Statistics of `stamps` (publisher stamps, ns, in arrival order); `None` below two.
pub fn hz_of(stamps: &[u64]) -> Option<HzWindow> {
    if stamps.len() < 2 {
        return None;
    }
    let periods: Vec<f64> = stamps
        .windows(2)
        .map(|w| w[1].saturating_sub(w[0]) as f64 / 1e6)
        .collect();
    let mean = periods.iter().sum::<f64>() / periods.len() as f64;
    let var = periods.iter().map(|p| (p - mean).powi(2)).sum::<f64>() / periods.len() as f64;
    Some(HzWindow {
        messages: stamps.len(),
        rate_hz: if mean > 0.0 {
            1e3 / mean
        } else {
            f64::INFINITY
        },
        min_ms: periods.iter().copied().fold(f64::INFINITY, f64::min),
        max_ms: periods.iter().copied().fold(0.0, f64::max),
        std_ms: var.sqrt(),
    })
}

/// `microrobot hz`.
pub fn hz(args: HzArgs) -> Result<()> {
    let window = Duration::from_secs_f64(args.window);
    let mut stamps: Vec<u64> = Vec::new();
    let mut start = Instant::now();
    let mut err = None;
    tap(&args.instance, args.stream, deadline(args.duration), |m| {
        stamps.push(m.stamp_ns);
        if start.elapsed() >= window {
            start = Instant::now();
            let line = match hz_of(&stamps) {
                Some(w) => format!(
                    "average rate: {:.3} Hz  min: {:.3} ms  max: {:.3} ms  std dev: {:.4} ms  window: {}",
                    w.rate_hz, w.min_ms, w.max_ms, w.std_ms, w.messages
                ),
                None => "no new messages".to_string(),
            };
            if let Err(e) = writeln!(std::io::stdout(), "{line}") {
                err = Some(e);
                return false;
            }
            // Keep the last stamp so the next window's first period is counted.
            let last = stamps.last().copied();
            stamps.clear();
            stamps.extend(last);
        }
        true
    })?;
    match err {
        Some(e) => Err(e).context("writing stdout"),
        None => Ok(()),
    }
}

/// `microrobot logs`.
pub fn logs(args: LogsArgs) -> Result<()> {
    let path = instance::run_file(&args.instance, &format!("{}.log", args.role))?;
    let mut file = std::fs::File::open(&path).map_err(|e| {
        anyhow!(
            "{}: {e} (no run of instance `{}` with a {} here; see `microrobot list`)",
            path.display(),
            args.instance,
            args.role
        )
    })?;
    let text = std::io::read_to_string(&mut file).with_context(|| format!("{}", path.display()))?;
    let lines: Vec<&str> = text.lines().collect();
    let from = args.lines.map_or(0, |n| lines.len().saturating_sub(n));
    let stdout = std::io::stdout();
    let mut out = stdout.lock();
    for l in &lines[from..] {
        writeln!(out, "{l}")?;
    }
    if !args.follow {
        return Ok(());
    }
    let mut reader = std::io::BufReader::new(file);
    let mut pos = reader.stream_position()?;
    loop {
        let mut line = String::new();
        match reader.read_line(&mut line)? {
            0 => {
                out.flush()?;
                std::thread::sleep(Duration::from_millis(200));
                // A new run truncates and rewrites the log: start again from its top.
                let len = std::fs::metadata(&path).map(|m| m.len()).unwrap_or(pos);
                if len < pos {
                    reader.rewind()?;
                    pos = 0;
                }
            }
            n => {
                pos += n as u64;
                write!(out, "{line}")?;
            }
        }
    }
}

/// One instance as `microrobot list` shows it.
#[derive(Debug, Clone, serde::Serialize)]
pub struct InstanceRow {
    pub instance: String,
    /// `running` (live processes) or `stale` (a run directory whose processes are gone).
    pub state: String,
    pub robot: Option<String>,
    pub rate_hz: Option<f64>,
    /// Since the run wrote its resolved config (s).
    pub uptime_s: Option<f64>,
    pub processes: usize,
    pub run_dir: String,
}

/// Robot and rate from a run directory's resolved config (a plain key lookup: the file
/// is the supervisor's own output).
fn resolved_facts(dir: &std::path::Path) -> (Option<String>, Option<f64>, Option<f64>) {
    let path = dir.join("pipeline.resolved.toml");
    let Ok(text) = std::fs::read_to_string(&path) else {
        return (None, None, None);
    };
    let table: toml::Table = match text.parse() {
        Ok(t) => t,
        Err(_) => return (None, None, None),
    };
    let robot = table.get("robot").and_then(|v| v.as_str()).map(|s| {
        PathBuf::from(s)
            .file_name()
            .map_or(s.to_string(), |f| f.to_string_lossy().into_owned())
    });
    let rate = table.get("rate_hz").and_then(|v| v.as_float());
    let uptime = std::fs::metadata(&path)
        .and_then(|m| m.modified())
        .ok()
        .and_then(|t| t.elapsed().ok())
        .map(|d| d.as_secs_f64());
    (robot, rate, uptime)
}

/// The instances with a run directory or live processes.
pub fn instances() -> Vec<InstanceRow> {
    let dir = instance::state_dir();
    let mut names: Vec<String> = std::fs::read_dir(&dir)
        .map(|rd| {
            rd.flatten()
                .filter(|e| e.file_type().is_ok_and(|t| t.is_dir()))
                .map(|e| e.file_name().to_string_lossy().into_owned())
                .collect()
        })
        .unwrap_or_default();
    names.sort();
    names
        .into_iter()
        .map(|name| {
            let live = instance::live_nodes(&name).len();
            let run_dir = dir.join(&name);
            let (robot, rate_hz, uptime_s) = resolved_facts(&run_dir);
            InstanceRow {
                state: if live > 0 { "running" } else { "stale" }.to_string(),
                robot,
                rate_hz,
                uptime_s: if live > 0 { uptime_s } else { None },
                processes: live,
                run_dir: run_dir.display().to_string(),
                instance: name,
            }
        })
        .collect()
}

/// `microrobot list`.
pub fn list(args: ListArgs) -> Result<()> {
    let rows = instances();
    let stdout = std::io::stdout();
    let mut out = stdout.lock();
    if args.json {
        for r in &rows {
            writeln!(out, "{}", serde_json::to_string(r)?)?;
        }
    } else if rows.is_empty() {
        writeln!(
            out,
            "no instances (state directory {})",
            instance::state_dir().display()
        )?;
    } else {
        writeln!(
            out,
            "{:<24} {:<8} {:<20} {:>8} {:>10} {:>5}  run dir",
            "instance", "state", "robot", "rate Hz", "uptime s", "procs"
        )?;
        for r in &rows {
            writeln!(
                out,
                "{:<24} {:<8} {:<20} {:>8} {:>10} {:>5}  {}",
                r.instance,
                r.state,
                r.robot.as_deref().unwrap_or("-"),
                r.rate_hz.map_or("-".into(), |v| format!("{v:.0}")),
                r.uptime_s.map_or("-".into(), |v| format!("{v:.0}")),
                r.processes,
                r.run_dir
            )?;
        }
    }
    if args.clean {
        let mut removed = 0;
        for r in rows.iter().filter(|r| r.state == "stale") {
            // Only what a run writes: its logs and resolved config, then the directory.
            let dir = PathBuf::from(&r.run_dir);
            if std::fs::symlink_metadata(&dir).is_ok_and(|m| m.file_type().is_dir()) {
                std::fs::remove_dir_all(&dir)
                    .with_context(|| format!("cannot remove {}", dir.display()))?;
                removed += 1;
            }
        }
        writeln!(out, "removed {removed} stale run director(y/ies)")?;
    } else if rows.iter().any(|r| r.state == "stale") {
        writeln!(
            out,
            "(stale: the run ended; `microrobot list --clean` removes its directory)"
        )?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hz_of_a_regular_stream_is_its_rate() {
        let stamps: Vec<u64> = (0..1001).map(|i| i * 1_000_000).collect();
        let w = hz_of(&stamps).expect("enough stamps");
        assert!((w.rate_hz - 1000.0).abs() < 1e-9, "{w:?}");
        assert_eq!((w.min_ms, w.max_ms), (1.0, 1.0));
        assert_eq!(w.std_ms, 0.0);
        assert_eq!(hz_of(&[5]), None);
    }

    #[test]
    fn hz_of_a_stalled_stream_shows_the_gap() {
        let mut stamps: Vec<u64> = (0..10).map(|i| i * 1_000_000).collect();
        stamps.push(30_000_000);
        let w = hz_of(&stamps).expect("enough stamps");
        assert_eq!(w.max_ms, 21.0);
        assert_eq!(w.min_ms, 1.0);
        assert!((w.rate_hz - 1e3 / 3.0).abs() < 1e-9, "{w:?}");
    }
}
