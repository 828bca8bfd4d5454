//! `microrobot run`: starts the planner, dynamics and actuator processes of one pipeline
//! instance from `config/pipeline.toml`, supervises them, and prints a summary.
//!
//! Sequence: load and validate the config (+ command-line overrides) → take the
//! instance lock and refuse a live instance → clean what a crashed earlier run left →
//! write the resolved config to the run dir → start actuator, dynamics, planner, each
//! once the previous one reports ready → show progress → stop at the end of the program,
//! after `--duration`, or on Ctrl-C (SIGINT to every child, wait for their final
//! statuses, SIGKILL after the grace period) → restart a service that died if the
//! config says so → summary (and `--summary-json`).

use std::io::IsTerminal as _;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use anyhow::Context as _;
use microrobot_messages::{
    Activity, LifecycleHook, LifecycleState, ProgramEnd, ProgramState, ServiceRole, ServiceStatus,
    monotonic_ns,
};
use microrobot_model::Robot;
use microrobot_runtime::config::{FailurePolicy, OwnedSection as _};
use microrobot_runtime::{PipelineConfig, exit_code};

use crate::binaries::ServiceBinaries;
use crate::instance::{self, InstanceInUse};
use crate::monitor::{ROLES, StatusMonitor, slot};
use crate::process::{Launch, Service, describe, log_tail};
use crate::state_tap::StateTap;
use crate::summary::{ProgramSummary, RunFacts, Summary, fold, lifecycle_name};

/// Options of `microrobot run`; each override replaces the config file's key.
#[derive(Debug, Clone, clap::Args)]
pub struct RunArgs {
    /// Pipeline config, every key documented in config/pipeline.README.md (default:
    /// ./config/pipeline.toml, else the config shipped with the sources).
    #[arg(long, default_value_os_t = microrobot_command_line::config_path::default_config())]
    pub config: PathBuf,
    /// Stop after this many seconds (overrides `duration_s`).
    #[arg(long, value_name = "DURATION", value_parser = microrobot_command_line::duration::parse)]
    pub duration: Option<f64>,
    /// Control rate in Hz (overrides `rate_hz`).
    #[arg(long, value_name = "HZ")]
    pub rate_hz: Option<f64>,
    /// Lockstep: logical time, one plant step per torque command (overrides `lockstep`).
    #[arg(long)]
    pub lockstep: bool,
    /// Motion program file (overrides `program`).
    #[arg(long, value_name = "FILE")]
    pub program: Option<PathBuf>,
    /// Run without a motion program: hold and take `microrobot send` commands.
    #[arg(long, conflicts_with = "program")]
    pub no_program: bool,
    /// Instance name: the service-name prefix (overrides `instance`).
    #[arg(long, value_name = "NAME")]
    pub instance: Option<String>,
    /// Write the summary as JSON to this file.
    #[arg(long, value_name = "FILE")]
    pub summary_json: Option<PathBuf>,
    /// Feed-forward only: computed-torque feedback off (overrides `dynamics.feedback`).
    #[arg(long)]
    pub no_feedback: bool,
    /// Links of the simulated arm heavier by this factor (overrides `actuator.sim.mass_scale`).
    #[arg(long, value_name = "FACTOR")]
    pub mass_scale: Option<f64>,
    /// No progress output, only the summary.
    #[arg(long, short)]
    pub quiet: bool,
    /// Record every topic to this MCAP file (`microrobot record`, started before the
    /// services so it sees the first setpoint, stopped after them).
    #[arg(long, value_name = "FILE.mcap")]
    pub record: Option<PathBuf>,
    /// Run a bare timer loop alongside, at the same rate with the same real-time settings
    /// and overrun policy (the machine's timer floor), and report the planner's lateness and misses against
    /// it in the summary (`floor`). It shares the services' CPU, so it costs them a little.
    #[arg(long)]
    pub floor_probe: bool,
}

impl RunArgs {
    /// The arguments of a plain `microrobot run --config <config>`.
    pub fn for_config(config: PathBuf) -> Self {
        Self {
            config,
            duration: None,
            rate_hz: None,
            lockstep: false,
            program: None,
            no_program: false,
            instance: None,
            summary_json: None,
            no_feedback: false,
            mass_scale: None,
            quiet: false,
            record: None,
            floor_probe: false,
        }
    }
}

/// Runs the pipeline; the exit code is one of [`exit_code`].
pub fn main(args: RunArgs) -> ExitCode {
    let mut floor = FloorProbe::default();
    let hooks: &mut dyn Hooks = if args.floor_probe {
        &mut floor
    } else {
        &mut NoHooks
    };
    let result = supervise_with(&args, hooks).and_then(|(code, mut summary)| {
        summary.floor = floor.finish();
        println!("{}", summary.render());
        if let Some(path) = &args.summary_json {
            write_summary_json(&summary, path).map_err(fail(exit_code::FAILURE))?;
        }
        Ok(code)
    });
    match result {
        Ok(code) => ExitCode::from(code),
        Err(Failure { code, error }) => {
            eprintln!("error: {error:#}");
            ExitCode::from(code)
        }
    }
}

/// Writes `summary` as pretty JSON to `path`.
pub fn write_summary_json(summary: &Summary, path: &Path) -> anyhow::Result<()> {
    let text = serde_json::to_string_pretty(summary).context("cannot serialise the summary")?;
    std::fs::write(path, text + "\n").with_context(|| format!("cannot write {}", path.display()))
}

/// An error with the exit code it maps to.
#[derive(Debug)]
pub struct Failure {
    pub code: u8,
    pub error: anyhow::Error,
}

/// What another command (`microrobot soak`) plugs into the supervision loop; every
/// method has a do-nothing default.
pub trait Hooks {
    /// After the cleanup of an earlier run, before the first service starts (open
    /// observers here so they see the first message).
    fn before_start(&mut self, _cfg: &PipelineConfig) -> anyhow::Result<()> {
        Ok(())
    }
    /// Every supervision loop iteration (~50 Hz) once every service was ready.
    fn poll(&mut self, _ctl: &mut Control<'_>) {}
    /// A dead service is about to be started again; for the actuator, `resume` is the
    /// state it is handed to resume from.
    fn restarting(
        &mut self,
        _role: ServiceRole,
        _resume: Option<&microrobot_messages::JointState>,
    ) {
    }
    /// The supervisor found `role`'s process `pid` hung (no status for
    /// `supervisor.hung_ms`) and is killing it; the death then applies the failure policy.
    fn hung(&mut self, _role: ServiceRole, _pid: u32) {}
    /// Appended to the progress line.
    fn progress(&self) -> String {
        String::new()
    }
    /// Whether this command injects faults on purpose and judges them by its own
    /// verdict (the soak): then a service that died and was restarted, or a safe state
    /// latched at the end, does not fail the run's own verdict.
    fn judges_faults(&self) -> bool {
        false
    }
}

/// `microrobot run` itself: no hooks.
pub struct NoHooks;

impl Hooks for NoHooks {}

/// `microrobot run --floor-probe`: the bare timer loop of
/// [`microrobot_runtime::timer::floor_probe_until`] in a thread with the pipeline's
/// real-time settings, from the moment every service is ready to the end of the run.
#[derive(Default)]
pub struct FloorProbe {
    settings: Option<(microrobot_runtime::config::RealtimeConfig, u64)>,
    stop: std::sync::Arc<std::sync::atomic::AtomicBool>,
    thread:
        Option<std::thread::JoinHandle<std::io::Result<microrobot_runtime::timer::FloorReport>>>,
}

impl FloorProbe {
    /// Stops the loop and returns its figures (None if it never ran or failed).
    pub fn finish(&mut self) -> Option<crate::summary::Floor> {
        self.stop.store(true, std::sync::atomic::Ordering::Relaxed);
        match self.thread.take()?.join() {
            Ok(Ok(f)) => Some(crate::summary::Floor {
                ticks: f.ticks,
                lateness_us: crate::summary::Percentiles::from(&f.lateness),
                deadline_misses: f.deadline_misses,
                window_p99_us: Vec::new(),
            }),
            Ok(Err(e)) => {
                eprintln!("warning: the floor probe failed: {e}");
                None
            }
            Err(_) => {
                eprintln!("warning: the floor probe's thread panicked; no floor reported");
                None
            }
        }
    }
}

impl Hooks for FloorProbe {
    fn before_start(&mut self, cfg: &PipelineConfig) -> anyhow::Result<()> {
        let mut rt = cfg.service_realtime();
        // The supervisor's memory need not be locked for a timer loop.
        rt.mlockall = false;
        self.settings = Some((rt, cfg.period_ns()));
        Ok(())
    }

    fn poll(&mut self, _ctl: &mut Control<'_>) {
        if self.thread.is_some() {
            return;
        }
        let Some((rt, period)) = self.settings.take() else {
            return;
        };
        let stop = self.stop.clone();
        self.thread = std::thread::Builder::new()
            .name("floor-probe".into())
            .spawn(move || {
                let _guard = microrobot_runtime::rt::apply(&rt);
                // At most a day; `finish` ends it with the run.
                microrobot_runtime::timer::floor_probe_until(
                    period,
                    86_400_000_000_000,
                    rt.overrun,
                    &stop,
                )
            })
            .map_err(|e| eprintln!("warning: cannot start the floor probe: {e}; no floor reported"))
            .ok();
    }
}

/// What [`Hooks::poll`] may look at and do.
pub struct Control<'a> {
    pipe: &'a mut Pipeline,
    /// Latest statuses.
    pub monitor: &'a StatusMonitor,
    note: &'a Progress,
}

impl Control<'_> {
    /// `kill -9` of `role`'s current process (the restart policy then applies); its pid.
    pub fn kill(&mut self, role: ServiceRole) -> Option<u32> {
        let s = self.pipe.service(role)?;
        if s.poll_exit().is_some() {
            return None;
        }
        s.signal(libc::SIGKILL);
        Some(s.pid())
    }

    /// Stops `role`'s current process (SIGSTOP: alive, but neither running nor
    /// reporting, as a hung service); its pid.
    pub fn stall(&mut self, role: ServiceRole) -> Option<u32> {
        let s = self.pipe.service(role)?;
        if s.poll_exit().is_some() {
            return None;
        }
        s.signal(libc::SIGSTOP);
        Some(s.pid())
    }

    /// Continues a process [`Control::stall`] stopped, if it is still `role`'s process
    /// (the supervisor may have killed it as hung and started another).
    pub fn resume(&mut self, role: ServiceRole, pid: u32) {
        if let Some(s) = self.pipe.service(role)
            && s.pid() == pid
            && s.poll_exit().is_none()
        {
            s.signal(libc::SIGCONT);
        }
    }

    /// Whether `role` was restarted and has not reported ready yet (or is dead).
    pub fn restarting(&mut self, role: ServiceRole) -> bool {
        self.pipe.restarting[slot(role)].is_some()
            || self
                .pipe
                .service(role)
                .is_none_or(|s| s.poll_exit().is_some())
    }

    /// Restarts of `role` so far.
    pub fn restarts(&self, role: ServiceRole) -> u32 {
        self.pipe.restarts[slot(role)]
    }

    /// A progress note (a line above the progress bar, or a plain line).
    pub fn note(&self, msg: &str) {
        self.note.note(msg);
    }
}

fn fail(code: u8) -> impl FnOnce(anyhow::Error) -> Failure {
    move |error| Failure { code, error }
}

/// Why the run is stopping.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Stop {
    ProgramDone,
    Duration,
    Interrupted,
    ServiceFailed,
    Timeout,
}

impl Stop {
    fn name(self) -> &'static str {
        match self {
            Stop::ProgramDone => "program_done",
            Stop::Duration => "duration",
            Stop::Interrupted => "interrupted",
            Stop::ServiceFailed => "service_failed",
            Stop::Timeout => "timeout",
        }
    }
}

/// Loads the config and applies the command-line overrides; every value is validated
/// again by the config loader, so an override is checked exactly like a file key.
pub fn resolve_config(args: &RunArgs) -> anyhow::Result<PipelineConfig> {
    let mut cfg = microrobot_config::load(&args.config).map_err(anyhow::Error::new)?;
    let mut overridden = false;
    if let Some(d) = args.duration {
        cfg.duration_s = Some(d);
        overridden = true;
    }
    for (flag, v) in [
        ("--rate-hz", args.rate_hz),
        ("--mass-scale", args.mass_scale),
    ] {
        if let Some(v) = v {
            anyhow::ensure!(v.is_finite(), "{flag}: {v} is not a finite number");
        }
    }
    if let Some(r) = args.rate_hz {
        cfg.rate_hz = r;
        overridden = true;
    }
    if args.lockstep {
        cfg.lockstep = true;
        overridden = true;
    }
    if let Some(p) = &args.program {
        let abs = std::fs::canonicalize(p)
            .with_context(|| format!("--program {}: cannot open", p.display()))?;
        cfg.program = Some(abs);
        overridden = true;
    }
    if args.no_program {
        cfg.program = None;
        overridden = true;
    }
    if let Some(i) = &args.instance {
        cfg.instance = i.clone();
        overridden = true;
    }
    if args.no_feedback {
        let dynamics = microrobot_dynamics::DynamicsConfig::from_pipeline(&cfg)?;
        microrobot_dynamics::DynamicsConfig {
            feedback: false,
            ..dynamics
        }
        .store(&mut cfg);
        overridden = true;
    }
    if let Some(m) = args.mass_scale {
        let mut actuator = microrobot_actuator::ActuatorConfig::from_pipeline(&cfg)?;
        actuator.sim.mass_scale = m;
        actuator.store(&mut cfg);
        overridden = true;
    }
    if overridden {
        let origin = format!("{} with command-line overrides", args.config.display());
        let base = args.config.parent().unwrap_or(Path::new("."));
        cfg = microrobot_config::from_toml_str(&cfg.to_toml_string(), &origin, base)
            .map_err(anyhow::Error::new)?;
    }
    Ok(cfg)
}

/// The per-role process slots and what they accumulated over restarts.
pub struct Pipeline {
    services: [Option<Service>; 3],
    /// Counters of earlier incarnations (restarts), per role.
    carried: [Option<ServiceStatus>; 3],
    restarts: [u32; 3],
    /// A restarted service that has not reported ready yet: since when.
    restarting: [Option<Instant>; 3],
}

impl Pipeline {
    fn service(&mut self, role: ServiceRole) -> Option<&mut Service> {
        self.services[slot(role)].as_mut()
    }

    /// Folds the last status of `role`'s current process into the carried totals.
    fn carry(&mut self, role: ServiceRole, monitor: &StatusMonitor) {
        if let Some(st) = monitor.get(role) {
            let acc = self.carried[slot(role)].get_or_insert_with(ServiceStatus::default);
            fold(acc, st);
        }
    }

    fn stop_all(&mut self, monitor: &mut StatusMonitor, grace: Duration) -> bool {
        // The planner first, so nothing new enters the pipeline; then the rest.
        for role in [
            ServiceRole::Planner,
            ServiceRole::Dynamics,
            ServiceRole::Actuator,
        ] {
            if let Some(s) = self.service(role) {
                s.signal(libc::SIGINT);
            }
        }
        let end = Instant::now() + grace;
        loop {
            let _ = monitor.poll();
            let running = self
                .services
                .iter_mut()
                .flatten()
                .map(|s| usize::from(s.poll_exit().is_none()))
                .sum::<usize>();
            if running == 0 {
                break;
            }
            if Instant::now() >= end {
                for s in self.services.iter_mut().flatten() {
                    if s.poll_exit().is_none() {
                        eprintln!(
                            "warning: {} (pid {}) did not stop within {:.1} s; killing it",
                            s.launch.role,
                            s.pid(),
                            grace.as_secs_f64()
                        );
                        s.kill_and_reap();
                    }
                }
                break;
            }
            std::thread::sleep(Duration::from_millis(10));
        }
        // Final statuses may arrive just before exit.
        let _ = monitor.poll();
        self.services
            .iter_mut()
            .flatten()
            .all(|s| s.poll_exit().is_some_and(|e| e.success()))
    }
}

fn role_name(role: ServiceRole) -> &'static str {
    role.name()
}

/// The environment every service (and an external driver) gets: instance, resolved
/// config, rate, lockstep, and the supervisor's pid (see `microrobot_runtime::provenance`).
pub fn service_env(cfg: &PipelineConfig, resolved: &Path) -> Vec<(String, String)> {
    vec![
        ("MICROROBOT_INSTANCE".to_string(), cfg.instance.clone()),
        (
            "MICROROBOT_CONFIG".to_string(),
            resolved.display().to_string(),
        ),
        ("MICROROBOT_RATE_HZ".to_string(), cfg.rate_hz.to_string()),
        (
            "MICROROBOT_LOCKSTEP".to_string(),
            if cfg.lockstep { "1" } else { "0" }.to_string(),
        ),
        (
            microrobot_runtime::provenance::SUPERVISOR_ENV.to_string(),
            std::process::id().to_string(),
        ),
        (
            crate::driver_info::DRIVER_INFO_ENV.to_string(),
            crate::driver_info::path_beside(resolved)
                .display()
                .to_string(),
        ),
    ]
}

/// An external driver's command line with `{instance}`, `{config}`, `{rate_hz}`,
/// `{run_dir}` and `{driver_info}` substituted.
pub fn driver_argv(
    command: &[String],
    cfg: &PipelineConfig,
    resolved: &Path,
    run_dir: &Path,
) -> Vec<String> {
    command
        .iter()
        .map(|a| {
            a.replace("{instance}", &cfg.instance)
                .replace("{config}", &resolved.display().to_string())
                .replace("{rate_hz}", &cfg.rate_hz.to_string())
                .replace("{run_dir}", &run_dir.display().to_string())
                .replace(
                    "{driver_info}",
                    &crate::driver_info::path_beside(resolved)
                        .display()
                        .to_string(),
                )
        })
        .collect()
}

/// The launch of `role`: its service binary (`microrobot-<role> --config <resolved>`)
/// or the configured external actuator command ([`driver_argv`]; [`service_env`]
/// either way).
fn launch_for(
    role: ServiceRole,
    binaries: &ServiceBinaries,
    cfg: &PipelineConfig,
    resolved: &Path,
    run_dir: &Path,
) -> Launch {
    let command = microrobot_actuator::ActuatorConfig::from_pipeline(cfg)
        .ok()
        .and_then(|a| a.command);
    let argv = match (&command, role) {
        (Some(cmd), ServiceRole::Actuator) => driver_argv(cmd, cfg, resolved, run_dir),
        _ => vec![
            binaries.path(role).display().to_string(),
            "--config".to_string(),
            resolved.display().to_string(),
        ],
    };
    Launch {
        role: role_name(role),
        argv,
        env: service_env(cfg, resolved),
        log: run_dir.join(format!("{}.log", role.name())),
    }
}

/// Progress output: an indicatif line on a terminal, plain lines every few seconds otherwise.
pub struct Progress {
    bar: Option<indicatif::ProgressBar>,
    last_plain: Instant,
    quiet: bool,
    /// Each role's problem counters at the start of the current interval.
    window: Window,
}

/// Problem counters per role at one moment (misses, lost, refused, stale, faults).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
struct Counts([[u64; 5]; 3]);

impl Counts {
    fn of(monitor: &StatusMonitor) -> Self {
        let mut c = Counts::default();
        for role in ROLES {
            if let Some(st) = monitor.get(role) {
                c.0[slot(role)] = [
                    st.deadline_misses,
                    st.lost_messages,
                    st.refused_messages,
                    st.stale_cycles,
                    st.faults,
                ];
            }
        }
        c
    }
}

/// The counters at the start of the interval the progress line reports on (the plain
/// line's 3 s, or the last few seconds on a terminal).
#[derive(Debug, Clone, Copy)]
struct Window {
    since: Instant,
    base: Counts,
}

impl Progress {
    fn new(quiet: bool) -> Self {
        let bar = (!quiet && std::io::stderr().is_terminal()).then(|| {
            let bar = indicatif::ProgressBar::new_spinner();
            bar.enable_steady_tick(Duration::from_millis(200));
            bar
        });
        Self {
            bar,
            last_plain: Instant::now(),
            quiet,
            window: Window {
                since: Instant::now(),
                base: Counts::default(),
            },
        }
    }

    fn note(&self, msg: &str) {
        if self.quiet {
            return;
        }
        self.warn(msg);
    }

    /// [`Self::note`], also when quiet.
    fn warn(&self, msg: &str) {
        match &self.bar {
            Some(bar) => bar.println(msg),
            None => eprintln!("{msg}"),
        }
    }

    fn update(&mut self, monitor: &StatusMonitor, start: Instant, extra: &str) {
        if self.quiet {
            return;
        }
        let now = Counts::of(monitor);
        let line = progress_line(monitor, start, &self.window, &now) + extra;
        match &self.bar {
            Some(bar) => {
                bar.set_message(line);
                if self.window.since.elapsed() >= Duration::from_secs(3) {
                    self.window = Window {
                        since: Instant::now(),
                        base: now,
                    };
                }
            }
            None => {
                if self.last_plain.elapsed() >= Duration::from_secs(3) {
                    self.last_plain = Instant::now();
                    eprintln!("{line}");
                    self.window = Window {
                        since: Instant::now(),
                        base: now,
                    };
                }
            }
        }
    }

    fn finish(&self) {
        if let Some(bar) = &self.bar {
            bar.finish_and_clear();
        }
    }
}

/// The progress line: program time, each service's rate with what went wrong in the
/// current interval (`+N misses` …, or `FAULT`), the end-to-end p99, and the totals.
fn progress_line(monitor: &StatusMonitor, start: Instant, window: &Window, now: &Counts) -> String {
    let mut s = format!("[{:6.1} s]", start.elapsed().as_secs_f64());
    if let Some(p) = monitor.get(ServiceRole::Planner) {
        let activity = Activity::from_wire(p.activity).map_or("?", Activity::name);
        s.push_str(&format!(" {activity} t={:.2} s", p.motion_time_s));
        if p.program_done == 1 {
            s.push_str(" (done)");
        }
    }
    const NAMES: [&str; 5] = ["misses", "lost", "refused", "stale", "faults"];
    for role in [
        ServiceRole::Planner,
        ServiceRole::Dynamics,
        ServiceRole::Actuator,
    ] {
        match monitor.get(role) {
            Some(st) => {
                let rate = monitor
                    .rate(role)
                    .map(|r| format!("{r:.0}/s"))
                    .unwrap_or_else(|| "-".into());
                let i = slot(role);
                let mut health = String::new();
                if st.lifecycle == LifecycleState::Fault as u32 {
                    health.push_str(" FAULT");
                }
                for (k, name) in NAMES.iter().enumerate() {
                    let d = now.0[i][k].saturating_sub(window.base.0[i][k]);
                    if d > 0 {
                        health.push_str(&format!(" +{d} {name}"));
                    }
                }
                s.push_str(&format!(" | {} {rate}{health}", role.name()));
            }
            None => s.push_str(&format!(" | {} -", role.name())),
        }
    }
    if let Some(a) = monitor.get(ServiceRole::Actuator) {
        s.push_str(&format!(
            " | e2e p99 {:.0} µs",
            a.latency.p99_ns as f64 / 1000.0
        ));
    }
    let misses = monitor
        .get(ServiceRole::Planner)
        .map_or(0, |p| p.deadline_misses);
    let lost: u64 = ROLES
        .iter()
        .filter_map(|r| monitor.get(*r))
        .map(|s| s.lost_messages)
        .sum();
    s.push_str(&format!(
        " | total misses {misses} lost {lost} (+N: in the last {:.0} s)",
        window.since.elapsed().as_secs_f64().max(1.0)
    ));
    s
}

/// Whether the run's program is over: finished or abandoned with the arm at rest
/// (`program_done`), or abandoned or not run while the actuator holds the arm in its
/// latched safe state (the planner then follows the arm and `program_done` never comes).
fn program_over(planner: &ServiceStatus, actuator: Option<&ServiceStatus>) -> bool {
    let ended = matches!(
        ProgramState::from_wire(planner.program_state),
        Some(ProgramState::Abandoned | ProgramState::NotRun)
    );
    planner.program_done == 1
        || (ended && actuator.is_some_and(|a| a.lifecycle == LifecycleState::Fault as u32))
}

/// Takes the waiting statuses and warns once of each origin refused for a role (a
/// status not from the process started for it: see [`crate::monitor`]).
fn poll_statuses(monitor: &mut StatusMonitor, progress: &Progress) {
    let _ = monitor.poll();
    for r in monitor.take_refused() {
        progress.warn(&format!("warning: {r}"));
    }
}

fn is_ready(monitor: &StatusMonitor, role: ServiceRole) -> bool {
    monitor.get(role).is_some_and(|s| s.ready == 1)
}

/// Exit code of a service that failed: its own if it says bad config / instance in use.
fn failure_code(status: std::process::ExitStatus) -> u8 {
    match status.code() {
        Some(c) if c == exit_code::BAD_CONFIG as i32 => exit_code::BAD_CONFIG,
        Some(c) if c == exit_code::INSTANCE_IN_USE as i32 => exit_code::INSTANCE_IN_USE,
        _ => exit_code::SERVICE_FAILED,
    }
}

/// Runs the pipeline of `args` with `hooks`; the exit code (one of [`exit_code`]) and
/// the summary.
pub fn supervise_with(args: &RunArgs, hooks: &mut dyn Hooks) -> Result<(u8, Summary), Failure> {
    iceoryx2::prelude::set_log_level_from_env_or(iceoryx2::prelude::LogLevel::Error);
    let cfg = resolve_config(args)
        .map_err(|e| e.context("bad config"))
        .map_err(fail(exit_code::BAD_CONFIG))?;
    let robot = Robot::from_file(&cfg.robot)
        .map_err(|e| anyhow::anyhow!("bad config: robot: {e}"))
        .map_err(fail(exit_code::BAD_CONFIG))?;
    let dof = robot.dof();
    let instance_name = cfg.instance.clone();
    // Everything `microrobot check` checks, before anything starts.
    let findings = crate::check::check_pipeline(&cfg);
    for w in &findings.warnings {
        eprintln!("warning: {w}");
    }
    if !findings.errors.is_empty() {
        return Err(Failure {
            code: exit_code::BAD_CONFIG,
            error: anyhow::anyhow!(
                "refused before start (`microrobot check` shows the same):\n  {}",
                findings.errors.join("\n  ")
            ),
        });
    }

    // The service binaries of this build (built first under `cargo run`), before anything
    // starts.
    let binaries = ServiceBinaries::locate().map_err(fail(exit_code::FAILURE))?;

    // One pipeline per instance: the lock refuses a second supervisor, the node scan a
    // pipeline whose supervisor is gone but whose services still run.
    let _lock = instance::lock_instance(&instance_name).map_err(|e| {
        let code = if e.downcast_ref::<InstanceInUse>().is_some() {
            exit_code::INSTANCE_IN_USE
        } else {
            exit_code::FAILURE
        };
        Failure { code, error: e }
    })?;
    let live = instance::live_nodes(&instance_name);
    if let Some((name, pid)) = live.first() {
        return Err(Failure {
            code: exit_code::INSTANCE_IN_USE,
            error: InstanceInUse {
                instance: instance_name.clone(),
                detail: format!("a live process (pid {pid}, node `{name}`) runs it"),
            }
            .into(),
        });
    }
    let cleaned = instance::clean_leftovers(&instance_name);

    let run_dir = instance::run_dir(&instance_name).map_err(fail(exit_code::FAILURE))?;
    let resolved = run_dir.join("pipeline.resolved.toml");
    instance::write_private(&resolved, cfg.to_toml_string().as_bytes())
        .map_err(fail(exit_code::FAILURE))?;
    crate::driver_info::write(&cfg, &robot, &resolved).map_err(fail(exit_code::FAILURE))?;

    let stop_flag = Arc::new(AtomicBool::new(false));
    {
        let flag = stop_flag.clone();
        ctrlc::set_handler(move || flag.store(true, Ordering::SeqCst))
            .context("cannot install the Ctrl-C handler")
            .map_err(fail(exit_code::FAILURE))?;
    }

    let mut progress = Progress::new(args.quiet);
    if cleaned.dead_nodes > 0 || cleaned.orphaned_services > 0 {
        progress.note(&format!(
            "cleaned up after an earlier run: {} dead iceoryx2 node(s), {} orphaned service(s)",
            cleaned.dead_nodes, cleaned.orphaned_services
        ));
    }
    let mut monitor = StatusMonitor::open(
        &instance_name,
        &format!("microrobot-supervisor.{instance_name}"),
    )
    .map_err(fail(exit_code::FAILURE))?;
    // The last measured state, for a restarted actuator to resume from.
    let mut state_tap =
        StateTap::open(monitor.node(), &instance_name).map_err(fail(exit_code::FAILURE))?;
    hooks.before_start(&cfg).map_err(fail(exit_code::FAILURE))?;

    let started = Instant::now();
    let mut pipe = Pipeline {
        services: [None, None, None],
        carried: [None; 3],
        restarts: [0; 3],
        restarting: [None; 3],
    };
    let ready_timeout = Duration::from_secs_f64(cfg.supervisor.ready_timeout_ms / 1000.0);
    let grace = Duration::from_secs_f64((cfg.supervisor.stop_timeout_ms / 1000.0).max(1.0));
    let program_given = cfg.program.is_some();

    let mut recorder = match &args.record {
        Some(out) => Some(
            start_recorder(out, &instance_name, &run_dir, ready_timeout)
                .map_err(fail(exit_code::FAILURE))?,
        ),
        None => None,
    };

    let mut outcome: Option<(Stop, u8, String)> = None;
    // Why the recorder stopped before the end, if it did.
    let mut recorder_failed: Option<String> = None;
    // What the verdict needs beyond the stop: every death (restarted or not) and when the
    // actuator's safe state latched (cleared again by a reset).
    let mut deaths: Vec<String> = Vec::new();
    let mut latched_at: Option<f64> = None;
    // A service killed because it hung: what its death is reported as.
    let mut hung: [Option<String>; 3] = [None, None, None];
    let hung_after = Duration::from_secs_f64(cfg.supervisor.hung_ms / 1000.0);

    // Start in order, each after the previous one is ready.
    for role in ROLES {
        let launch = launch_for(role, &binaries, &cfg, &resolved, &run_dir);
        monitor.reset(role, monotonic_ns());
        match Service::spawn(launch) {
            Ok(s) => {
                monitor.expect(role, s.pid());
                pipe.services[slot(role)] = Some(s);
            }
            Err(e) => {
                outcome = Some((
                    Stop::ServiceFailed,
                    exit_code::SERVICE_FAILED,
                    format!("{e:#}"),
                ));
                break;
            }
        }
        let deadline = Instant::now() + ready_timeout;
        loop {
            poll_statuses(&mut monitor, &progress);
            if is_ready(&monitor, role) {
                progress.note(&format!(
                    "{} ready (pid {})",
                    role.name(),
                    pipe.service(role).map_or(0, |s| s.pid())
                ));
                break;
            }
            if stop_flag.load(Ordering::SeqCst) {
                outcome = Some((Stop::Interrupted, exit_code::OK, String::new()));
                break;
            }
            if let Some(s) = pipe.service(role)
                && let Some(st) = s.poll_exit()
            {
                outcome = Some((
                    Stop::ServiceFailed,
                    failure_code(st),
                    format!(
                        "the {} service exited before it was ready ({}); its log {}:\n{}",
                        role.name(),
                        describe(st),
                        s.launch.log.display(),
                        log_tail(&s.launch.log, 15)
                    ),
                ));
                break;
            }
            if Instant::now() >= deadline {
                let log = pipe
                    .service(role)
                    .map(|s| s.launch.log.clone())
                    .unwrap_or_default();
                outcome = Some((
                    Stop::Timeout,
                    exit_code::TIMEOUT,
                    format!(
                        "the {} service did not report ready within {:.1} s (supervisor.ready_timeout_ms); its log {}:\n{}",
                        role.name(),
                        ready_timeout.as_secs_f64(),
                        log.display(),
                        log_tail(&log, 15)
                    ),
                ));
                break;
            }
            std::thread::sleep(Duration::from_millis(10));
        }
        if outcome.is_some() {
            break;
        }
    }

    // Supervise until a stop condition.
    let run_start = Instant::now();
    while outcome.is_none() {
        poll_statuses(&mut monitor, &progress);
        state_tap.poll();
        if let Some(a) = monitor.get(ServiceRole::Actuator) {
            match LifecycleState::from_wire(a.lifecycle) {
                Some(LifecycleState::Fault) => {
                    latched_at.get_or_insert(run_start.elapsed().as_secs_f64());
                }
                Some(LifecycleState::Active | LifecycleState::Inactive) => latched_at = None,
                _ => {}
            }
        }
        progress.update(&monitor, started, &hooks.progress());
        hooks.poll(&mut Control {
            pipe: &mut pipe,
            monitor: &monitor,
            note: &progress,
        });
        if stop_flag.load(Ordering::SeqCst) {
            outcome = Some((Stop::Interrupted, exit_code::OK, String::new()));
            break;
        }
        if let Some(d) = cfg.duration_s
            && run_start.elapsed().as_secs_f64() >= d
        {
            outcome = Some((Stop::Duration, exit_code::OK, String::new()));
            break;
        }
        if program_given
            && monitor
                .get(ServiceRole::Planner)
                .is_some_and(|p| program_over(p, monitor.get(ServiceRole::Actuator)))
        {
            outcome = Some((Stop::ProgramDone, exit_code::OK, String::new()));
            break;
        }
        for role in ROLES {
            let i = slot(role);
            // A live service whose status stopped is hung: kill it, and the death below
            // applies the failure policy (reported as a hang).
            if pipe.restarting[i].is_none()
                && hung[i].is_none()
                && let Some(seen) = &monitor.latest[i]
                && seen.status.lifecycle != LifecycleState::Finalized as u32
                && let Some(why) = hang(&seen.status, seen.at.elapsed(), hung_after)
                && let Some(s) = pipe.service(role)
                && s.poll_exit().is_none()
            {
                hooks.hung(role, s.pid());
                progress.note(&format!(
                    "{} (pid {}) hung: {}; killing it",
                    role.name(),
                    s.pid(),
                    why.note(cfg.supervisor.hung_ms)
                ));
                s.signal(libc::SIGKILL);
                hung[i] = Some(why.verdict());
            }
            // A restarted service must report ready in time.
            if let Some(since) = pipe.restarting[i] {
                if is_ready(&monitor, role) {
                    pipe.restarting[i] = None;
                    progress.note(&format!("{} ready again after restart", role.name()));
                } else if since.elapsed() >= ready_timeout {
                    outcome = Some((
                        Stop::Timeout,
                        exit_code::TIMEOUT,
                        format!(
                            "the restarted {} service did not report ready within {:.1} s",
                            role.name(),
                            ready_timeout.as_secs_f64()
                        ),
                    ));
                    break;
                }
            }
            let Some(st) = pipe.service(role).and_then(|s| s.poll_exit()) else {
                continue;
            };
            let log = pipe
                .service(role)
                .map(|s| s.launch.log.clone())
                .unwrap_or_default();
            let may_restart = cfg.supervisor.on_failure == FailurePolicy::Restart
                && pipe.restarts[i] < cfg.supervisor.max_restarts;
            let how = hung[i]
                .take()
                .unwrap_or_else(|| format!("died ({})", describe(st)));
            if !may_restart {
                outcome = Some((
                    Stop::ServiceFailed,
                    exit_code::SERVICE_FAILED,
                    format!(
                        "the {} service {how}; stopping the pipeline (supervisor.on_failure = {}); its log {}:\n{}",
                        role.name(),
                        if cfg.supervisor.on_failure == FailurePolicy::Restart {
                            "restart, but max_restarts reached"
                        } else {
                            "stop_all"
                        },
                        log.display(),
                        log_tail(&log, 15)
                    ),
                ));
                break;
            }
            deaths.push(format!(
                "the {} service {how} {:.1} s into the run and was restarted",
                role.name(),
                run_start.elapsed().as_secs_f64()
            ));
            pipe.carry(role, &monitor);
            pipe.restarts[i] += 1;
            progress.note(&format!(
                "{} died ({}); restarting it ({}/{})",
                role.name(),
                describe(st),
                pipe.restarts[i],
                cfg.supervisor.max_restarts
            ));
            if role == ServiceRole::Actuator {
                // Every state the dead actuator published, before its memory is cleaned.
                state_tap.poll();
            }
            // The dead process's iceoryx2 resources go before the new one opens its ports.
            instance::clean_leftovers(&instance_name);
            let mut launch = match pipe.services[i].take() {
                Some(s) => s.launch,
                None => continue,
            };
            if role == ServiceRole::Actuator {
                // The arm resumes where the dead actuator last measured it.
                launch
                    .env
                    .retain(|(k, _)| k != microrobot_actuator::RESUME_ENV);
                if let Some(kv) = state_tap.resume_env() {
                    launch.env.push(kv);
                }
            }
            hooks.restarting(
                role,
                (role == ServiceRole::Actuator)
                    .then(|| state_tap.latest())
                    .flatten(),
            );
            monitor.reset(role, monotonic_ns());
            match Service::spawn(launch) {
                Ok(s) => {
                    monitor.expect(role, s.pid());
                    pipe.services[i] = Some(s);
                    pipe.restarting[i] = Some(Instant::now());
                }
                Err(e) => {
                    outcome = Some((
                        Stop::ServiceFailed,
                        exit_code::SERVICE_FAILED,
                        format!("{e:#}"),
                    ));
                    break;
                }
            }
        }
        // A recorder that stops mid-run (a full disk, a write error) is said at once; the
        // pipeline keeps running, and the verdict names it at the end.
        if recorder_failed.is_none()
            && let Some(r) = recorder.as_mut()
            && let Some(st) = r.poll_exit()
        {
            let msg = format!(
                "the recorder stopped {:.1} s into the run ({}): {}",
                started.elapsed().as_secs_f64(),
                describe(st),
                log_tail(&r.launch.log, 2).replace('\n', " | ")
            );
            progress.note(&format!("error: {msg}; the pipeline keeps running"));
            recorder_failed = Some(msg);
        }
        if outcome.is_none() {
            std::thread::sleep(Duration::from_millis(20));
        }
    }

    let (stop, mut code, message) =
        outcome.unwrap_or((Stop::Interrupted, exit_code::OK, String::new()));
    let all_clean = pipe.stop_all(&mut monitor, grace);
    let recorded = recorder.as_mut().is_none_or(|r| stop_recorder(r, grace));
    progress.finish();
    for r in monitor.take_refused() {
        eprintln!("warning: {r}");
    }
    if let Some(msg) = &recorder_failed {
        eprintln!("error: {msg}");
    } else if !recorded {
        eprintln!(
            "error: the recorder did not finish its file cleanly (see its log in {})",
            run_dir.display()
        );
    }
    if !message.is_empty() {
        eprintln!("error: {message}");
    }
    let mut exits = [String::new(), String::new(), String::new()];
    for role in ROLES {
        let i = slot(role);
        exits[i] = match pipe.services[i].as_mut().and_then(|s| s.poll_exit()) {
            Some(st) => describe(st),
            None => "not started".to_string(),
        };
    }
    let mut failures: Vec<String> = Vec::new();
    if !message.is_empty() {
        failures.push(first_line(&message));
    }
    if code == exit_code::OK && !recorded {
        code = exit_code::FAILURE;
        failures.push(
            recorder_failed
                .clone()
                .unwrap_or_else(|| "the recorder did not finish its file cleanly".into()),
        );
    }
    if code == exit_code::OK && !all_clean {
        let msg = format!("not every service exited cleanly ({})", exits.join(", "));
        eprintln!("error: {msg}");
        failures.push(msg);
        code = exit_code::SERVICE_FAILED;
    }
    let planner_log = run_dir.join("planner.log");
    let verdict = judge(&Judged {
        stop,
        program_given,
        planner: monitor.get(ServiceRole::Planner),
        deaths: &deaths,
        latched_at_s: latched_at,
        faults_judged_elsewhere: hooks.judges_faults(),
        planner_log: &planner_log,
    });
    for (c, why) in verdict {
        eprintln!("error: {why}");
        if code == exit_code::OK {
            code = c;
        }
        failures.push(why);
    }
    // Without final statuses the figures are partial: say so.
    for role in ROLES {
        if pipe.services[slot(role)].is_some()
            && monitor
                .get(role)
                .is_some_and(|s| s.lifecycle != LifecycleState::Finalized as u32)
            && code == exit_code::OK
        {
            eprintln!(
                "warning: no final status from {} (last lifecycle {}); its figures may be a little short",
                role.name(),
                monitor
                    .get(role)
                    .map_or("none", |s| lifecycle_name(s.lifecycle))
            );
        }
    }
    let mut totals: [Option<ServiceStatus>; 3] = pipe.carried;
    for role in ROLES {
        let i = slot(role);
        if let Some(st) = monitor.get(role) {
            fold(totals[i].get_or_insert_with(ServiceStatus::default), st);
        }
    }
    let program = program_given.then(|| {
        let p = monitor
            .get(ServiceRole::Planner)
            .copied()
            .unwrap_or_default();
        ProgramSummary::from_status(&p)
    });
    let summary = Summary::build(
        RunFacts {
            instance: instance_name.clone(),
            exit_code: code,
            failures,
            program,
            stop_reason: stop.name().to_string(),
            rate_hz: cfg.rate_hz,
            lockstep: cfg.lockstep,
            feedback: microrobot_dynamics::DynamicsConfig::from_pipeline(&cfg)
                .is_ok_and(|d| d.feedback),
            wall_time_s: started.elapsed().as_secs_f64(),
            dof,
            joints: robot
                .joints()
                .iter()
                .map(|j| {
                    (
                        j.name.clone(),
                        j.kind == microrobot_model::JointKind::Prismatic,
                    )
                })
                .collect(),
            run_dir: run_dir.display().to_string(),
        },
        &totals,
        &pipe.restarts,
        &exits,
    );
    // Our own node goes first, then whatever the services left (nothing, normally).
    drop(state_tap);
    drop(monitor);
    instance::clean_leftovers(&instance_name);
    Ok((code, summary))
}

/// What [`judge`] looks at once the pipeline has stopped.
struct Judged<'a> {
    stop: Stop,
    program_given: bool,
    /// The planner's last status (its final one after a clean stop).
    planner: Option<&'a ServiceStatus>,
    /// Every service death the restart policy recovered from.
    deaths: &'a [String],
    /// Seconds into the run at which the actuator's safe state latched, if it was still
    /// latched at the stop.
    latched_at_s: Option<f64>,
    /// The soak injects faults on purpose and judges them itself.
    faults_judged_elsewhere: bool,
    planner_log: &'a Path,
}

/// The run's verdict beyond the stop itself: each reason the job asked for did not
/// happen, with its exit code (one of [`exit_code`]). Empty: the job ran to its end.
fn judge(j: &Judged<'_>) -> Vec<(u8, String)> {
    let mut out = Vec::new();
    // A death first: it is the cause of what follows it.
    if !j.faults_judged_elsewhere {
        for d in j.deaths {
            out.push((exit_code::SERVICE_FAILED, d.clone()));
        }
        if let Some(t) = j.latched_at_s {
            out.push((
                exit_code::JOB_FAILED,
                format!(
                    "the actuator's safe state latched {t:.1} s into the run and was not reset by the end"
                ),
            ));
        }
    }
    if j.program_given && j.stop != Stop::ServiceFailed && j.stop != Stop::Timeout {
        let p = j.planner.copied().unwrap_or_default();
        let state = ProgramState::from_wire(p.program_state).unwrap_or(ProgramState::None);
        let end = ProgramEnd::from_wire(p.program_end).unwrap_or(ProgramEnd::None);
        let detail = || {
            let lines = log_lines_with(j.planner_log, "planner: program", 2);
            if lines.is_empty() {
                String::new()
            } else {
                format!(" (planner log: {})", lines.join(" | "))
            }
        };
        match (state, j.stop) {
            (ProgramState::Finished, _) => {}
            (ProgramState::Abandoned, _) => out.push((
                exit_code::JOB_FAILED,
                format!(
                    "the program was abandoned at program time {:.3} s: {}{}",
                    p.motion_time_s,
                    end.describe(),
                    detail()
                ),
            )),
            (ProgramState::NotRun, _) => out.push((
                exit_code::JOB_FAILED,
                format!("the program was not run: {}{}", end.describe(), detail()),
            )),
            // `--duration` bounds the job: a program still running then is not a failure.
            (_, Stop::Duration) => {}
            (_, Stop::Interrupted) => out.push((
                exit_code::INTERRUPTED,
                format!(
                    "interrupted before the program finished (program {} at {:.3} s)",
                    state.name(),
                    p.motion_time_s
                ),
            )),
            (_, _) => out.push((
                exit_code::JOB_FAILED,
                format!(
                    "the run stopped ({}) but the planner reports its program {}",
                    j.stop.name(),
                    state.name()
                ),
            )),
        }
    }
    out
}

/// The last `n` lines of `log` that contain `needle`, trimmed of their timestamp prefix.
fn log_lines_with(log: &Path, needle: &str, n: usize) -> Vec<String> {
    let Ok(text) = std::fs::read_to_string(log) else {
        return Vec::new();
    };
    let mut lines: Vec<String> = text
        .lines()
        .filter_map(|l| l.find(needle).map(|i| l[i..].trim().to_string()))
        .collect();
    let keep = lines.len().saturating_sub(n);
    lines.drain(..keep);
    lines
}

/// The first line of a (possibly multi-line) message.
fn first_line(msg: &str) -> String {
    msg.lines().next().unwrap_or_default().to_string()
}

/// Starts `microrobot record` for the instance and waits until all its subscribers are
/// open (it creates its ready file then), so it sees the pipeline's first message.
fn start_recorder(
    out: &Path,
    instance: &str,
    run_dir: &Path,
    timeout: Duration,
) -> anyhow::Result<Service> {
    let exe = std::env::current_exe().context("cannot find the microrobot executable")?;
    let ready = run_dir.join("recorder.ready");
    let _ = std::fs::remove_file(&ready);
    let launch = Launch {
        role: "recorder",
        argv: vec![
            exe.display().to_string(),
            "record".into(),
            "--instance".into(),
            instance.into(),
            "--out".into(),
            out.display().to_string(),
            "--ready-file".into(),
            ready.display().to_string(),
        ],
        env: Vec::new(),
        log: run_dir.join("recorder.log"),
    };
    let log = launch.log.clone();
    let mut recorder = Service::spawn(launch)?;
    let deadline = Instant::now() + timeout;
    while !ready.exists() {
        if let Some(st) = recorder.poll_exit() {
            anyhow::bail!(
                "the recorder exited at start ({}): {}",
                describe(st),
                log_tail(&log, 5)
            );
        }
        if Instant::now() > deadline {
            recorder.kill_and_reap();
            anyhow::bail!("the recorder was not ready within {timeout:?}");
        }
        std::thread::sleep(Duration::from_millis(10));
    }
    Ok(recorder)
}

/// Asks the recorder to finish its file (SIGINT) and waits for it; true if it exited 0.
fn stop_recorder(recorder: &mut Service, grace: Duration) -> bool {
    recorder.signal(libc::SIGINT);
    let deadline = Instant::now() + grace;
    loop {
        if let Some(st) = recorder.poll_exit() {
            return st.success();
        }
        if Instant::now() > deadline {
            recorder.kill_and_reap();
            return false;
        }
        std::thread::sleep(Duration::from_millis(10));
    }
}

/// Why a live service is taken for hung ([`hang`]).
#[derive(Debug, Clone, Copy, PartialEq)]
enum Hang {
    /// No status for `silent_ms`, beyond `supervisor.hung_ms`.
    Silent { silent_ms: f64 },
    /// Its last status said it entered lifecycle hook `hook`, allowed to block for
    /// `budget_ms`; silent for `silent_ms` since, beyond that budget.
    InHook {
        hook: LifecycleHook,
        budget_ms: u32,
        silent_ms: f64,
    },
}

impl Hang {
    /// The progress line's reason (after "hung: ").
    fn note(self, hung_ms: f64) -> String {
        match self {
            Self::Silent { silent_ms } => {
                format!("no status for {silent_ms:.0} ms (supervisor.hung_ms = {hung_ms})")
            }
            Self::InHook {
                hook,
                budget_ms,
                silent_ms,
            } => format!(
                "inside its {} hook for {silent_ms:.0} ms, beyond the hook's budget of {budget_ms} ms (actuator.hook_budget_ms)",
                hook.name()
            ),
        }
    }

    /// What its death is reported as in the verdict.
    fn verdict(self) -> String {
        match self {
            Self::Silent { silent_ms } => {
                format!("hung (its process lived but sent no status for {silent_ms:.0} ms; killed)")
            }
            Self::InHook {
                hook,
                budget_ms,
                silent_ms,
            } => format!(
                "hung (its process lived but stayed inside its {} hook for {silent_ms:.0} ms, beyond the hook's budget of {budget_ms} ms (actuator.hook_budget_ms); killed)",
                hook.name()
            ),
        }
    }
}

/// Whether a live service whose last status is `last`, silent for `silent` since, is
/// hung: silent for `hung_after` (`supervisor.hung_ms`), or, while `last` says it is
/// inside a lifecycle hook, for longer than the hook's declared budget (if that is
/// longer: a hook that brings a bus up again blocks the cycle, and so its status).
fn hang(last: &ServiceStatus, silent: Duration, hung_after: Duration) -> Option<Hang> {
    let silent_ms = silent.as_secs_f64() * 1e3;
    let hook = LifecycleHook::from_wire(last.hook).unwrap_or(LifecycleHook::None);
    let budget = Duration::from_millis(u64::from(last.hook_budget_ms));
    if hook != LifecycleHook::None && budget > hung_after {
        return (silent > budget).then_some(Hang::InHook {
            hook,
            budget_ms: last.hook_budget_ms,
            silent_ms,
        });
    }
    (silent >= hung_after).then_some(Hang::Silent { silent_ms })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn planner(state: ProgramState, end: ProgramEnd) -> ServiceStatus {
        ServiceStatus {
            role: ServiceRole::Planner as u32,
            program_state: state as u32,
            program_end: end as u32,
            motion_time_s: 1.5,
            ..Default::default()
        }
    }

    fn judged(
        stop: Stop,
        program: Option<ServiceStatus>,
        deaths: &[String],
        latched_at_s: Option<f64>,
        elsewhere: bool,
    ) -> Vec<u8> {
        judge(&Judged {
            stop,
            program_given: program.is_some(),
            planner: program.as_ref(),
            deaths,
            latched_at_s,
            faults_judged_elsewhere: elsewhere,
            planner_log: Path::new("/nonexistent/planner.log"),
        })
        .into_iter()
        .map(|(code, why)| {
            assert!(!why.is_empty());
            code
        })
        .collect()
    }

    #[test]
    fn a_hook_is_given_its_budget_and_caught_as_hung_beyond_it() {
        let ms = Duration::from_millis;
        let hung_after = ms(500);
        let plain = ServiceStatus {
            role: ServiceRole::Actuator as u32,
            ..Default::default()
        };
        assert_eq!(hang(&plain, ms(499), hung_after), None);
        assert!(matches!(
            hang(&plain, ms(500), hung_after),
            Some(Hang::Silent { .. })
        ));
        let in_reset = ServiceStatus {
            hook: LifecycleHook::Reset as u32,
            hook_budget_ms: 3000,
            ..plain
        };
        // A reset that brings a bus up again is no hang within its budget...
        assert_eq!(hang(&in_reset, ms(600), hung_after), None);
        assert_eq!(hang(&in_reset, ms(3000), hung_after), None);
        // ... and is one beyond it, named with its hook and budget.
        let h = hang(&in_reset, ms(3001), hung_after).expect("hung");
        assert_eq!(
            h,
            Hang::InHook {
                hook: LifecycleHook::Reset,
                budget_ms: 3000,
                silent_ms: 3001.0
            }
        );
        let v = h.verdict();
        assert!(v.contains("on_reset") && v.contains("3000 ms"), "{v}");
        assert!(h.note(500.0).contains("actuator.hook_budget_ms"));
        // A budget shorter than hung_ms never makes the check stricter.
        let short = ServiceStatus {
            hook: LifecycleHook::Activate as u32,
            hook_budget_ms: 100,
            ..plain
        };
        assert_eq!(hang(&short, ms(400), hung_after), None);
        assert!(matches!(
            hang(&short, ms(500), hung_after),
            Some(Hang::Silent { .. })
        ));
        // An unknown hook value is no hook.
        let unknown = ServiceStatus {
            hook: 99,
            hook_budget_ms: 3000,
            ..plain
        };
        assert!(hang(&unknown, ms(500), hung_after).is_some());
    }

    #[test]
    fn a_forged_status_neither_refreshes_liveness_nor_extends_the_hang_budget() {
        use microrobot_messages::{ServiceKind, open_publish_subscribe};
        let me = std::process::id();
        let instance = format!("status-origin-test-{me}");
        let mut monitor = StatusMonitor::open(&instance, &format!("microrobot-test.{instance}"))
            .expect("monitor");
        let node =
            microrobot_runtime::node::named_node(&format!("forger.{instance}")).expect("node");
        let publisher =
            open_publish_subscribe::<ServiceStatus>(&node, &instance, ServiceKind::Status)
                .expect("status service")
                .publisher_builder()
                .create()
                .expect("publisher");
        let mut seq = 0;
        let mut send = |pid: u32, hook: LifecycleHook, budget_ms: u32| {
            seq += 1;
            let st = ServiceStatus {
                seq,
                stamp_ns: monotonic_ns(),
                role: ServiceRole::Actuator as u32,
                lifecycle: LifecycleState::Active as u32,
                pid,
                ready: 1,
                hook: hook as u32,
                hook_budget_ms: budget_ms,
                ..Default::default()
            };
            publisher.send_copy(st).expect("send");
        };
        let hung_after = Duration::from_millis(500);
        let at = |m: &StatusMonitor| m.latest[slot(ServiceRole::Actuator)].map(|s| s.at);

        // This process stands for the actuator the supervisor started: its status counts.
        monitor.expect(ServiceRole::Actuator, me);
        send(me, LifecycleHook::None, 0);
        assert_eq!(monitor.poll().expect("poll"), 1);
        let alive_at = at(&monitor).expect("a status");
        assert!(monitor.take_refused().is_empty());

        // Another pid's status announcing a 600 s hook: dropped, reported once.
        let other = me.wrapping_add(1);
        send(other, LifecycleHook::Reset, 600_000);
        send(other, LifecycleHook::Reset, 600_000);
        assert_eq!(monitor.poll().expect("poll"), 0);
        assert_eq!(at(&monitor), Some(alive_at), "liveness not refreshed");
        let last = monitor.get(ServiceRole::Actuator).expect("a status");
        assert_eq!(last.pid, me);
        assert!(
            matches!(
                hang(last, hung_after, hung_after),
                Some(Hang::Silent { .. })
            ),
            "the hang allowance stays supervisor.hung_ms"
        );
        let refused = monitor.take_refused();
        assert_eq!(
            refused,
            [crate::monitor::Refused {
                role: ServiceRole::Actuator,
                claimed_pid: other,
                publisher_pid: Some(me as i32),
                expected_pid: me,
            }]
        );
        let line = refused[0].to_string();
        assert!(
            line.contains("actuator")
                && line.contains(&format!("claim pid {other}"))
                && line.contains(&format!("is pid {me}")),
            "{line}"
        );

        // The process's own statuses still count.
        send(me, LifecycleHook::None, 0);
        assert_eq!(monitor.poll().expect("poll"), 1);
        assert!(at(&monitor) > Some(alive_at));

        // A status claiming the started process's pid from a publisher of another
        // process (here: this one, while a child stands for the actuator) is dropped too.
        let mut child = std::process::Command::new("sleep")
            .arg("30")
            .spawn()
            .expect("spawn sleep");
        let child_pid = child.id();
        monitor.expect(ServiceRole::Actuator, child_pid);
        let before = at(&monitor);
        send(child_pid, LifecycleHook::Reset, 600_000);
        let polled = monitor.poll().expect("poll");
        let _ = child.kill();
        let _ = child.wait();
        assert_eq!(polled, 0);
        assert_eq!(at(&monitor), before);
        assert_eq!(
            monitor.get(ServiceRole::Actuator).map(|s| s.hook),
            Some(LifecycleHook::None as u32)
        );
        assert_eq!(
            monitor.take_refused(),
            [crate::monitor::Refused {
                role: ServiceRole::Actuator,
                claimed_pid: child_pid,
                publisher_pid: Some(me as i32),
                expected_pid: child_pid,
            }]
        );
    }

    #[test]
    fn a_finished_program_or_a_plain_hold_passes() {
        let done = planner(ProgramState::Finished, ProgramEnd::None);
        assert!(judged(Stop::ProgramDone, Some(done), &[], None, false).is_empty());
        assert!(judged(Stop::Duration, None, &[], None, false).is_empty());
        assert!(judged(Stop::Interrupted, None, &[], None, false).is_empty());
    }

    #[test]
    fn a_program_that_did_not_run_to_its_end_fails() {
        let abandoned = planner(ProgramState::Abandoned, ProgramEnd::StaleState);
        let not_run = planner(ProgramState::NotRun, ProgramEnd::CannotPlan);
        let running = planner(ProgramState::Running, ProgramEnd::None);
        let code = exit_code::JOB_FAILED;
        assert_eq!(
            judged(Stop::ProgramDone, Some(abandoned), &[], None, false),
            [code]
        );
        assert_eq!(
            judged(Stop::ProgramDone, Some(not_run), &[], None, false),
            [code]
        );
        // `--duration` bounds the job; Ctrl-C cuts it short.
        assert!(judged(Stop::Duration, Some(running), &[], None, false).is_empty());
        assert_eq!(
            judged(Stop::Interrupted, Some(running), &[], None, false),
            [exit_code::INTERRUPTED]
        );
    }

    #[test]
    fn deaths_and_latches_fail_the_run_unless_judged_elsewhere() {
        let death = ["the dynamics service died (killed by signal 9)".to_string()];
        let abandoned = planner(ProgramState::Abandoned, ProgramEnd::SafeState);
        assert_eq!(
            judged(Stop::ProgramDone, Some(abandoned), &death, Some(2.0), false),
            [
                exit_code::SERVICE_FAILED,
                exit_code::JOB_FAILED,
                exit_code::JOB_FAILED
            ],
            "the death first, then the latch, then the program"
        );
        assert!(judged(Stop::Duration, None, &death, Some(2.0), true).is_empty());
    }

    #[test]
    fn a_program_is_over_when_done_or_ended_under_a_latched_actuator() {
        let mut p = planner(ProgramState::Abandoned, ProgramEnd::SafeState);
        let latched = ServiceStatus {
            lifecycle: LifecycleState::Fault as u32,
            ..Default::default()
        };
        let active = ServiceStatus {
            lifecycle: LifecycleState::Active as u32,
            ..Default::default()
        };
        assert!(program_over(&p, Some(&latched)));
        assert!(!program_over(&p, Some(&active)), "still braking");
        p.program_done = 1;
        assert!(program_over(&p, Some(&active)));
        let running = planner(ProgramState::Running, ProgramEnd::None);
        assert!(!program_over(&running, Some(&latched)));
    }
}
