//! `microrobot service <planner|dynamics|actuator> --config FILE` (hidden): runs one
//! pipeline service in this process. `microrobot run` starts each service this way;
//! the same code is also built as the standalone binaries `microrobot-planner`,
//! `microrobot-dynamics` and `microrobot-actuator`.

use std::path::PathBuf;
use std::process::ExitCode;

use microrobot_runtime::{ServiceRole, service_main};

/// Which service to run.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Role {
    /// The clock: samples the motion and publishes joint setpoints.
    Planner,
    /// Setpoints and measured state to joint torques.
    Dynamics,
    /// The actuator backend (simulated arm).
    Actuator,
}

/// Arguments of `microrobot service`.
#[derive(Debug, Clone, clap::Args)]
pub struct ServiceArgs {
    /// The service to run.
    #[arg(value_enum)]
    pub role: Role,
    /// Pipeline config (e.g. config/pipeline.toml); the supervisor passes a resolved copy.
    #[arg(long)]
    pub config: PathBuf,
}

/// Runs the service until SIGINT/SIGTERM (or its own end); returns its exit code
/// (`microrobot_runtime::exit_code`).
pub fn main(args: ServiceArgs) -> ExitCode {
    match args.role {
        Role::Planner => service_main(ServiceRole::Planner, &args.config, microrobot_planner::run),
        Role::Dynamics => service_main(
            ServiceRole::Dynamics,
            &args.config,
            microrobot_dynamics::run,
        ),
        Role::Actuator => service_main(
            ServiceRole::Actuator,
            &args.config,
            microrobot_actuator::run,
        ),
    }
}
