//! The pipeline configuration (`config/pipeline.toml`): the pipeline-wide keys and the
//! sections several processes read, every key checked, units in the key names
//! converted once at load, relative paths resolved against the file's directory. The
//! sections a single service crate uses ([`OWNED_SECTIONS`]) are handed out raw to their
//! owners ([`OwnedSection`]); `microrobot-config` reads a whole file through all of them.
//! `config/pipeline.README.md` documents every key.
//!
//! Errors name the file and the full key path (`watchdog.stale_ms`), so a user finds
//! the typo. Unknown keys, wrong types, non-finite numbers and out-of-range values are
//! all refused; nothing is silently defaulted except keys that are absent.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use microrobot_keypath::{KeyError, Range, Table as KeyTable};
use toml::{Table, Value};

/// Why a pipeline config was refused.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{file}: {}{message}", key.as_deref().map(|k| format!("{k}: ")).unwrap_or_default())]
pub struct ConfigError {
    /// File name (or other origin) of the config text.
    pub file: String,
    /// Key path the error is about (`None` for I/O and TOML syntax errors).
    pub key: Option<String>,
    /// What is wrong.
    pub message: String,
}

impl ConfigError {
    fn at(file: &str, key: &str, message: impl Into<String>) -> Self {
        Self {
            file: file.to_string(),
            key: Some(key.to_string()),
            message: message.into(),
        }
    }
}

/// What the actuator does when it latches its safe state.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SafeStateMode {
    /// Hold the position measured at the latch under the actuator's own PD (gravity compensated).
    Hold,
    /// Damp every joint to rest (gravity compensated), then hold where it stopped.
    Damp,
}

impl SafeStateMode {
    /// The config's name for it (`watchdog.safe_state`).
    pub fn name(self) -> &'static str {
        match self {
            Self::Hold => "hold",
            Self::Damp => "damp",
        }
    }
}

/// What the planner's clock does after it woke more than one period late.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum OverrunPolicy {
    /// Drop the missed ticks and continue on the grid (motion time jumps by the missed periods).
    Skip,
    /// Run one tick per missed period, back to back, until on time again.
    CatchUp,
}

/// What the planner ticks on.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PlannerClock {
    /// Its own absolute-deadline timer at `rate_hz`: the planner is the pipeline's clock.
    Timer,
    /// Each measured-state message of the actuator: the drive's bus cycle is the master
    /// clock (as with an EtherCAT distributed clock). Lockstep always ticks this way.
    ActuatorState,
}

/// What the supervisor does when a service dies.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FailurePolicy {
    /// Restart the failed service, up to `max_restarts` times.
    Restart,
    /// Stop the whole pipeline.
    StopAll,
}

/// Watchdog thresholds (`[watchdog]`), shared by every stage.
#[derive(Debug, Clone, PartialEq)]
pub struct WatchdogConfig {
    /// Input older than this is stale: flagged, counted, and the stage holds (ms).
    pub stale_ms: f64,
    /// Torque commands missing this long latch the actuator's safe state (ms).
    pub fault_ms: f64,
    /// Hold position or damp to rest in the safe state.
    pub safe_state: SafeStateMode,
    /// Leave the safe state by itself once commands are fresh again (else only a Reset).
    pub auto_resume: bool,
    /// Time over which the actuator blends into and out of its own control law (ms).
    pub ramp_ms: f64,
}

/// A configured time in ms as CLOCK_MONOTONIC ns (the loops' unit); the config's
/// ranges keep it finite and non-negative.
#[inline]
pub fn ms_to_ns(ms: f64) -> u64 {
    (ms * 1e6) as u64
}

impl WatchdogConfig {
    /// `stale_ms` in ns: the age at which input is stale, and the silence after which a
    /// new publisher may take a stream over.
    pub fn stale_ns(&self) -> u64 {
        ms_to_ns(self.stale_ms)
    }

    /// `fault_ms` in ns: the silence after which the actuator latches its safe state.
    pub fn fault_ns(&self) -> u64 {
        ms_to_ns(self.fault_ms)
    }
}

/// The smallest limit scale accepted, in the config and in motion commands: slower than
/// 0.1 % of the robot's limits is no motion anyone asks for, and denormal limits break
/// the planners' root finding (a fuzz corpus input found a panic at 1e-300).
pub const MIN_LIMIT_SCALE: f64 = 1e-3;

/// `[planner]`.
#[derive(Debug, Clone, PartialEq)]
pub struct PlannerConfig {
    /// How long to wait at start for the actuator's first measured state (ms).
    pub state_timeout_ms: f64,
    /// Scale [0.001, 1] ([`MIN_LIMIT_SCALE`]) of the robot's velocity/acceleration/jerk
    /// limits for the program and for commands that give no scale.
    pub limit_scale: f64,
    /// Scale [0.001, 1] of the limits for the e-stop's jerk-limited brake (1 = the full
    /// limits).
    pub estop_limit_scale: f64,
    /// A Move command with a stamp older than this is refused as stale (ms).
    pub command_max_age_ms: f64,
    /// What the planner ticks on (free-running; lockstep always ticks on states).
    pub clock: PlannerClock,
}

/// `[realtime]`: per-process real-time settings, each falling back with one warning.
#[derive(Debug, Clone, PartialEq)]
pub struct RealtimeConfig {
    /// CPUs to pin every service to (empty: no pinning).
    pub cpu_affinity: Vec<usize>,
    /// Hold `/dev/cpu_dma_latency` open at `pm_qos_latency_us` while running.
    pub pm_qos: bool,
    /// The PM QoS latency request (µs).
    pub pm_qos_latency_us: u32,
    /// `prctl(PR_SET_TIMERSLACK)` in ns (0: leave the kernel default of 50 µs).
    pub timer_slack_ns: u64,
    /// SCHED_FIFO priority 1..=99, 0: stay SCHED_OTHER. Not applied in lockstep (the
    /// loop free-wheels there and would hog its CPU).
    pub sched_fifo_priority: u32,
    /// `mlockall(MCL_CURRENT | MCL_FUTURE)`.
    pub mlockall: bool,
    /// Planner overrun policy.
    pub overrun: OverrunPolicy,
}

/// `[supervisor]`: read by `microrobot run`.
#[derive(Debug, Clone, PartialEq)]
pub struct SupervisorConfig {
    /// How long each service may take to report ready (ms).
    pub ready_timeout_ms: f64,
    /// How long services get to exit after SIGTERM before SIGKILL (ms).
    pub stop_timeout_ms: f64,
    /// Restart a failed service or stop everything.
    pub on_failure: FailurePolicy,
    /// Restarts allowed per service with `on_failure = "restart"`.
    pub max_restarts: u32,
    /// A live service whose status stops for this long is hung (ms): the supervisor
    /// kills it and applies `on_failure` as to a dead one. At least two status periods.
    pub hung_ms: f64,
}

/// The sections of the file that a service crate owns: their structs, defaults and
/// readers live with the code that uses them (`[dynamics]` in `microrobot-dynamics`,
/// `[actuator]` in `microrobot-actuator`, `[teleop]` in `microrobot-planner`). The
/// runtime checks only that each is a table and keeps it raw in
/// [`PipelineConfig::sections`]; `microrobot-config` reads the whole file through every
/// owner. The other sections stay here: `[watchdog]`, `[planner]` (its `clock` sets the
/// actuator's phase too) and `[realtime]` are read by several services, and
/// `[supervisor]`, read by `microrobot run`, is checked by every service at start,
/// which links no CLI code.
pub const OWNED_SECTIONS: [&str; 3] = ["dynamics", "actuator", "teleop"];

/// A section of the file owned by a service crate ([`OWNED_SECTIONS`]): its struct,
/// defaults and reader live with the code that uses it.
pub trait OwnedSection: Sized {
    /// The section's name in the file (`dynamics`).
    const NAME: &'static str;

    /// Reads the section of `cfg` ([`PipelineConfig::section`]): every key checked
    /// (unknown ones refused), absent ones defaulted, units converted. Errors name the
    /// file and the key.
    fn from_pipeline(cfg: &PipelineConfig) -> Result<Self, ConfigError>;

    /// The section with every key, in the file's units (what [`OwnedSection::store`]
    /// stores, so that the effective config is complete).
    fn to_table(&self) -> Table;

    /// Stores this as the section of `cfg`, every key: a command-line override, or the
    /// effective values after a check.
    fn store(&self, cfg: &mut PipelineConfig) {
        cfg.set_section(Self::NAME, self.to_table());
    }

    /// Reads the section of `cfg` and stores it back with every key.
    fn check(cfg: &mut PipelineConfig) -> Result<Self, ConfigError> {
        let section = Self::from_pipeline(cfg)?;
        section.store(cfg);
        Ok(section)
    }
}

/// The owned sections of a config ([`OWNED_SECTIONS`]) as raw TOML tables, with the
/// name of the file they came from so that their owners' errors name it. Equal when the
/// tables are: the file name is where a config came from, not part of it.
#[derive(Debug, Clone, Default)]
pub struct Sections {
    file: String,
    tables: Table,
}

impl PartialEq for Sections {
    fn eq(&self, other: &Self) -> bool {
        self.tables == other.tables
    }
}

/// The whole pipeline configuration: the runtime's keys validated, the owned sections
/// raw until their owners read them (`microrobot_config::load` reads a file through
/// every owner and stores each section back in full).
#[derive(Debug, Clone, PartialEq)]
pub struct PipelineConfig {
    /// Instance name: the service-name prefix (`[A-Za-z0-9_-]`, 1..=64 chars).
    pub instance: String,
    /// Control rate (Hz).
    pub rate_hz: f64,
    /// Run time limit (s); `None`: until the program is done (or forever without one).
    pub duration_s: Option<f64>,
    /// Robot description file (absolute after load).
    pub robot: PathBuf,
    /// Motion program file (absolute after load).
    pub program: Option<PathBuf>,
    /// Lockstep: logical time, one plant step per torque command, reproducible runs.
    pub lockstep: bool,
    /// Status publishing period (ms).
    pub status_period_ms: f64,
    pub watchdog: WatchdogConfig,
    pub planner: PlannerConfig,
    pub realtime: RealtimeConfig,
    pub supervisor: SupervisorConfig,
    /// The owned sections ([`OWNED_SECTIONS`]), read by their owners
    /// ([`PipelineConfig::section`]).
    pub sections: Sections,
}

impl Default for PipelineConfig {
    /// The built-in defaults (what an empty file gives), with `robot` relative.
    fn default() -> Self {
        Self {
            instance: "default".into(),
            rate_hz: 1000.0,
            duration_s: None,
            robot: PathBuf::from("robots/seed-arm.toml"),
            program: None,
            lockstep: false,
            status_period_ms: 100.0,
            watchdog: WatchdogConfig {
                stale_ms: 50.0,
                fault_ms: 200.0,
                safe_state: SafeStateMode::Hold,
                auto_resume: false,
                ramp_ms: 20.0,
            },
            planner: PlannerConfig {
                state_timeout_ms: 5000.0,
                limit_scale: 1.0,
                estop_limit_scale: 1.0,
                command_max_age_ms: 1000.0,
                clock: PlannerClock::Timer,
            },
            realtime: RealtimeConfig {
                cpu_affinity: vec![1],
                pm_qos: true,
                pm_qos_latency_us: 0,
                timer_slack_ns: 1,
                sched_fifo_priority: 80,
                mlockall: true,
                overrun: OverrunPolicy::CatchUp,
            },
            supervisor: SupervisorConfig {
                ready_timeout_ms: 10000.0,
                stop_timeout_ms: 3000.0,
                on_failure: FailurePolicy::StopAll,
                max_restarts: 3,
                hung_ms: 500.0,
            },
            sections: Sections::default(),
        }
    }
}

impl PipelineConfig {
    /// Reads a pipeline config file and validates the runtime's keys, keeping the owned
    /// sections raw ([`OWNED_SECTIONS`]; `microrobot_config::load` reads them through
    /// their owners too); relative paths inside are resolved against the file's
    /// directory. Errors name the file and the key.
    pub fn load_runtime_keys(path: &Path) -> Result<Self, ConfigError> {
        let origin = path.display().to_string();
        let text = std::fs::read_to_string(path).map_err(|e| ConfigError {
            file: origin.clone(),
            key: None,
            message: format!("cannot read: {e}"),
        })?;
        let base = path
            .parent()
            .map(Path::to_path_buf)
            .unwrap_or_else(|| PathBuf::from("."));
        let base = if base.as_os_str().is_empty() {
            PathBuf::from(".")
        } else {
            base
        };
        Self::runtime_keys_from_toml_str(&text, &origin, &base)
    }

    /// Parses config text and validates the runtime's keys, keeping the owned sections
    /// raw (as [`PipelineConfig::load_runtime_keys`]); `origin` names it in errors,
    /// `base_dir` resolves relative paths (made absolute when `base_dir` exists).
    pub fn runtime_keys_from_toml_str(
        text: &str,
        origin: &str,
        base_dir: &Path,
    ) -> Result<Self, ConfigError> {
        let table: Table = text.parse().map_err(|e: toml::de::Error| ConfigError {
            file: origin.to_string(),
            key: None,
            message: format!("invalid TOML: {}", e.to_string().trim()),
        })?;
        let r = Reader { file: origin };
        let base = std::fs::canonicalize(base_dir).unwrap_or_else(|_| base_dir.to_path_buf());
        r.pipeline(&table, &base)
    }

    /// The owned section `name` ([`OWNED_SECTIONS`]) as a key-path table of the file it
    /// came from, for its owner to read (absent: an empty table, every key absent).
    pub fn section(&self, name: &str) -> Result<KeyTable<'_>, KeyError> {
        KeyTable::root(&self.sections.file, &self.sections.tables).opt_table(name)
    }

    /// Stores `table` as the owned section `name`: its owner's effective values, so that
    /// [`PipelineConfig::to_toml_string`] writes every key of it.
    pub fn set_section(&mut self, name: &str, table: Table) {
        self.sections
            .tables
            .insert(name.to_string(), Value::Table(table));
    }

    /// The control period in ns (`1e9 / rate_hz`, rounded).
    pub fn period_ns(&self) -> u64 {
        (1e9 / self.rate_hz).round() as u64
    }

    /// Whether the planner ticks once per measured-state message (lockstep, or
    /// `planner.clock = "actuator_state"`) instead of on its own timer.
    pub fn planner_ticks_on_states(&self) -> bool {
        self.lockstep || self.planner.clock == PlannerClock::ActuatorState
    }

    /// The real-time settings a service of this config runs with: `[realtime]`, without
    /// SCHED_FIFO in lockstep (the chain free-wheels there; a FIFO busy chain would starve
    /// the machine). The floor probes use the same, so they measure what the services get.
    pub fn service_realtime(&self) -> RealtimeConfig {
        let mut rt = self.realtime.clone();
        if self.lockstep {
            rt.sched_fifo_priority = 0;
        }
        rt
    }

    /// Serialises the (validated) config back to TOML with absolute paths, so the text
    /// is self-contained: reading it back (`microrobot_config::from_toml_str`) gives the
    /// same config.
    pub fn to_toml_string(&self) -> String {
        let mut s = String::new();
        let f = |v: f64| fmt_f64(v);
        let _ = writeln!(s, "instance = {}", quote(&self.instance));
        let _ = writeln!(s, "rate_hz = {}", f(self.rate_hz));
        if let Some(d) = self.duration_s {
            let _ = writeln!(s, "duration_s = {}", f(d));
        }
        let _ = writeln!(s, "robot = {}", quote(&self.robot.to_string_lossy()));
        if let Some(p) = &self.program {
            let _ = writeln!(s, "program = {}", quote(&p.to_string_lossy()));
        }
        let _ = writeln!(s, "lockstep = {}", self.lockstep);
        let _ = writeln!(s, "status_period_ms = {}", f(self.status_period_ms));
        let w = &self.watchdog;
        let _ = writeln!(s, "\n[watchdog]");
        let _ = writeln!(s, "stale_ms = {}", f(w.stale_ms));
        let _ = writeln!(s, "fault_ms = {}", f(w.fault_ms));
        let _ = writeln!(s, "safe_state = {}", quote(w.safe_state.name()));
        let _ = writeln!(s, "auto_resume = {}", w.auto_resume);
        let _ = writeln!(s, "ramp_ms = {}", f(w.ramp_ms));
        let p = &self.planner;
        let _ = writeln!(s, "\n[planner]");
        let _ = writeln!(s, "state_timeout_ms = {}", f(p.state_timeout_ms));
        let _ = writeln!(s, "limit_scale = {}", f(p.limit_scale));
        let _ = writeln!(s, "estop_limit_scale = {}", f(p.estop_limit_scale));
        let _ = writeln!(s, "command_max_age_ms = {}", f(p.command_max_age_ms));
        let _ = writeln!(
            s,
            "clock = {}",
            quote(match p.clock {
                PlannerClock::Timer => "timer",
                PlannerClock::ActuatorState => "actuator_state",
            })
        );
        let r = &self.realtime;
        let _ = writeln!(s, "\n[realtime]");
        let cpus: Vec<String> = r.cpu_affinity.iter().map(|c| c.to_string()).collect();
        let _ = writeln!(s, "cpu_affinity = [{}]", cpus.join(", "));
        let _ = writeln!(s, "pm_qos = {}", r.pm_qos);
        let _ = writeln!(s, "pm_qos_latency_us = {}", r.pm_qos_latency_us);
        let _ = writeln!(s, "timer_slack_ns = {}", r.timer_slack_ns);
        let _ = writeln!(s, "sched_fifo_priority = {}", r.sched_fifo_priority);
        let _ = writeln!(s, "mlockall = {}", r.mlockall);
        let _ = writeln!(
            s,
            "overrun = {}",
            quote(match r.overrun {
                OverrunPolicy::Skip => "skip",
                OverrunPolicy::CatchUp => "catch_up",
            })
        );
        let v = &self.supervisor;
        let _ = writeln!(s, "\n[supervisor]");
        let _ = writeln!(s, "ready_timeout_ms = {}", f(v.ready_timeout_ms));
        let _ = writeln!(s, "stop_timeout_ms = {}", f(v.stop_timeout_ms));
        let _ = writeln!(
            s,
            "on_failure = {}",
            quote(match v.on_failure {
                FailurePolicy::Restart => "restart",
                FailurePolicy::StopAll => "stop_all",
            })
        );
        let _ = writeln!(s, "max_restarts = {}", v.max_restarts);
        let _ = writeln!(s, "hung_ms = {}", f(v.hung_ms));
        if !self.sections.tables.is_empty() {
            let _ = write!(s, "\n{}", self.sections.tables);
        }
        s
    }
}

/// Shortest text that parses back to exactly `v` (always with a decimal point or exponent).
fn fmt_f64(v: f64) -> String {
    let s = format!("{v:?}");
    if s.contains('.') || s.contains('e') || s.contains("inf") || s.contains("NaN") {
        s
    } else {
        format!("{s}.0")
    }
}

fn quote(s: &str) -> String {
    Value::String(s.to_string()).to_string()
}

/// Reads the pipeline file: the key-by-key readers of [`microrobot_keypath`] plus the
/// checks that span keys (they name the key they refuse).
struct Reader<'a> {
    file: &'a str,
}

type Res<T> = Result<T, ConfigError>;

impl From<KeyError> for ConfigError {
    fn from(e: KeyError) -> Self {
        Self {
            file: e.file,
            key: Some(e.key),
            message: e.problem.to_string(),
        }
    }
}

impl Reader<'_> {
    fn err(&self, key: &str, message: impl Into<String>) -> ConfigError {
        ConfigError::at(self.file, key, message)
    }

    fn path(
        &self,
        tab: &KeyTable<'_>,
        key: &str,
        base: &Path,
        must_exist: bool,
    ) -> Res<Option<PathBuf>> {
        let Some(s) = tab.opt_string(key)? else {
            return Ok(None);
        };
        let k = tab.key(key);
        if s.is_empty() {
            return Err(self.err(&k, "empty path"));
        }
        let p = PathBuf::from(&s);
        let p = if p.is_absolute() { p } else { base.join(p) };
        if must_exist && !p.is_file() {
            return Err(self.err(&k, format!("file `{}` does not exist", p.display())));
        }
        Ok(Some(p))
    }

    fn pipeline(&self, root: &Table, base: &Path) -> Res<PipelineConfig> {
        let d = PipelineConfig::default();
        let top = KeyTable::root(self.file, root);
        top.allow(&[
            "instance",
            "rate_hz",
            "duration_s",
            "robot",
            "program",
            "lockstep",
            "status_period_ms",
            "watchdog",
            "planner",
            "dynamics",
            "actuator",
            "realtime",
            "supervisor",
            "teleop",
        ])?;
        let instance = top
            .opt_string("instance")?
            .map_or(d.instance.clone(), str::to_string);
        if instance.is_empty()
            || instance.len() > 64
            || !instance
                .chars()
                .all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-')
        {
            return Err(self.err(
                "instance",
                format!("`{instance}` must be 1 to 64 characters of A-Z a-z 0-9 _ -"),
            ));
        }
        let rate_hz = top.number_in("rate_hz", d.rate_hz, Range::closed(1.0, 10_000.0))?;
        let duration_s = top.opt_number_in("duration_s", Range::left_open(0.0, 1.0e7))?;
        let robot = match self.path(&top, "robot", base, true)? {
            Some(p) => p,
            None => {
                let p = base.join(&d.robot);
                if !p.is_file() {
                    return Err(self.err(
                        "robot",
                        format!("missing, and the default `{}` does not exist", p.display()),
                    ));
                }
                p
            }
        };
        let program = self.path(&top, "program", base, true)?;
        let lockstep = top.bool_or("lockstep", d.lockstep)?;
        let status_period_ms = top.number_in(
            "status_period_ms",
            d.status_period_ms,
            Range::closed(10.0, 10_000.0),
        )?;

        let t = top.section(
            "watchdog",
            &[
                "stale_ms",
                "fault_ms",
                "safe_state",
                "auto_resume",
                "ramp_ms",
            ],
        )?;
        let dw = &d.watchdog;
        let stale_ms = t.number_in("stale_ms", dw.stale_ms, Range::left_open(0.0, 60_000.0))?;
        let fault_ms = t.number_in("fault_ms", dw.fault_ms, Range::left_open(0.0, 60_000.0))?;
        if fault_ms < stale_ms {
            return Err(self.err(
                "watchdog.fault_ms",
                format!("{fault_ms} must be >= watchdog.stale_ms ({stale_ms})"),
            ));
        }
        let period_ms = 1000.0 / rate_hz;
        if stale_ms < 2.0 * period_ms {
            return Err(self.err(
                "watchdog.stale_ms",
                format!(
                    "{stale_ms} must be at least two control periods ({:.3} ms)",
                    2.0 * period_ms
                ),
            ));
        }
        let watchdog = WatchdogConfig {
            stale_ms,
            fault_ms,
            safe_state: t.choice(
                "safe_state",
                dw.safe_state,
                &[("hold", SafeStateMode::Hold), ("damp", SafeStateMode::Damp)],
            )?,
            auto_resume: t.bool_or("auto_resume", dw.auto_resume)?,
            ramp_ms: t.number_in("ramp_ms", dw.ramp_ms, Range::closed(0.0, 10_000.0))?,
        };

        let t = top.section(
            "planner",
            &[
                "state_timeout_ms",
                "limit_scale",
                "estop_limit_scale",
                "command_max_age_ms",
                "clock",
            ],
        )?;
        let dp = &d.planner;
        let planner = PlannerConfig {
            state_timeout_ms: t.number_in(
                "state_timeout_ms",
                dp.state_timeout_ms,
                Range::left_open(0.0, 600_000.0),
            )?,
            limit_scale: t.number_in(
                "limit_scale",
                dp.limit_scale,
                Range::closed(MIN_LIMIT_SCALE, 1.0),
            )?,
            estop_limit_scale: t.number_in(
                "estop_limit_scale",
                dp.estop_limit_scale,
                Range::closed(MIN_LIMIT_SCALE, 1.0),
            )?,
            command_max_age_ms: t.number_in(
                "command_max_age_ms",
                dp.command_max_age_ms,
                Range::left_open(0.0, 3_600_000.0),
            )?,
            clock: t.choice(
                "clock",
                dp.clock,
                &[
                    ("timer", PlannerClock::Timer),
                    ("actuator_state", PlannerClock::ActuatorState),
                ],
            )?,
        };

        let mut tables = Table::new();
        for name in OWNED_SECTIONS {
            if let Some(t) = top.opt_table(name)?.raw() {
                tables.insert(name.to_string(), Value::Table(t.clone()));
            }
        }
        let sections = Sections {
            file: self.file.to_string(),
            tables,
        };

        let t = top.section(
            "realtime",
            &[
                "cpu_affinity",
                "pm_qos",
                "pm_qos_latency_us",
                "timer_slack_ns",
                "sched_fifo_priority",
                "mlockall",
                "overrun",
            ],
        )?;
        let dr = &d.realtime;
        let cpu_affinity = match t.get("cpu_affinity") {
            None => dr.cpu_affinity.clone(),
            Some(Value::Array(items)) => {
                let mut out = Vec::with_capacity(items.len());
                for (i, it) in items.iter().enumerate() {
                    match it {
                        Value::Integer(c) if (0..1024).contains(c) => out.push(*c as usize),
                        _ => {
                            return Err(self.err(
                                &format!("realtime.cpu_affinity[{i}]"),
                                "expected a CPU number 0..1023",
                            ));
                        }
                    }
                }
                out
            }
            Some(_) => {
                return Err(self.err("realtime.cpu_affinity", "expected an array of CPU numbers"));
            }
        };
        let realtime = RealtimeConfig {
            cpu_affinity,
            pm_qos: t.bool_or("pm_qos", dr.pm_qos)?,
            pm_qos_latency_us: t.integer_in(
                "pm_qos_latency_us",
                dr.pm_qos_latency_us as u64,
                0,
                1_000_000,
            )? as u32,
            timer_slack_ns: t.integer_in("timer_slack_ns", dr.timer_slack_ns, 0, 1_000_000_000)?,
            sched_fifo_priority: t.integer_in(
                "sched_fifo_priority",
                dr.sched_fifo_priority as u64,
                0,
                99,
            )? as u32,
            mlockall: t.bool_or("mlockall", dr.mlockall)?,
            overrun: t.choice(
                "overrun",
                dr.overrun,
                &[
                    ("skip", OverrunPolicy::Skip),
                    ("catch_up", OverrunPolicy::CatchUp),
                ],
            )?,
        };

        let t = top.section(
            "supervisor",
            &[
                "ready_timeout_ms",
                "stop_timeout_ms",
                "on_failure",
                "max_restarts",
                "hung_ms",
            ],
        )?;
        let dv = &d.supervisor;
        let supervisor = SupervisorConfig {
            ready_timeout_ms: t.number_in(
                "ready_timeout_ms",
                dv.ready_timeout_ms,
                Range::left_open(0.0, 600_000.0),
            )?,
            stop_timeout_ms: t.number_in(
                "stop_timeout_ms",
                dv.stop_timeout_ms,
                Range::left_open(0.0, 600_000.0),
            )?,
            on_failure: t.choice(
                "on_failure",
                dv.on_failure,
                &[
                    ("restart", FailurePolicy::Restart),
                    ("stop_all", FailurePolicy::StopAll),
                ],
            )?,
            max_restarts: t.integer_in("max_restarts", dv.max_restarts as u64, 0, 1000)? as u32,
            hung_ms: t.number_in("hung_ms", dv.hung_ms, Range::left_open(0.0, 600_000.0))?,
        };
        if supervisor.hung_ms < 2.0 * status_period_ms {
            return Err(self.err(
                "supervisor.hung_ms",
                format!(
                    "{} must be >= 2 × status_period_ms ({status_period_ms}): a healthy service reports once per status period",
                    supervisor.hung_ms
                ),
            ));
        }

        Ok(PipelineConfig {
            instance,
            rate_hz,
            duration_s,
            robot,
            program,
            lockstep,
            status_period_ms,
            watchdog,
            planner,
            realtime,
            supervisor,
            sections,
        })
    }
}
