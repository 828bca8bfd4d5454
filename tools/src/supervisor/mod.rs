//! The pipeline supervisor behind `microrobot run`, and the status-stream plumbing that
//! `microrobot top` and `microrobot send` share with it.

pub mod binaries;
pub mod instance;
pub mod monitor;
pub mod process;
pub mod state_tap;
pub mod summary;
