//! `microrobot-actuator --config FILE`: the actuator service as a standalone binary
//! (the supervisor runs the same code as `microrobot service actuator`).

use std::path::PathBuf;
use std::process::ExitCode;

fn main() -> ExitCode {
    let mut args = std::env::args().skip(1);
    let config = match (args.next().as_deref(), args.next()) {
        (Some("--config"), Some(p)) => PathBuf::from(p),
        _ => {
            eprintln!("usage: microrobot-actuator --config FILE");
            return ExitCode::from(microrobot_runtime::exit_code::USAGE);
        }
    };
    microrobot_runtime::service_main(
        microrobot_runtime::ServiceRole::Actuator,
        &config,
        microrobot_actuator::run,
    )
}
