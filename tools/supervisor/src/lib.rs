//! The pipeline supervisor behind `microrobot run`: it checks a pipeline before anything
//! moves (`microrobot check`), finds the service binaries of its own build, starts and
//! watches them and the driver, and summarises the run; plus the status-stream plumbing
//! and the instance directories that the bus tools share with it, and `microrobot
//! driver-check`, which runs a driver the way the supervisor does against a scripted
//! pipeline.

pub mod binaries;
pub mod check;
pub mod driver_check;
pub mod driver_info;
pub mod instance;
pub mod monitor;
pub mod process;
pub mod run;
pub mod state_tap;
pub mod summary;
