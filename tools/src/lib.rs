//! The `microrobot` CLI's subcommands, as a library so system tests and tools share them.

pub use microrobot_command_line::{config_path, duration, exit};
pub use microrobot_supervisor::{self as supervisor, check, run};

pub mod probe_chain;
pub mod soak;
