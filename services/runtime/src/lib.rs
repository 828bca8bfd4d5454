//! The shared service runtime of the microrobot pipeline: config loading, tracing, one
//! owner of SIGINT/SIGTERM, absolute monotonic deadlines from a timerfd, overrun
//! policy, millisecond watchdogs, bus-payload validation, real-time settings, latency
//! histograms and the ~10 Hz status message. The planner, dynamics and actuator
//! services are `fn(&PipelineConfig, &Shutdown) -> anyhow::Result<()>` run by
//! [`service_main`].

pub mod arrival;
pub mod config;
pub mod node;
pub mod ports;
pub mod provenance;
pub mod reactor;
pub mod rt;
pub mod shutdown;
pub mod stage;
pub mod stats;
pub mod status;
pub mod timer;
pub mod validate;
pub mod watchdog;

use std::path::Path;
use std::process::ExitCode;

pub use config::{ConfigError, PipelineConfig};
pub use microrobot_messages::ServiceRole;

// The bus carries the model's joint vectors: one capacity for both (the messages crate
// stays free of the model, the model free of the bus).
const _: () = assert!(microrobot_messages::MAX_JOINTS == microrobot_model::MAX_JOINTS);
pub use arrival::ArrivalTicker;
pub use node::{InstanceInUse, open_node, waitset};
pub use ports::{Inbox, Outbox, Received, Subscription};
pub use reactor::{Reactor, Ready, Source};
pub use shutdown::Shutdown;
pub use stage::{Cycle, SWEEP_NS, SetUp, Stage, serve};
pub use status::StatusPort;
pub use timer::{PeriodicClock, Tick, TickTimer, Ticker, TimerFd};
pub use watchdog::{Freshness, Watchdog};

/// Process exit codes shared by the services and every `microrobot` command; one meaning
/// each (the README's "Exit codes" table lists them).
pub mod exit_code {
    /// The job asked for ran to its end (a service: a clean exit, also after SIGINT/SIGTERM).
    pub const OK: u8 = 0;
    /// Any other failure (an I/O error, an unreadable input file, a missing instance).
    pub const FAILURE: u8 = 1;
    /// The command line was not understood (clap's usage errors).
    pub const USAGE: u8 = 2;
    /// Supervisor: a service exited with an error or died (restarted or not).
    pub const SERVICE_FAILED: u8 = 3;
    /// Supervisor: a service did not become ready (or stopped reporting) in time.
    pub const TIMEOUT: u8 = 4;
    /// A live process already runs this instance (same instance name).
    pub const INSTANCE_IN_USE: u8 = 5;
    /// The config, robot or program file (or a command-line override) was refused before
    /// anything started.
    pub const BAD_CONFIG: u8 = 6;
    /// The pipeline ran but the job did not happen: the program was abandoned or not run,
    /// the actuator's safe state was latched and not reset by the end, a command or
    /// check was refused.
    pub const JOB_FAILED: u8 = 7;
    /// Stopped by SIGINT/SIGTERM (Ctrl-C) before the job was done (128 + SIGINT).
    pub const INTERRUPTED: u8 = 130;
}

/// A service's main loop: runs until the program is done or `shutdown` is requested.
pub type ServiceFn = fn(&PipelineConfig, &Shutdown) -> anyhow::Result<()>;

/// Reads and validates a whole pipeline config file (`microrobot_config::load`): the
/// runtime cannot read the sections its services own, so a service's `main` passes it in.
pub type LoadFn = fn(&Path) -> Result<PipelineConfig, ConfigError>;

/// A config (or robot/program file) error, so [`service_main`] exits with BAD_CONFIG.
#[derive(Debug, thiserror::Error)]
#[error("{0}")]
pub struct BadConfig(pub String);

/// Called by a service right before its cyclic loop: pins it to its CPUs and makes it
/// SCHED_FIFO (each falling back with one warning), as `cfg` says
/// ([`PipelineConfig::service_realtime`]). Everything before — loading the model, opening
/// ports, locking memory, waiting for the first state — ran as an ordinary task, so a
/// restarting service never holds up the running pipeline's real-time stages on their CPU.
/// Returns what runs the cycle's status work below its priority ([`rt::Housekeeping`]).
pub fn enter_cycle(cfg: &PipelineConfig) -> rt::Housekeeping {
    let mut g = rt::RtGuard::default();
    rt::enter_cycle(&cfg.service_realtime(), &mut g);
    tracing::info!(
        "entering the cycle: real-time settings applied: {:?}",
        g.applied
    );
    rt::Housekeeping::new(g.fifo_priority)
}

/// The `main` of a service binary (`microrobot-planner`, `microrobot-dynamics`,
/// `microrobot-actuator`): `--config FILE` runs the service ([`service_main`]);
/// `--build-id` prints `build_id`, the identity of the build this binary came from,
/// which the supervisor compares with its own before it starts anything, so a binary
/// left over from another build never runs in a pipeline. Anything else is a usage
/// error ([`exit_code::USAGE`]).
/// `load` reads the whole config file (`microrobot_config::load`: the runtime's keys and
/// every owned section through its owner).
pub fn service_binary_main(
    role: ServiceRole,
    build_id: &str,
    load: LoadFn,
    service: ServiceFn,
) -> ExitCode {
    let args: Vec<std::ffi::OsString> = std::env::args_os().skip(1).collect();
    let program = format!("microrobot-{}", role.name());
    match args.as_slice() {
        [flag] if flag == "--build-id" => {
            println!("{build_id}");
            ExitCode::SUCCESS
        }
        [flag, path] if flag == "--config" => service_main(role, Path::new(path), load, service),
        _ => {
            eprintln!("usage: {program} --config FILE\n       {program} --build-id");
            ExitCode::from(exit_code::USAGE)
        }
    }
}

/// Installs tracing (`RUST_LOG`, default `info`, to stderr), makes `ctrlc` the one owner
/// of SIGINT/SIGTERM, asks for SIGTERM if the parent (the supervisor) dies, loads the
/// config with `load`, applies the real-time settings that precede set-up (PM QoS, timer slack,
/// mlockall; each falling back with one warning), leaves CPU affinity and SCHED_FIFO to
/// [`enter_cycle`], and runs `service`. Returns the process exit code ([`exit_code`]).
pub fn service_main(
    role: ServiceRole,
    config_path: &Path,
    load: LoadFn,
    service: ServiceFn,
) -> ExitCode {
    service_main_with(role, config_path, load, |_| Ok(()), service)
}

/// [`service_main`] with a closure as the service, and `adjust` applied to the loaded
/// config first (command-line overrides; an `Err` is a config error, exit code 2).
pub fn service_main_with(
    role: ServiceRole,
    config_path: &Path,
    load: LoadFn,
    adjust: impl FnOnce(&mut PipelineConfig) -> Result<(), String>,
    service: impl FnOnce(&PipelineConfig, &Shutdown) -> anyhow::Result<()>,
) -> ExitCode {
    init_tracing();
    iceoryx2::prelude::set_log_level_from_env_or(iceoryx2::prelude::LogLevel::Error);
    let shutdown = match Shutdown::new() {
        Ok(s) => s,
        Err(e) => {
            tracing::error!("{}: cannot create shutdown eventfd: {e}", role.name());
            return ExitCode::from(exit_code::FAILURE);
        }
    };
    if let Err(e) = shutdown.install_signal_handler() {
        tracing::error!(
            "{}: cannot install SIGINT/SIGTERM handler: {e}",
            role.name()
        );
        return ExitCode::from(exit_code::FAILURE);
    }
    // If the supervisor dies, we get SIGTERM and stop cleanly (the actuator goes safe
    // on its own watchdog either way).
    // SAFETY: plain prctl.
    unsafe { libc::prctl(libc::PR_SET_PDEATHSIG, libc::SIGTERM, 0, 0, 0) };

    let cfg = match load(config_path) {
        Ok(mut c) => match adjust(&mut c) {
            Ok(()) => c,
            Err(e) => {
                tracing::error!("{}: bad config: {e}", role.name());
                return ExitCode::from(exit_code::BAD_CONFIG);
            }
        },
        Err(e) => {
            tracing::error!("{}: bad config: {e}", role.name());
            return ExitCode::from(exit_code::BAD_CONFIG);
        }
    };
    let rt = rt::prepare(&cfg.service_realtime());
    tracing::info!(
        "{} starting: instance `{}`, {} Hz{}, real-time settings applied: {:?}",
        role.name(),
        cfg.instance,
        cfg.rate_hz,
        if cfg.lockstep { ", lockstep" } else { "" },
        rt.applied
    );
    let result = service(&cfg, &shutdown);
    drop(rt);
    match result {
        Ok(()) => {
            tracing::info!("{} stopped cleanly", role.name());
            ExitCode::from(exit_code::OK)
        }
        Err(e) => {
            if let Some(e) = e.downcast_ref::<InstanceInUse>() {
                tracing::error!("{}: {e}", role.name());
                ExitCode::from(exit_code::INSTANCE_IN_USE)
            } else if e.downcast_ref::<BadConfig>().is_some() {
                tracing::error!("{}: bad config: {e:#}", role.name());
                ExitCode::from(exit_code::BAD_CONFIG)
            } else {
                tracing::error!("{} failed: {e:#}", role.name());
                ExitCode::from(exit_code::FAILURE)
            }
        }
    }
}

/// Installs the tracing subscriber once (env filter from `RUST_LOG`, default `info`,
/// stderr). Colours only on a terminal: a service's stderr is its log file, which must
/// stay plain text for `grep`, `microrobot logs` and the run's verdict.
pub fn init_tracing() {
    init_tracing_quiet(QuietLines(&[]));
}

/// [`init_tracing`] leaving `quiet` out of the log. Only the first installation counts:
/// a process that quiets lines calls this before anything else installs tracing (the
/// later [`init_tracing`] of [`service_main`] then changes nothing).
pub fn init_tracing_quiet(quiet: QuietLines) {
    use std::io::IsTerminal as _;
    use tracing_subscriber::EnvFilter;
    use tracing_subscriber::layer::SubscriberExt as _;
    use tracing_subscriber::util::SubscriberInitExt as _;
    let filter = EnvFilter::try_from_default_env().unwrap_or_else(|_| EnvFilter::new("info"));
    let fmt = tracing_subscriber::fmt::layer()
        .with_writer(std::io::stderr)
        .with_ansi(std::io::stderr().is_terminal());
    let _ = tracing_subscriber::registry()
        .with(fmt)
        .with(filter)
        .with(quiet)
        .try_init();
}

/// Log lines a process leaves out of its log: the events (and `log` records) whose
/// target is exactly `.0` at exactly level `.1`. Exact, unlike a `RUST_LOG` directive,
/// which also matches the modules below the target: those keep every line. For a
/// library's line per event in the cycle that the process counts and reports itself.
/// As a layer it decides at each call site (no cost for the others); it is a per-layer
/// filter too.
#[derive(Debug, Clone, Copy)]
pub struct QuietLines(pub &'static [(&'static str, tracing::Level)]);

impl QuietLines {
    /// Whether `meta` is one of the quieted lines.
    pub fn hides(&self, meta: &tracing::Metadata<'_>) -> bool {
        self.0
            .iter()
            .any(|(target, level)| meta.target() == *target && meta.level() == level)
    }

    fn interest(&self, meta: &tracing::Metadata<'_>) -> tracing::subscriber::Interest {
        if self.hides(meta) {
            tracing::subscriber::Interest::never()
        } else {
            tracing::subscriber::Interest::always()
        }
    }
}

impl<S: tracing::Subscriber> tracing_subscriber::Layer<S> for QuietLines {
    fn register_callsite(
        &self,
        meta: &'static tracing::Metadata<'static>,
    ) -> tracing::subscriber::Interest {
        self.interest(meta)
    }

    fn enabled(
        &self,
        meta: &tracing::Metadata<'_>,
        _: tracing_subscriber::layer::Context<'_, S>,
    ) -> bool {
        !self.hides(meta)
    }
}

impl<S> tracing_subscriber::layer::Filter<S> for QuietLines {
    fn enabled(
        &self,
        meta: &tracing::Metadata<'_>,
        _: &tracing_subscriber::layer::Context<'_, S>,
    ) -> bool {
        !self.hides(meta)
    }

    fn callsite_enabled(
        &self,
        meta: &'static tracing::Metadata<'static>,
    ) -> tracing::subscriber::Interest {
        self.interest(meta)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::{Arc, Mutex};
    use tracing_subscriber::layer::SubscriberExt as _;

    /// (target, level) of every event that reaches it.
    struct Seen(Arc<Mutex<Vec<(String, tracing::Level)>>>);

    impl<S: tracing::Subscriber> tracing_subscriber::Layer<S> for Seen {
        fn on_event(&self, e: &tracing::Event<'_>, _: tracing_subscriber::layer::Context<'_, S>) {
            let m = e.metadata();
            if let Ok(mut v) = self.0.lock() {
                v.push((m.target().to_string(), *m.level()));
            }
        }
    }

    #[test]
    fn quiet_lines_hide_exactly_their_target_and_level() {
        static QUIET: &[(&str, tracing::Level)] = &[("lib::frames", tracing::Level::ERROR)];
        let seen = Arc::default();
        let subscriber = tracing_subscriber::registry()
            .with(Seen(Arc::clone(&seen)))
            .with(QuietLines(QUIET));
        tracing::subscriber::with_default(subscriber, || {
            tracing::error!(target: "lib::frames", "hidden");
            tracing::warn!(target: "lib::frames", "another level");
            tracing::error!(target: "lib::frames::rx", "a module below");
            tracing::error!(target: "lib", "the module above");
            tracing::error!(target: "lib::framesx", "a longer name");
        });
        let seen = seen.lock().expect("seen").clone();
        let targets: Vec<&str> = seen.iter().map(|(t, _)| t.as_str()).collect();
        assert_eq!(
            targets,
            ["lib::frames", "lib::frames::rx", "lib", "lib::framesx"],
            "{seen:?}"
        );
        assert_eq!(seen[0].1, tracing::Level::WARN);
    }
}
