//! The bus contract of the microrobot pipeline: the `#[repr(C)]` payloads every process
//! exchanges over iceoryx2, the service names, and the one function that opens every
//! service with the same QoS settings.
//!
//! Everything here is plain data that any language's iceoryx2 binding can read:
//! fixed-width numbers, fixed arrays and nested `#[repr(C)]` structs, no `usize`, no Rust
//! enums, no pointers. Every payload carries an explicit, versioned type name
//! (`microrobot::v2::...`): a build with another contract version cannot open the
//! services (iceoryx2 refuses the type with `IncompatibleTypes`).
//!
//! All values are SI (rad or m, rad/s, N·m or N, ns of `CLOCK_MONOTONIC`). See
//! `messages/README.md` for the field-by-field contract, rates and who publishes what.

pub mod command;
pub mod layout;
pub mod master;
pub mod ports;
pub mod status;
pub mod stream;

pub use command::{CommandKind, MotionCommand, ProfileKind, TargetSpace};
pub use master::MasterPose;
pub use ports::{
    BusError, ServiceKind, Topic, open_event, open_publish_subscribe, service_name, topic,
};
pub use status::{
    Activity, COMMAND_VERDICTS, CommandVerdict, HopLatency, LatencySummary, LifecycleHook,
    LifecycleState, ProgramEnd, ProgramState, RefusalQuantity, RefusalReason, STATUS_HOPS,
    ServiceRole, ServiceStatus, VerdictLookup,
};
pub use stream::{
    Header, JointSetpoint, JointState, TorqueCommand, setpoint_flags, state_flags, torque_flags,
};

/// Joint capacity of every payload. A message carries `dof` active joints; entries past
/// `dof` are zero and must be ignored.
pub const MAX_JOINTS: usize = 8;

/// Version of this contract. It is part of every type name and every service name, so
/// two builds with different contracts never exchange data.
pub const CONTRACT_VERSION: u32 = 2;

/// Reads `CLOCK_MONOTONIC` in nanoseconds: the time base of every timestamp on the bus.
pub fn monotonic_ns() -> u64 {
    let mut ts = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: `ts` is a valid, writable timespec; CLOCK_MONOTONIC always exists on Linux.
    unsafe { libc::clock_gettime(libc::CLOCK_MONOTONIC, &mut ts) };
    (ts.tv_sec as u64) * 1_000_000_000 + ts.tv_nsec as u64
}

/// Checks that the first `dof` entries of `values` are finite and `dof` is within capacity.
pub fn all_finite(values: &[f64; MAX_JOINTS], dof: u32) -> bool {
    (dof as usize) <= MAX_JOINTS && values[..dof as usize].iter().all(|v| v.is_finite())
}
