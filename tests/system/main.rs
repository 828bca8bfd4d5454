//! The system tests: each starts the real `microrobot` binary (and through it the three
//! service processes) with a config of its own and a unique instance name, so they run
//! side by side in one test binary. The tests whose subject is the host's timing (a
//! saturated CPU, frozen services, long soaks) are binaries of their own beside this
//! one (`tests/overload.rs`, `tests/stall.rs`, `tests/queue_depth.rs`, `tests/soak.rs`):
//! Cargo runs test binaries one after another, so those never share the machine with
//! another test.

#[path = "../common/mod.rs"]
mod common;

mod bad_input;
mod cli_errors;
mod commands;
mod config_keys;
mod driver_check;
mod error_messages;
mod estop;
mod ethercat_driver_check;
mod ethercat_faults;
mod ethercat_netns;
mod ethercat_rig;
mod faults;
mod hop_budget;
mod inspect;
mod lifecycle;
mod pipeline;
mod planner_clock;
mod recording;
mod restart;
mod robot_urdf;
mod send_instance;
mod service_binaries;
mod state_dir;
mod study;
mod takeover;
mod teleop;
mod trust_boundary;
mod urdf_robot_run;
mod verdicts;
mod view;
