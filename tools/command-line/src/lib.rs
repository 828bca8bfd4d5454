//! What every `microrobot` command shares: how an error becomes an exit code, the one
//! duration syntax of the time flags, and where the pipeline config is found when
//! `--config` is not given.

pub mod config_path;
pub mod duration;
pub mod exit;
