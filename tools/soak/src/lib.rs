//! The long runs and measurements of the live stack: `microrobot soak` (below) and
//! `microrobot probe-chain` ([`probe_chain`], the machine's floor for the pipeline's
//! latency and CPU).
//!
//! `microrobot soak`: runs the real pipeline (the supervisor of `microrobot run`, with
//! the restart policy) for minutes to hours, keeps the arm moving, optionally injects
//! faults (kill -9 of a service in turn, random motion commands, CPU load), watches the
//! streams online ([`observer`]), measures the bare timer floor alongside, and writes
//! `report.json` and `report.md` ([`report`]). The exit code is non-zero when the
//! verdict fails: an unrecovered fault, a jump, lost messages outside the kill windows,
//! a safe-state latch without an injected fault, or a pipeline that did not end cleanly.

pub mod inject;
pub mod observer;
pub mod probe_chain;
pub mod report;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use anyhow::Context as _;
use microrobot_actuator::ActuatorConfig;
use microrobot_messages::{LifecycleState, ServiceRole, monotonic_ns};
use microrobot_model::Robot;
use microrobot_runtime::config::{FailurePolicy, OwnedSection as _, RealtimeConfig};
use microrobot_runtime::exit_code;
use microrobot_runtime::timer::{FloorReport, floor_probe_windows};

use inject::{CommandPort, CpuLoad, Rng, Targets};
use microrobot_bus_tools::invariants::{self, Bounds};
use microrobot_supervisor::run::{self, Control, Hooks, RunArgs};
use microrobot_supervisor::summary::Percentiles;
use observer::Observer;
use report::{Facts, Floor, Kill, Report};

/// Options of `microrobot soak`.
#[derive(Debug, Clone, clap::Args)]
pub struct SoakArgs {
    /// Pipeline config (its program is replaced by the soak's own motion commands).
    #[arg(long, default_value_os_t = microrobot_command_line::config_path::default_config())]
    pub config: PathBuf,
    /// How long: `90s`, `10m`, `1h` (a bare number is seconds).
    #[arg(long, default_value = "60s", value_parser = microrobot_command_line::duration::parse)]
    pub duration: f64,
    /// Control rate in Hz (overrides `rate_hz`).
    #[arg(long, value_name = "HZ")]
    pub rate_hz: Option<f64>,
    /// kill -9 a service every SECS seconds, in turn planner, dynamics, actuator; the
    /// supervisor restarts it.
    #[arg(long, value_name = "DURATION", value_parser = microrobot_command_line::duration::parse)]
    pub kill_every: Option<f64>,
    /// Stop a service (SIGSTOP) every SECS seconds, in turn planner, dynamics, actuator,
    /// and continue it (SIGCONT) after `--stall-for`; a stall of at least
    /// `supervisor.hung_ms` must be caught as hung (killed and restarted).
    #[arg(long, value_name = "DURATION", value_parser = microrobot_command_line::duration::parse)]
    pub stall_every: Option<f64>,
    /// How long each stall lasts.
    #[arg(long, default_value = "1s", value_name = "DURATION", value_parser = microrobot_command_line::duration::parse)]
    pub stall_for: f64,
    /// Random valid moves (replanning mid-motion) and stops, besides the motion cycle.
    #[arg(long)]
    pub random_commands: bool,
    /// Busy threads loading the CPUs meanwhile.
    #[arg(long, default_value_t = 0, value_name = "N")]
    pub cpu_load: usize,
    /// Output directory for report.json and report.md (with --render: the markdown file).
    #[arg(long, value_name = "DIR")]
    pub out: PathBuf,
    /// Instance name (default `soak-<pid>`).
    #[arg(long, value_name = "NAME")]
    pub instance: Option<String>,
    /// Seed of the random commands.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Relative tolerance of the jump thresholds (see `microrobot_bus_tools::invariants`).
    #[arg(long, default_value_t = 0.5, value_name = "TOL")]
    pub jump_tolerance: f64,
    /// No progress output.
    #[arg(long, short)]
    pub quiet: bool,
    /// Render an existing report.json as markdown into the file `--out` (e.g.
    /// docs/soak-1h.md) instead of running a soak.
    #[arg(long, value_name = "REPORT.json")]
    pub render: Option<PathBuf>,
    /// Heading of the rendered markdown.
    #[arg(long, default_value = "Soak report")]
    pub title: String,
}

/// Entry point of `microrobot soak`.
pub fn main(args: SoakArgs) -> ExitCode {
    if let Some(src) = &args.render {
        return match render(src, &args.out, &args.title) {
            Ok(()) => ExitCode::SUCCESS,
            Err(e) => {
                eprintln!("error: {e:#}");
                ExitCode::from(exit_code::FAILURE)
            }
        };
    }
    match soak(&args) {
        Ok(code) => ExitCode::from(code),
        Err(run::Failure { code, error }) => {
            eprintln!("error: {error:#}");
            ExitCode::from(code)
        }
    }
}

/// Renders `report.json` as markdown into `out`.
pub fn render(src: &Path, out: &Path, title: &str) -> anyhow::Result<()> {
    let text =
        std::fs::read_to_string(src).with_context(|| format!("cannot read {}", src.display()))?;
    let r: Report = serde_json::from_str(&text)
        .with_context(|| format!("{}: not a soak report", src.display()))?;
    std::fs::write(out, r.markdown(title))
        .with_context(|| format!("cannot write {}", out.display()))
}

fn load_average() -> String {
    std::fs::read_to_string("/proc/loadavg")
        .map(|s| s.split_whitespace().take(3).collect::<Vec<_>>().join(" "))
        .unwrap_or_default()
}

/// UTC date and time of the wall clock now (`YYYY-MM-DD HH:MM:SS`).
fn utc_now() -> String {
    let secs = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_secs()) as i64;
    let (days, rem) = (secs.div_euclid(86400), secs.rem_euclid(86400));
    // Civil from days (H. Hinnant's algorithm).
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = doy - (153 * mp + 2) / 5 + 1;
    let m = if mp < 10 { mp + 3 } else { mp - 9 };
    let y = yoe + era * 400 + i64::from(m <= 2);
    format!(
        "{y:04}-{m:02}-{d:02} {:02}:{:02}:{:02}",
        rem / 3600,
        rem / 60 % 60,
        rem % 60
    )
}

fn bad(e: anyhow::Error) -> run::Failure {
    run::Failure {
        code: exit_code::BAD_CONFIG,
        error: e,
    }
}

fn failed(e: anyhow::Error) -> run::Failure {
    run::Failure {
        code: exit_code::FAILURE,
        error: e,
    }
}

fn soak(args: &SoakArgs) -> Result<u8, run::Failure> {
    if let Some(k) = args.kill_every
        && (!k.is_finite() || k < 2.0)
    {
        return Err(bad(anyhow::anyhow!(
            "--kill-every {k}: must be at least 2 s (a restart and its recovery take time)"
        )));
    }
    if let Some(k) = args.stall_every
        && (!k.is_finite() || k < 2.0 || k <= args.stall_for + 1.0)
    {
        return Err(bad(anyhow::anyhow!(
            "--stall-every {k}: must be at least 2 s and more than --stall-for + 1 s ({} s)",
            args.stall_for + 1.0
        )));
    }
    if !(args.stall_for.is_finite() && args.stall_for > 0.0 && args.stall_for <= 30.0) {
        return Err(bad(anyhow::anyhow!(
            "--stall-for {}: must be within (0, 30] s",
            args.stall_for
        )));
    }
    if !(args.jump_tolerance.is_finite() && (0.0..=10.0).contains(&args.jump_tolerance)) {
        return Err(bad(anyhow::anyhow!(
            "--jump-tolerance {}: must be within [0, 10]",
            args.jump_tolerance
        )));
    }
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("cannot create {}", args.out.display()))
        .map_err(failed)?;
    let config = std::fs::canonicalize(&args.config)
        .with_context(|| format!("--config {}: cannot open", args.config.display()))
        .map_err(bad)?;
    let instance = args
        .instance
        .clone()
        .unwrap_or_else(|| format!("soak-{}", std::process::id()));
    let base = RunArgs {
        config,
        duration: Some(args.duration),
        rate_hz: args.rate_hz,
        lockstep: false,
        program: None,
        no_program: true,
        instance: Some(instance),
        summary_json: None,
        no_feedback: false,
        mass_scale: None,
        quiet: args.quiet,
        record: None,
        floor_probe: false,
    };
    let mut cfg = run::resolve_config(&base).map_err(bad)?;
    // The soak restarts what it kills, as often as it kills.
    cfg.supervisor.on_failure = FailurePolicy::Restart;
    cfg.supervisor.max_restarts = 1000;
    let soak_cfg = args.out.join("pipeline.soak.toml");
    std::fs::write(&soak_cfg, cfg.to_toml_string())
        .with_context(|| format!("cannot write {}", soak_cfg.display()))
        .map_err(failed)?;
    let run_args = RunArgs {
        config: soak_cfg,
        duration: None,
        rate_hz: None,
        instance: None,
        ..base
    };
    let robot = Robot::from_file(&cfg.robot).map_err(|e| bad(anyhow::anyhow!("robot: {e}")))?;
    let sim = ActuatorConfig::from_pipeline(&cfg)
        .map_err(|e| bad(anyhow::Error::new(e)))?
        .sim;
    let bounds = Bounds::new(
        &robot,
        cfg.rate_hz,
        args.jump_tolerance,
        sim.sensor_noise_rad,
        sim.sensor_noise_rad_s,
    );
    let mut realtime = cfg.service_realtime();
    // The probe shares the pipeline's policy, affinity, PM QoS and slack; locking the
    // soak process's memory would not change a timer's wake-up.
    realtime.mlockall = false;
    let mut hooks = Soak {
        args: args.clone(),
        bounds,
        targets: Targets::new(&robot),
        rng: Rng::new(args.seed),
        realtime,
        period_ns: cfg.period_ns(),
        observer: None,
        port: None,
        load: None,
        floor: None,
        t0: None,
        t0_ns: 0,
        last_poll_ns: 0,
        kills: Vec::new(),
        rotation: 0,
        floor_epoch: Default::default(),
        next_kill_s: args.kill_every.unwrap_or(f64::INFINITY),
        next_stall_s: args.stall_every.unwrap_or(f64::INFINITY),
        stalled: None,
        pending_fault: false,
        last_command: None,
        last_reset: None,
        next_random_s: 1.0,
        commands: BTreeMap::new(),
    };
    let started_utc = utc_now();
    let load_start = load_average();
    let (code, summary) = run::supervise_with(&run_args, &mut hooks)?;
    // The run under test ends at the last poll; what the stop itself flags (every
    // service leaving Active) is not a fault's symptom. A restart quicker than the
    // watchdogs flags nothing, and the stop's edges were then taken for its detection.
    let end_ns = match hooks.last_poll_ns {
        0 => monotonic_ns(),
        t => t,
    };
    drop(hooks.load.take());
    let observed = match hooks.observer.take() {
        Some(o) => o.finish().map_err(failed)?,
        None => return Err(failed(anyhow::anyhow!("the pipeline never started"))),
    };
    let floor = hooks.floor.take().and_then(|h| {
        let end = Instant::now() + Duration::from_secs(3);
        while !h.is_finished() && Instant::now() < end {
            std::thread::sleep(Duration::from_millis(20));
        }
        if !h.is_finished() {
            return None;
        }
        match h.join() {
            Ok(Ok(f)) => Some(Floor {
                ticks: f.ticks,
                lateness_us: Percentiles::from(&f.lateness),
                deadline_misses: f.deadline_misses,
                window_p99_us: f.windows.iter().map(|w| w.p99_ns as f64 / 1000.0).collect(),
            }),
            _ => None,
        }
    });
    let mut thresholds = BTreeMap::new();
    let tol = args.jump_tolerance;
    thresholds.insert(
        "setpoint".into(),
        format!(
            "|Δq| ≤ vmax·dt·(1+{tol}) + {:e}, |Δq̇| ≤ amax·dt·(1+{tol}) + {:e}, dt = ticks × period; \
             a restarted planner's first setpoint against the measured state likewise with dt = its age + one period; \
             setpoints mirroring the held arm (HOLD_FOR_SAFE_STATE) are not judged",
            invariants::EPS_Q,
            invariants::EPS_QD
        ),
    );
    thresholds.insert(
        "torque".into(),
        format!(
            "commanded and applied: |Δτ| ≤ τmax·dt/{:.0} ms·(1+{tol}) (a full-scale change in no less than {:.0} ms; the actuator blends every switch over ramp_ms)",
            invariants::T_SLEW_S * 1e3,
            invariants::T_SLEW_S * 1e3
        ),
    );
    thresholds.insert(
        "state".into(),
        format!(
            "within one actuator process |Δq − (q̇₀+q̇₁)/2·dt| ≤ {:e}; a restarted actuator resumes its predecessor's last q and q̇ within {:e}",
            invariants::EPS_STATE,
            invariants::EPS_RESUME
        ),
    );
    let report = Report::build(
        Facts {
            command: std::env::args().collect::<Vec<_>>().join(" "),
            started_utc,
            duration_s: args.duration,
            rate_hz: cfg.rate_hz,
            kill_every_s: args.kill_every,
            random_commands: args.random_commands,
            cpu_load_threads: args.cpu_load,
            seed: args.seed,
            load_average_start: load_start,
            load_average_end: load_average(),
            thresholds,
            t0_ns: hooks.t0_ns,
            end_ns,
            kills: hooks.kills.clone(),
            stall_every_s: args.stall_every,
            stall_ms: args.stall_every.map(|_| args.stall_for * 1e3),
            hung_ms: cfg.supervisor.hung_ms,
            floor,
            commands: hooks.commands.clone(),
            exit_code: code,
        },
        observed,
        summary,
    );
    report.write(&args.out).map_err(failed)?;
    let v = &report.verdict;
    println!(
        "soak {}: {} fault(s) injected, {} recovered; {} jump(s); lost outside kill windows {}; latches without a fault {}; report in {}",
        if v.pass { "PASS" } else { "FAIL" },
        v.faults_injected,
        v.faults_recovered,
        v.jumps,
        v.lost_outside_kill_windows,
        v.latches_without_fault,
        args.out.display()
    );
    for r in &v.reasons {
        println!("  - {r}");
    }
    Ok(if code != exit_code::OK {
        code
    } else if v.pass {
        exit_code::OK
    } else {
        exit_code::JOB_FAILED
    })
}

/// Kills are not injected this close to the end (the recovery must fit in the run).
const NO_KILL_BEFORE_END_S: f64 = 15.0;
/// Resets are repeated at most this often while something holds.
const RESET_EVERY: Duration = Duration::from_millis(500);
/// The next motion command no sooner than this after the previous one.
const COMMAND_GAP: Duration = Duration::from_millis(500);

/// The soak's part of the supervision loop.
struct Soak {
    args: SoakArgs,
    bounds: Bounds,
    targets: Targets,
    rng: Rng,
    realtime: RealtimeConfig,
    period_ns: u64,
    observer: Option<Observer>,
    port: Option<CommandPort>,
    load: Option<CpuLoad>,
    floor: Option<JoinHandle<std::io::Result<FloorReport>>>,
    /// Bumped at every planner kill: the floor probe starts a new window.
    floor_epoch: std::sync::Arc<std::sync::atomic::AtomicU64>,
    t0: Option<Instant>,
    t0_ns: u64,
    /// Monotonic time of the latest supervision poll: the pipeline's orderly stop
    /// starts after the last one.
    last_poll_ns: u64,
    kills: Vec<Kill>,
    rotation: usize,
    next_kill_s: f64,
    next_stall_s: f64,
    /// The stalled service (role, pid, when to continue it).
    stalled: Option<(ServiceRole, u32, Instant)>,
    /// A kill whose recovery has not been seen yet (no further kill meanwhile).
    pending_fault: bool,
    last_command: Option<Instant>,
    last_reset: Option<Instant>,
    next_random_s: f64,
    commands: BTreeMap<String, u64>,
}

impl Soak {
    fn count(&mut self, what: &str) {
        *self.commands.entry(what.to_string()).or_default() += 1;
    }

    fn start_clock(&mut self) {
        self.t0 = Some(Instant::now());
        self.t0_ns = monotonic_ns();
        let rt = self.realtime.clone();
        let (period, duration) = (self.period_ns, (self.args.duration * 1e9) as u64);
        let epoch = self.floor_epoch.clone();
        self.floor = std::thread::Builder::new()
            .name("soak-floor".into())
            .spawn(move || {
                let _guard = microrobot_runtime::rt::apply(&rt);
                let never = std::sync::atomic::AtomicBool::new(false);
                floor_probe_windows(period, duration, rt.overrun, &never, Some(&epoch))
            })
            .ok();
        if self.args.cpu_load > 0 {
            self.load = Some(CpuLoad::start(self.args.cpu_load));
        }
    }
}

impl Hooks for Soak {
    fn judges_faults(&self) -> bool {
        true
    }

    fn before_start(&mut self, cfg: &microrobot_runtime::PipelineConfig) -> anyhow::Result<()> {
        self.observer = Some(Observer::start(&cfg.instance, self.bounds)?);
        self.port = Some(CommandPort::open(&cfg.instance)?);
        Ok(())
    }

    fn poll(&mut self, ctl: &mut Control<'_>) {
        self.last_poll_ns = monotonic_ns();
        let Some(t0) = self.t0 else {
            self.start_clock();
            return;
        };
        let now = Instant::now();
        let t = now.duration_since(t0).as_secs_f64();
        let roles = [
            ServiceRole::Planner,
            ServiceRole::Dynamics,
            ServiceRole::Actuator,
        ];
        // A stall ends on time, whatever else is going on.
        if let Some((role, pid, until)) = self.stalled
            && now >= until
        {
            ctl.resume(role, pid);
            self.stalled = None;
        }
        if self.stalled.is_some() {
            return;
        }
        if roles.iter().any(|r| ctl.restarting(*r)) {
            return;
        }
        let fault = LifecycleState::Fault as u32;
        let active = LifecycleState::Active as u32;
        let actuator = ctl.monitor.get(ServiceRole::Actuator).copied();
        let planner = ctl.monitor.get(ServiceRole::Planner).copied();
        let latched = actuator.is_some_and(|s| s.lifecycle == fault);
        let holding = planner.is_some_and(|s| s.lifecycle == fault);
        let Some(port) = self.port.as_mut() else {
            return;
        };
        // Recovery: a latched actuator (and the planner mirroring it) need a Reset.
        if latched || holding {
            if self.last_reset.is_none_or(|r| r.elapsed() >= RESET_EVERY) {
                port.reset();
                self.last_reset = Some(now);
                self.count("reset");
            }
            return;
        }
        let healthy = actuator.is_some_and(|s| s.lifecycle == active)
            && planner.is_some_and(|s| s.lifecycle == active);
        if self.pending_fault && healthy {
            self.pending_fault = false;
        }
        // Fault injection, one at a time, in turn.
        if t >= self.next_stall_s
            && !self.pending_fault
            && self.args.duration - t > NO_KILL_BEFORE_END_S
        {
            let role = roles[self.rotation % roles.len()];
            self.rotation += 1;
            self.next_stall_s += self.args.stall_every.unwrap_or(f64::INFINITY);
            if let Some(pid) = ctl.stall(role) {
                let stall = Duration::from_secs_f64(self.args.stall_for);
                self.stalled = Some((role, pid, now + stall));
                self.kills.push(Kill {
                    role: role.name().to_string(),
                    pid,
                    stamp_ns: monotonic_ns(),
                    kind: "stall".into(),
                    stall_ms: Some(self.args.stall_for * 1e3),
                    hung_at_ns: None,
                });
                self.pending_fault = true;
                ctl.note(&format!(
                    "soak: SIGSTOP {} (pid {pid}) for {:.0} ms at {t:.1} s",
                    role.name(),
                    self.args.stall_for * 1e3
                ));
            }
            return;
        }
        if t >= self.next_kill_s
            && !self.pending_fault
            && self.args.duration - t > NO_KILL_BEFORE_END_S
        {
            let role = roles[self.rotation % roles.len()];
            self.rotation += 1;
            self.next_kill_s += self.args.kill_every.unwrap_or(f64::INFINITY);
            if let Some(pid) = ctl.kill(role) {
                if role == ServiceRole::Planner {
                    self.floor_epoch
                        .fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                }
                self.kills.push(Kill {
                    role: role.name().to_string(),
                    pid,
                    stamp_ns: monotonic_ns(),
                    kind: "kill".into(),
                    stall_ms: None,
                    hung_at_ns: None,
                });
                self.pending_fault = true;
                ctl.note(&format!(
                    "soak: kill -9 {} (pid {pid}) at {t:.1} s",
                    role.name()
                ));
            }
            return;
        }
        if !healthy || self.last_command.is_some_and(|c| c.elapsed() < COMMAND_GAP) {
            return;
        }
        let dof = self.targets.dof();
        let idle = planner.is_some_and(|s| s.program_done == 1);
        if self.args.random_commands && t >= self.next_random_s {
            self.next_random_s = t + self.rng.range(0.5, 4.0);
            if self.rng.unit() < 0.75 {
                let target = self.targets.random(&mut self.rng);
                // Scaled-down limits only from rest: a moving arm may already exceed them
                // (the planner would refuse the move); mid-motion the configured limits.
                let scale = if idle { self.rng.range(0.2, 1.0) } else { 0.0 };
                port.move_to(&target, dof, scale);
                self.count("random_move");
            } else {
                port.stop();
                self.count("stop");
            }
            self.last_command = Some(now);
        } else if idle {
            // The motion cycle repeats whenever the planner is idle.
            let target = self.targets.cycle();
            port.move_to(&target, dof, 0.0);
            self.count("move");
            self.last_command = Some(now);
        }
    }

    fn restarting(&mut self, role: ServiceRole, resume: Option<&microrobot_messages::JointState>) {
        if role == ServiceRole::Actuator
            && let Some(o) = &self.observer
            && let Ok(mut h) = o.handover.lock()
        {
            *h = resume.copied();
        }
    }

    fn hung(&mut self, role: ServiceRole, pid: u32) {
        if let Some(k) = self
            .kills
            .iter_mut()
            .rev()
            .find(|k| k.kind == "stall" && k.pid == pid && k.role == role.name())
        {
            k.hung_at_ns.get_or_insert(monotonic_ns());
        }
        if self.stalled.is_some_and(|(_, p, _)| p == pid) {
            self.stalled = None;
        }
    }

    fn progress(&self) -> String {
        let (jumps, latches) = self.observer.as_ref().map_or((0, 0), |o| {
            (
                o.live.jumps.load(std::sync::atomic::Ordering::Relaxed),
                o.live.latches.load(std::sync::atomic::Ordering::Relaxed),
            )
        });
        let eta = self.t0.map_or(String::new(), |t0| {
            let left = (self.args.duration - t0.elapsed().as_secs_f64()).max(0.0) as u64;
            format!(
                ", ETA {}:{:02}:{:02}",
                left / 3600,
                left / 60 % 60,
                left % 60
            )
        });
        format!(
            " | soak: faults {}, jumps {jumps}, latches {latches}{eta}",
            self.kills.len()
        )
    }
}
