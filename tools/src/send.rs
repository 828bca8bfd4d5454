//! `microrobot send` (being written by the supervisor's owner).
/// Arguments.
#[derive(Debug, clap::Args)]
pub struct SendArgs {}
/// Entry point.
pub fn main(_args: SendArgs) -> anyhow::Result<()> { anyhow::bail!("send is not built yet") }
