//! `microrobot eval trajectory` (being written by the trajectory library's owner).
/// Runs the JSON-lines interface.
pub fn run() -> anyhow::Result<()> { anyhow::bail!("eval trajectory is not built yet") }
