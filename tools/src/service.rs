//! `microrobot service` (being written by the services' owner).
/// Arguments.
#[derive(Debug, clap::Args)]
pub struct ServiceArgs {}
/// Entry point.
pub fn main(_args: ServiceArgs) -> std::process::ExitCode { std::process::ExitCode::FAILURE }
