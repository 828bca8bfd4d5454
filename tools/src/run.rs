//! `microrobot run` (being written by the supervisor's owner).
/// Arguments.
#[derive(Debug, clap::Args)]
pub struct RunArgs {}
/// Entry point.
pub fn main(_args: RunArgs) -> std::process::ExitCode { std::process::ExitCode::FAILURE }
