//! The microrobot driver SDK: how an actuator driver joins the pipeline.
//!
//! A driver is an [`ActuatorBackend`] — `read(now) -> Measured`, `write(now, period, τ)`
//! and optional lifecycle hooks — handed to [`main`]. The actuator framework behind it
//! (the same code as the simulated arm's `microrobot-actuator`) does the rest:
//! the bus ports, the lifecycle, the stale hold and the latched safe state with its
//! reset, the one-publisher rule, stall handling, the state stream with its header
//! bookkeeping (one state per cycle free-running, one per torque command in lockstep),
//! the status at ~10 Hz with the backend's fault code, the last state and status on
//! SIGINT/SIGTERM, the exit codes.
//!
//! ```no_run
//! use microrobot_driver::{ActuatorBackend, Args, Fault, JointVector, Measured, Setup};
//!
//! struct Drive { dof: usize, q: JointVector }
//!
//! impl ActuatorBackend for Drive {
//!     fn dof(&self) -> usize { self.dof }
//!     fn write(&mut self, _now_ns: u64, _period_s: f64, _tau: &JointVector) -> Result<(), Fault> {
//!         Ok(()) // send the torques to the drives
//!     }
//!     fn read(&mut self, _now_ns: u64) -> Result<Measured, Fault> {
//!         Ok(Measured { q: self.q, ..Default::default() }) // the encoders
//!     }
//! }
//!
//! fn main() -> std::process::ExitCode {
//!     let args = match Args::from_env(&[]) {
//!         Ok(a) => a,
//!         Err(e) => return microrobot_driver::usage_error("my-driver", &e),
//!     };
//!     microrobot_driver::main(&args, |s: &Setup| Ok(Drive { dof: s.dof(), q: s.start.q }))
//! }
//! ```
//!
//! Configuration comes from the resolved pipeline config the supervisor hands over
//! (`MICROROBOT_CONFIG`, or `--config FILE`): [`Setup`] gives the robot (joint names,
//! limits), the rate, lockstep and the start state.

use std::path::PathBuf;
use std::process::ExitCode;

pub use anyhow;
pub use microrobot_actuator::lifecycle::Lifecycle;
pub use microrobot_actuator::{
    ActuatorBackend, Fault, Measured, Setup, StartFrom, StartState, serve,
};
pub use microrobot_messages::{LifecycleState, MAX_JOINTS};
pub use microrobot_model::{self as model, JointKind, JointVector, Robot};
pub use microrobot_runtime::config::PipelineConfig;
pub use microrobot_runtime::{Shutdown, exit_code};

/// The environment variable the supervisor sets to the resolved config file.
pub const CONFIG_ENV: &str = "MICROROBOT_CONFIG";

/// The command line every driver understands, plus the driver's own `--name value`
/// options.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Args {
    /// `--config FILE`, else [`CONFIG_ENV`].
    pub config: Option<PathBuf>,
    /// `--instance NAME`: overrides the config's `instance`.
    pub instance: Option<String>,
    /// `--rate-hz HZ`: overrides the config's `rate_hz`.
    pub rate_hz: Option<f64>,
    /// The driver's own options, `(name, value)` in order.
    pub extra: Vec<(String, String)>,
}

impl Args {
    /// Parses `args` (without the program name); `extra` names the driver's own options
    /// (each takes a value). The error names the argument.
    pub fn parse(
        args: impl IntoIterator<Item = String>,
        extra: &[&str],
        config_env: Option<String>,
    ) -> Result<Self, String> {
        let mut out = Args {
            config: config_env.filter(|c| !c.is_empty()).map(PathBuf::from),
            ..Default::default()
        };
        let mut args = args.into_iter();
        while let Some(arg) = args.next() {
            let mut value = || args.next().ok_or(format!("{arg} needs a value"));
            match arg.as_str() {
                "--config" => out.config = Some(PathBuf::from(value()?)),
                "--instance" => out.instance = Some(value()?),
                "--rate-hz" => {
                    let v = value()?;
                    let r = v
                        .parse::<f64>()
                        .ok()
                        .filter(|r| r.is_finite() && *r > 0.0)
                        .ok_or(format!("--rate-hz must be a positive number, got `{v}`"))?;
                    out.rate_hz = Some(r);
                }
                name if extra.contains(&name) => {
                    let v = value()?;
                    out.extra.push((arg, v));
                }
                other => return Err(format!("unknown argument `{other}`")),
            }
        }
        Ok(out)
    }

    /// [`Args::parse`] of this process's arguments and [`CONFIG_ENV`].
    pub fn from_env(extra: &[&str]) -> Result<Self, String> {
        Self::parse(
            std::env::args().skip(1),
            extra,
            std::env::var(CONFIG_ENV).ok(),
        )
    }

    /// The last value of the driver's option `name`.
    pub fn value(&self, name: &str) -> Option<&str> {
        self.extra
            .iter()
            .rev()
            .find(|(n, _)| n == name)
            .map(|(_, v)| v.as_str())
    }
}

/// Prints `msg` prefixed by the driver's `name` and returns the bad-config exit code.
pub fn usage_error(name: &str, msg: &str) -> ExitCode {
    eprintln!("{name}: {msg}");
    ExitCode::from(exit_code::BAD_CONFIG)
}

/// Runs the driver as the pipeline's actuator until SIGINT/SIGTERM and returns the exit
/// code: loads the config `args` names (with its overrides), builds the backend with
/// `make_backend` and [`serve`]s it.
pub fn main<B, F>(args: &Args, make_backend: F) -> ExitCode
where
    B: ActuatorBackend,
    F: FnOnce(&Setup) -> anyhow::Result<B>,
{
    let Some(config) = &args.config else {
        let argv0 = std::env::args().next().unwrap_or_default();
        let name = std::path::Path::new(&argv0)
            .file_name()
            .and_then(|n| n.to_str())
            .unwrap_or("driver");
        return usage_error(
            name,
            &format!(
                "no config: pass --config FILE or set {CONFIG_ENV} (`microrobot run` sets it)"
            ),
        );
    };
    let adjust = |cfg: &mut PipelineConfig| {
        if let Some(i) = &args.instance {
            cfg.instance = i.clone();
        }
        if let Some(r) = args.rate_hz {
            cfg.rate_hz = r;
        }
        Ok(())
    };
    microrobot_runtime::service_main_with(
        microrobot_runtime::ServiceRole::Actuator,
        config,
        microrobot_config::load,
        adjust,
        |cfg, shutdown| serve(cfg, shutdown, make_backend),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(a: &[&str], env: Option<&str>) -> Result<Args, String> {
        Args::parse(
            a.iter().map(|s| s.to_string()),
            &["--q0-deg"],
            env.map(String::from),
        )
    }

    #[test]
    fn common_and_own_options_parse_and_bad_ones_are_named() {
        let a = parse(
            &["--instance", "x", "--rate-hz", "500", "--q0-deg", "1,2"],
            Some("/tmp/c.toml"),
        )
        .unwrap();
        assert_eq!(a.config, Some(PathBuf::from("/tmp/c.toml")));
        assert_eq!(a.instance.as_deref(), Some("x"));
        assert_eq!(a.rate_hz, Some(500.0));
        assert_eq!(a.value("--q0-deg"), Some("1,2"));
        let a = parse(&["--config", "b.toml"], Some("/tmp/c.toml")).unwrap();
        assert_eq!(a.config, Some(PathBuf::from("b.toml")), "--config wins");
        assert!(
            parse(&["--speed", "3"], None)
                .unwrap_err()
                .contains("--speed")
        );
        assert!(
            parse(&["--rate-hz", "0"], None)
                .unwrap_err()
                .contains("--rate-hz")
        );
        assert!(
            parse(&["--q0-deg"], None)
                .unwrap_err()
                .contains("needs a value")
        );
    }
}
