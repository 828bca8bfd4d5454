//! The plug-in point for actuator drivers: [`ActuatorBackend`], with a lifecycle after
//! ros2_control's `hardware_interface` (unconfigured → inactive → active, fault latched
//! until an explicit reset), a `write()` of joint torques and a `read()` of the measured
//! state every cycle.
//!
//! # Mapping a CiA 402 drive in cyclic synchronous torque mode (CST, mode 10)
//!
//! One backend drives one EtherCAT (or CANopen) segment; each joint is one CiA 402 axis.
//!
//! | backend call | what it does on the drives |
//! |---|---|
//! | `configure()` | Bring the bus to PRE-OP, check every axis is there, write the SDOs: modes of operation `0x6060 = 10` (CST), torque limits `0x6072`, rated torque `0x6076` (for the per-mille scaling of target torque `0x6071`), following-error and quick-stop settings; map RxPDO {controlword `0x6040`, target torque `0x6071`} and TxPDO {statusword `0x6041`, position actual `0x6064`, velocity actual `0x606C`, torque actual `0x6077`}; set the sync (DC) cycle to the pipeline period and the drive's own communication watchdog (SM watchdog / `0x10F1` or the vendor's "sync loss" timeout, e.g. 3 periods) so a drive that stops receiving PDOs brakes on its own even if this process dies. Go to SAFE-OP, then OP. State: Unconfigured → Inactive. |
//! | `activate()` | The enable sequence, one controlword per cycle, each waiting for its statusword: *Switch on disabled* → `0x0006` Shutdown → *Ready to switch on* → `0x0007` Switch on → *Switched on* → write target torque = 0 first (or the holding torque of the measured state, so the arm does not sag when the brake opens), then `0x000F` Enable operation → *Operation enabled*, release the brake. Inactive → Active. |
//! | `write(tau)` | Target torque `0x6071` = tau / gear ratio / rated torque × 1000 per axis, in the next RxPDO. Called every cycle: the drive's watchdog sees a missing cycle. |
//! | `read()` | Position/velocity actual from the last TxPDO, converted to joint side (encoder counts → rad, gear ratio); `tau_applied` from torque actual `0x6077`. Statusword bit 3 (Fault) set on any axis → the backend goes to Fault and `read()`/`write()` return [`BackendError::Fault`]. |
//! | `deactivate()` | Controlword `0x0007` (Disable operation; the drive decelerates per `0x605C`), close the brake. Active → Inactive. |
//! | `reset_fault()` | Read the error code `0x603F` for the log, then controlword bit 7 rising edge (Fault reset, `0x0080`) → *Switch on disabled*. Fault → Inactive; activation then needs the enable sequence again, starting from the measured state. |
//!
//! The actuator service adds the pipeline's watchdogs on top: stale torque commands
//! (`stale_ms`) make it hold position with its own law, missing commands for `fault_ms`
//! latch the safe state. A real drive should additionally keep its own communication
//! watchdog armed (see `configure()`), because it is the only one that still works when
//! this process is gone.

use microrobot_messages::LifecycleState;
use microrobot_model::JointVector;

/// Why a backend call failed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum BackendError {
    /// The call is not allowed in the backend's current lifecycle state.
    #[error("`{call}` is not allowed in lifecycle state {state:?}")]
    WrongState {
        /// The call.
        call: &'static str,
        /// The state it was made in.
        state: LifecycleState,
    },
    /// The hardware (or simulation) is in fault; [`ActuatorBackend::reset_fault`] is needed.
    #[error("backend fault: {0}")]
    Fault(&'static str),
}

/// The measured joint state returned by [`ActuatorBackend::read`], SI units.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Measured {
    /// Position (rad or m).
    pub q: JointVector,
    /// Velocity (rad/s or m/s).
    pub qd: JointVector,
    /// Torque actually applied after saturation (N·m or N).
    pub tau_applied: JointVector,
    /// Whether the last written torque was saturated on some joint.
    pub saturated: bool,
}

/// A joint-torque actuator for `dof` joints with an explicit lifecycle.
///
/// Transitions: `configure` (Unconfigured → Inactive), `activate` (Inactive → Active),
/// `deactivate` (Active → Inactive), `reset_fault` (Fault → Inactive). Any state can
/// go to Fault on an error. `read` works in Inactive, Active and (for the last known
/// state) Fault; `write` only in Active.
pub trait ActuatorBackend {
    /// Number of joints.
    fn dof(&self) -> usize;
    /// Current lifecycle state.
    fn lifecycle(&self) -> LifecycleState;
    /// Unconfigured → Inactive: open and check the hardware.
    fn configure(&mut self) -> Result<(), BackendError>;
    /// Inactive → Active: enable the drives holding the measured state.
    fn activate(&mut self) -> Result<(), BackendError>;
    /// Active → Inactive: disable the drives, brakes on.
    fn deactivate(&mut self) -> Result<(), BackendError>;
    /// Fault → Inactive: acknowledge the fault.
    fn reset_fault(&mut self) -> Result<(), BackendError>;
    /// Applies `tau` (joint side) for the next cycle of `period_s` seconds.
    fn write(&mut self, tau: &JointVector, period_s: f64) -> Result<(), BackendError>;
    /// The measured state now.
    fn read(&mut self) -> Result<Measured, BackendError>;
}
