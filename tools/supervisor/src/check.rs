//! `microrobot check`: validates the pipeline config, its robot and its program together,
//! before anything moves, and prints the resolved settings. `microrobot run` runs the same
//! checks first and refuses to start on an error.
//!
//! Errors (the run would fail or do something else than asked): the robot or program
//! file refused, the joint counts differ, a program target outside its joint's range, a
//! program rate limit above the robot's, a program that cannot be planned from the
//! configured start, a program beside `teleop.enabled`. Warnings (the run goes on, but
//! not as configured): real-time settings this machine will not apply, a start position
//! outside the joint range (it is clamped).

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

use microrobot_actuator::ActuatorConfig;
use microrobot_model::{JointKind, Robot};
use microrobot_planner::program::ProgramRunner;
use microrobot_runtime::config::OwnedSection as _;
use microrobot_runtime::{PipelineConfig, exit_code};
use microrobot_trajectory::MotionState;
use microrobot_trajectory::program::Target;

use crate::run::{RunArgs, resolve_config};

/// Options of `microrobot check`; the overrides are `run`'s.
#[derive(Debug, Clone, clap::Args)]
pub struct CheckArgs {
    /// Pipeline config (default: ./config/pipeline.toml, else the shipped one).
    #[arg(long, default_value_os_t = microrobot_command_line::config_path::default_config())]
    pub config: PathBuf,
    /// Robot file (overrides `robot`).
    #[arg(long, value_name = "FILE")]
    pub robot: Option<PathBuf>,
    /// Motion program file (overrides `program`).
    #[arg(long, value_name = "FILE")]
    pub program: Option<PathBuf>,
    /// Check without the config's program.
    #[arg(long, conflicts_with = "program")]
    pub no_program: bool,
    /// Print only warnings, errors and the verdict, not the resolved settings.
    #[arg(long, short)]
    pub quiet: bool,
}

/// What the checks found.
#[derive(Debug, Default, Clone, PartialEq)]
pub struct Findings {
    /// The run would fail, or do something other than asked.
    pub errors: Vec<String>,
    /// The run goes on, but not exactly as configured.
    pub warnings: Vec<String>,
    /// What was checked and found right (the resolved robot and program).
    pub notes: Vec<String>,
}

impl Findings {
    /// The findings as terminal lines: notes, then `warning:` and `error:` lines.
    pub fn render(&self, with_notes: bool) -> String {
        let mut s = String::new();
        if with_notes {
            for n in &self.notes {
                let _ = writeln!(s, "{n}");
            }
        }
        for w in &self.warnings {
            let _ = writeln!(s, "warning: {w}");
        }
        for e in &self.errors {
            let _ = writeln!(s, "error: {e}");
        }
        s
    }
}

/// `microrobot check`.
pub fn main(args: CheckArgs) -> ExitCode {
    let run_args = RunArgs {
        program: args.program.clone(),
        no_program: args.no_program,
        ..RunArgs::for_config(args.config.clone())
    };
    let mut cfg = match resolve_config(&run_args) {
        Ok(c) => c,
        Err(e) => {
            eprintln!("error: bad config: {e:#}");
            eprintln!("check: FAILED");
            return ExitCode::from(exit_code::BAD_CONFIG);
        }
    };
    if let Some(r) = &args.robot {
        match std::fs::canonicalize(r) {
            Ok(abs) => cfg.robot = abs,
            Err(e) => {
                eprintln!("error: --robot {}: cannot open: {e}", r.display());
                eprintln!("check: FAILED");
                return ExitCode::from(exit_code::BAD_CONFIG);
            }
        }
    }
    if !args.quiet {
        println!("# resolved pipeline config ({})", args.config.display());
        print!("{}", cfg.to_toml_string());
        println!();
    }
    let f = check_pipeline(&cfg);
    print!("{}", f.render(!args.quiet));
    if f.errors.is_empty() {
        println!(
            "check: ok{}",
            if f.warnings.is_empty() {
                String::new()
            } else {
                format!(" ({} warning(s))", f.warnings.len())
            }
        );
        ExitCode::from(exit_code::OK)
    } else {
        println!("check: FAILED ({} error(s))", f.errors.len());
        ExitCode::from(exit_code::BAD_CONFIG)
    }
}

/// `x` with at most 6 decimals and no trailing zeros (`120`, `-90`, `0.5`, `2.094395`).
pub fn trim_number(x: f64) -> String {
    let s = format!("{x:.6}");
    let s = s.trim_end_matches('0').trim_end_matches('.');
    if s == "-0" {
        "0".to_string()
    } else {
        s.to_string()
    }
}

/// A joint value in the unit a user writes it in: degrees (revolute) or mm (prismatic).
fn user_value(kind: JointKind, si: f64) -> String {
    match kind {
        JointKind::Revolute => format!("{}°", trim_number(si.to_degrees())),
        JointKind::Prismatic => format!("{} mm", trim_number(si * 1e3)),
    }
}

/// A joint rate in user units: `order` 1 velocity, 2 acceleration, 3 jerk.
fn user_rate(kind: JointKind, si: f64, order: i32) -> String {
    let (v, unit) = match kind {
        JointKind::Revolute => (si.to_degrees(), "°"),
        JointKind::Prismatic => (si * 1e3, " mm"),
    };
    let per = match order {
        1 => "/s",
        2 => "/s²",
        _ => "/s³",
    };
    format!("{}{unit}{per}", trim_number(v))
}

/// Every check of `microrobot check` on a resolved config.
pub fn check_pipeline(cfg: &PipelineConfig) -> Findings {
    let mut f = Findings::default();
    let robot = match Robot::from_file(&cfg.robot) {
        Ok(r) => r,
        Err(e) => {
            f.errors
                .push(format!("robot file {}: {e}", cfg.robot.display()));
            return f;
        }
    };
    f.notes.push(format!(
        "robot `{}` ({}): {} joints: {}",
        robot.name(),
        cfg.robot.display(),
        robot.dof(),
        robot
            .joints()
            .iter()
            .map(|j| format!(
                "{} [{}, {}]",
                j.name,
                user_value(j.kind, j.limits.min),
                user_value(j.kind, j.limits.max)
            ))
            .collect::<Vec<_>>()
            .join(", ")
    ));
    if let Some(msg) = microrobot_planner::missing_limits_error(&robot) {
        f.errors
            .push(format!("robot file {}: {msg}", cfg.robot.display()));
    }
    let start = start_position(&robot, cfg, &mut f);
    check_realtime(cfg, &mut f);
    let Some(path) = &cfg.program else {
        f.notes
            .push("program: none (the arm holds and takes `microrobot send` commands)".into());
        return f;
    };
    if microrobot_planner::TeleopConfig::from_pipeline(cfg).is_ok_and(|t| t.enabled) {
        f.errors.push(format!(
            "program {} is set, but teleop.enabled = true: the planner would start in teleop mode and never run it (run with --no-program, or set teleop.enabled = false)",
            path.display()
        ));
    }
    let mut runner = match ProgramRunner::from_file(path, &robot) {
        Ok(r) => r,
        Err(e) => {
            f.errors.push(format!("program: {e}"));
            return f;
        }
    };
    let errors_before = f.errors.len();
    check_program_values(&robot, runner.program(), path, &mut f);
    if f.errors.len() > errors_before {
        return f;
    }
    let limits = microrobot_planner::program_limits(&robot, cfg);
    let state = MotionState {
        q: start,
        ..Default::default()
    };
    match runner.plan(&robot, &state, &limits) {
        Ok(()) => f.notes.push(format!(
            "program `{}` ({}): {} segment(s), {:.3} s from the configured start{}",
            runner.name(),
            path.display(),
            runner.program().segments.len(),
            runner.duration(),
            match cfg.duration_s {
                Some(d) if d < runner.duration() =>
                    format!("; duration_s = {d} s ends the run before the program does"),
                _ => String::new(),
            }
        )),
        Err(e) => f.errors.push(format!(
            "program {} cannot be planned from the configured start ({}): {e}",
            path.display(),
            start_origin(cfg)
        )),
    }
    f
}

fn start_origin(cfg: &PipelineConfig) -> &'static str {
    if ActuatorConfig::from_pipeline(cfg).is_ok_and(|a| a.command.is_some()) {
        "an external driver reports the real start at run time; checked from actuator.sim.initial_q_deg"
    } else {
        "actuator.sim.initial_q_deg"
    }
}

/// The simulated arm's start position (`actuator.sim.initial_q_deg`), clamped into the
/// joint ranges as the simulator does; a value outside is a warning.
fn start_position(
    robot: &Robot,
    cfg: &PipelineConfig,
    f: &mut Findings,
) -> microrobot_model::JointVector {
    // Validated at load: the defaults stand in only for a config built in code.
    let sim = ActuatorConfig::from_pipeline(cfg).unwrap_or_default().sim;
    let mut q = microrobot_actuator::initial_q(robot, &sim);
    for (i, j) in robot.joints().iter().enumerate() {
        if !j.limits.contains(q[i]) {
            f.warnings.push(format!(
                "actuator.sim.initial_q_deg[{i}] ({}): {} is outside [{}, {}]; the arm starts clamped at {}",
                j.name,
                user_value(j.kind, q[i]),
                user_value(j.kind, j.limits.min),
                user_value(j.kind, j.limits.max),
                user_value(j.kind, j.limits.clamp(q[i]))
            ));
            q[i] = j.limits.clamp(q[i]);
        }
    }
    q
}

/// Joint targets inside their joints' ranges, the program's own rate limits within the
/// robot's (the planner plans with them in place of the robot's).
fn check_program_values(
    robot: &Robot,
    program: &microrobot_trajectory::program::Program,
    path: &Path,
    f: &mut Findings,
) {
    for (k, seg) in program.segments.iter().enumerate() {
        let Target::Joint(q) = &seg.target else {
            continue;
        };
        for (i, j) in robot.joints().iter().enumerate() {
            if !j.limits.contains(q[i]) {
                f.errors.push(format!(
                    "program {}: segment {k}{}: {} target {} is outside its range [{}, {}]",
                    path.display(),
                    seg.name
                        .as_deref()
                        .map(|n| format!(" (`{n}`)"))
                        .unwrap_or_default(),
                    j.name,
                    user_value(j.kind, q[i]),
                    user_value(j.kind, j.limits.min),
                    user_value(j.kind, j.limits.max)
                ));
            }
        }
    }
    if let Some([v, a, jk]) = &program.limits {
        for (i, j) in robot.joints().iter().enumerate() {
            for (order, name, given, robot_max) in [
                (1, "vel", v[i], j.limits.velocity),
                (2, "acc", a[i], j.limits.acceleration),
                (3, "jerk", jk[i], j.limits.jerk),
            ] {
                if given > robot_max * (1.0 + 1e-12) {
                    f.errors.push(format!(
                        "program {}: [limits] {name} of {} is {}, above the robot's {}",
                        path.display(),
                        j.name,
                        user_rate(j.kind, given, order),
                        user_rate(j.kind, robot_max, order)
                    ));
                }
            }
        }
    }
}

/// The CPUs this machine has online (`/sys/devices/system/cpu/online`, e.g. `0-1,4`).
fn online_cpus() -> Option<Vec<usize>> {
    let text = std::fs::read_to_string("/sys/devices/system/cpu/online").ok()?;
    parse_cpu_list(text.trim())
}

/// Parses a kernel CPU list (`0-3,6,8-9`).
fn parse_cpu_list(s: &str) -> Option<Vec<usize>> {
    let mut out = Vec::new();
    for part in s.split(',').filter(|p| !p.is_empty()) {
        match part.split_once('-') {
            Some((a, b)) => {
                let (a, b): (usize, usize) = (a.parse().ok()?, b.parse().ok()?);
                out.extend(a..=b);
            }
            None => out.push(part.parse().ok()?),
        }
    }
    Some(out)
}

/// Real-time settings this process's user and machine will not apply (each service
/// falls back with one warning in its log; `check` says so on the terminal).
fn check_realtime(cfg: &PipelineConfig, f: &mut Findings) {
    let rt = cfg.service_realtime();
    if let Some(online) = online_cpus() {
        for c in &rt.cpu_affinity {
            if !online.contains(c) {
                f.warnings.push(format!(
                    "realtime.cpu_affinity: CPU {c} is not online here (online: {online:?}); the services will not be pinned"
                ));
            }
        }
    }
    // SAFETY: geteuid and getrlimit have no preconditions; `lim` is a valid out-pointer.
    let root = unsafe { libc::geteuid() } == 0;
    let rlimit = |res| {
        let mut lim = libc::rlimit {
            rlim_cur: 0,
            rlim_max: 0,
        };
        // SAFETY: as above.
        (unsafe { libc::getrlimit(res, &mut lim) } == 0).then_some(lim.rlim_cur)
    };
    if rt.sched_fifo_priority > 0 && !root {
        let allowed = rlimit(libc::RLIMIT_RTPRIO).unwrap_or(0);
        if allowed < u64::from(rt.sched_fifo_priority) {
            f.warnings.push(format!(
                "realtime.sched_fifo_priority = {}: RLIMIT_RTPRIO is {allowed} for this user; the services will run SCHED_OTHER",
                rt.sched_fifo_priority
            ));
        }
    }
    if rt.mlockall && !root && rlimit(libc::RLIMIT_MEMLOCK) != Some(libc::RLIM_INFINITY) {
        f.warnings.push(
            "realtime.mlockall = true: RLIMIT_MEMLOCK is limited for this user; memory locking may fail".into(),
        );
    }
    if rt.pm_qos
        && std::fs::OpenOptions::new()
            .write(true)
            .open("/dev/cpu_dma_latency")
            .is_err()
    {
        f.warnings.push(
            "realtime.pm_qos = true: /dev/cpu_dma_latency cannot be opened for writing; no PM QoS request".into(),
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cpu_lists_parse_ranges_and_singles() {
        assert_eq!(parse_cpu_list("0-1"), Some(vec![0, 1]));
        assert_eq!(parse_cpu_list("0-2,5,7-8"), Some(vec![0, 1, 2, 5, 7, 8]));
        assert_eq!(parse_cpu_list("3"), Some(vec![3]));
        assert_eq!(parse_cpu_list("x"), None);
    }
}
