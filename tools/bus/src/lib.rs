//! The tools that work on a running pipeline's bus or on what it recorded: the one bus
//! tap that every reader shares, recording (`record`) and what is done with a recording
//! (`export`, `plot`, `replay` and its closed-loop variant, `recover`), the services'
//! logs, the live viewer's feed, the readers of a running pipeline (`list`, `echo`,
//! `hz`, `logs`, `top`, `teleop-report`), its writers (`send`, `teleop-source`), and the
//! stream invariants that the soak and the system tests judge the streams by.

pub mod inspect;
pub mod invariants;
pub mod recording;
pub mod send;
pub mod teleop_report;
pub mod teleop_source;
pub mod top;
