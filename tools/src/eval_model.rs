//! `microrobot eval model` (being written by the model library's owner).
use std::path::Path;
/// Dynamics path.
#[derive(Debug, Clone, Copy, clap::ValueEnum)]
pub enum Method { NewtonEuler, LagrangeEuler }
/// Runs the JSON-lines interface.
pub fn run(_robot: &Path, _method: Method) -> anyhow::Result<()> { anyhow::bail!("eval model is not built yet") }
