//! `microrobot top` (being written by the supervisor's owner).
/// Arguments.
#[derive(Debug, clap::Args)]
pub struct TopArgs {}
/// Entry point.
pub fn main(_args: TopArgs) -> anyhow::Result<()> { anyhow::bail!("top is not built yet") }
