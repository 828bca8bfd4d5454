//! The whole pipeline file (`config/pipeline.toml`), read through every owner: the
//! runtime validates its own keys (instance, rate, robot, lockstep, watchdogs, real-time
//! settings, ...) and hands out each owned section raw
//! ([`microrobot_runtime::config::OWNED_SECTIONS`]); the crate that uses a section reads
//! it (`[dynamics]`: [`DynamicsConfig`], `[actuator]`: [`ActuatorConfig`], `[teleop]`:
//! [`TeleopConfig`]) and stores it back with
//! every key, so that [`PipelineConfig::to_toml_string`] writes the effective config in
//! full and reading that back gives the same config.
//!
//! Everything that takes a pipeline file — `microrobot check`, `microrobot run` before
//! it starts anything, each service at start — loads it here, so an unknown key or a bad
//! value in any section is refused with the file and the key.

use std::path::Path;

use microrobot_actuator::ActuatorConfig;
use microrobot_dynamics::DynamicsConfig;
use microrobot_planner::TeleopConfig;
use microrobot_runtime::config::{ConfigError, OwnedSection, PipelineConfig};

/// Reads every owned section of `cfg` through its owner and stores each back with every
/// key. Errors name the file and the key.
pub fn check(cfg: &mut PipelineConfig) -> Result<(), ConfigError> {
    DynamicsConfig::check(cfg)?;
    ActuatorConfig::check(cfg)?;
    TeleopConfig::check(cfg)?;
    Ok(())
}

/// Reads and validates a pipeline config file, every section; relative paths inside are
/// resolved against the file's directory. Errors name the file and the key.
pub fn load(path: &Path) -> Result<PipelineConfig, ConfigError> {
    let mut cfg = PipelineConfig::load_runtime_keys(path)?;
    check(&mut cfg)?;
    Ok(cfg)
}

/// Parses and validates config text, every section; `origin` names it in errors,
/// `base_dir` resolves relative paths (made absolute when `base_dir` exists).
pub fn from_toml_str(
    text: &str,
    origin: &str,
    base_dir: &Path,
) -> Result<PipelineConfig, ConfigError> {
    let mut cfg = PipelineConfig::runtime_keys_from_toml_str(text, origin, base_dir)?;
    check(&mut cfg)?;
    Ok(cfg)
}
