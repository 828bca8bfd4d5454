//! The plug-in point for actuator drivers: [`ActuatorBackend`]. A backend only talks to
//! its hardware: `read()` the measured state and `write()` joint torques every cycle,
//! plus lifecycle hooks after ros2_control's `hardware_interface` (`on_configure`,
//! `on_activate`, `on_deactivate`, `on_error`, `on_reset`, `on_shutdown`, each with a
//! default that does nothing). The framework ([`crate::serve`], [`crate::ActuatorCore`])
//! owns the lifecycle (unconfigured → inactive → active, fault latched until an explicit
//! reset) and calls a hook only in the state it belongs to, so a backend has no state
//! guards of its own.
//!
//! # Mapping a CiA 402 drive in cyclic synchronous torque mode (CST, mode 10)
//!
//! One backend drives one EtherCAT (or CANopen) segment; each joint is one CiA 402 axis.
//!
//! | backend call | what it does on the drives |
//! |---|---|
//! | `on_configure()` | Bring the bus to PRE-OP, check every axis is there, write the SDOs: modes of operation `0x6060 = 10` (CST), torque limits `0x6072`, rated torque `0x6076` (for the per-mille scaling of target torque `0x6071`), following-error and quick-stop settings; map RxPDO {controlword `0x6040`, target torque `0x6071`} and TxPDO {statusword `0x6041`, position actual `0x6064`, velocity actual `0x606C`, torque actual `0x6077`}; set the sync (DC) cycle to the pipeline period and the drive's own communication watchdog (SM watchdog / `0x10F1` or the vendor's "sync loss" timeout, e.g. 3 periods) so a drive that stops receiving PDOs brakes on its own even if this process dies. Go to SAFE-OP, then OP. State: Unconfigured → Inactive. |
//! | `on_activate()` | The enable sequence, one controlword per cycle, each waiting for its statusword: *Switch on disabled* → `0x0006` Shutdown → *Ready to switch on* → `0x0007` Switch on → *Switched on* → write target torque = 0 first (or the holding torque of the measured state, so the arm does not sag when the brake opens), then `0x000F` Enable operation → *Operation enabled*, release the brake. Inactive → Active. |
//! | `write(now, period, tau)` | Target torque `0x6071` = tau / gear ratio / rated torque × 1000 per axis, in the next RxPDO. Called every cycle: the drive's watchdog sees a missing cycle. |
//! | `read()` | Position/velocity actual from the last TxPDO, converted to joint side (encoder counts → rad, gear ratio); `tau_applied` from torque actual `0x6077`. Statusword bit 3 (Fault) set on any axis → return a [`Fault`] with that joint and the drive's error code `0x603F`: the framework goes to Fault, calls `on_error`, holds no torque on it and reports the code in its status. |
//! | `on_deactivate()` | Controlword `0x0007` (Disable operation; the drive decelerates per `0x605C`), close the brake. Active → Inactive. |
//! | `on_reset()` | Read the error code `0x603F` for the log, then controlword bit 7 rising edge (Fault reset, `0x0080`) → *Switch on disabled*. Fault → Inactive; activation then needs the enable sequence again, starting from the measured state. |
//!
//! The actuator service adds the pipeline's watchdogs on top: stale torque commands
//! (`stale_ms`) make it hold position with its own law, missing commands for `fault_ms`
//! latch the safe state. A real drive should additionally keep its own communication
//! watchdog armed (see `on_configure()`), because it is the only one that still works when
//! this process is gone.

use std::borrow::Cow;

use microrobot_model::JointVector;

/// A backend fault: which joint (if one), a numeric code and a text. Reported in the
/// actuator's status (`fault_code`, `fault_joint`) and log.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Fault {
    /// The joint (0-based), `None` for the whole drive or bus.
    pub joint: Option<usize>,
    /// The device's error code (a CiA 402 drive's `0x603F`; a backend's own otherwise).
    pub code: u32,
    /// What happened. A `&'static str` does not allocate.
    pub text: Cow<'static, str>,
}

impl Fault {
    /// A fault of the whole drive with a static text.
    pub const fn drive(code: u32, text: &'static str) -> Self {
        Self {
            joint: None,
            code,
            text: Cow::Borrowed(text),
        }
    }

    /// A fault of joint `joint` (0-based) with a static text.
    pub const fn joint(joint: usize, code: u32, text: &'static str) -> Self {
        Self {
            joint: Some(joint),
            code,
            text: Cow::Borrowed(text),
        }
    }
}

impl std::fmt::Display for Fault {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        if let Some(j) = self.joint {
            write!(f, "joint {}: ", j + 1)?;
        }
        write!(f, "{} (code {:#06x})", self.text, self.code)
    }
}

impl std::error::Error for Fault {}

/// The measured joint state returned by [`ActuatorBackend::read`], SI units.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Measured {
    /// Position (rad or m).
    pub q: JointVector,
    /// Velocity (rad/s or m/s).
    pub qd: JointVector,
    /// Torque actually applied after saturation (N·m or N); zero while the drives are off.
    pub tau_applied: JointVector,
    /// Whether the last written torque was saturated on some joint.
    pub saturated: bool,
}

/// A joint-torque actuator for `dof` joints.
///
/// The framework calls, in its lifecycle order: `on_configure` once (Unconfigured →
/// Inactive), `on_activate` when the first valid torque command arrives (Inactive →
/// Active), `write` and `read` every cycle while Active (`read` also while Inactive and in
/// Fault, for the last known state), `on_deactivate` on the way out (Active → Inactive),
/// `on_shutdown` last. A [`Fault`] returned by any call puts the framework in Fault: it
/// calls `on_error` once, writes no more torque, and calls `on_reset` on a Reset command
/// (Fault → Inactive; the next valid command activates again). Hooks default to doing
/// nothing. Times are `CLOCK_MONOTONIC` ns; in lockstep they only stamp.
///
/// `read` and `write` run inside the control cycle: no allocation, locks, blocking I/O
/// or logging there.
pub trait ActuatorBackend {
    /// Number of joints the hardware drives (the framework refuses a robot with another).
    fn dof(&self) -> usize;
    /// Open and check the hardware (Unconfigured → Inactive).
    fn on_configure(&mut self) -> Result<(), Fault> {
        Ok(())
    }
    /// Enable the drives holding the measured state, brakes off (Inactive → Active).
    fn on_activate(&mut self) -> Result<(), Fault> {
        Ok(())
    }
    /// Disable the drives, brakes on (Active → Inactive).
    fn on_deactivate(&mut self) -> Result<(), Fault> {
        Ok(())
    }
    /// The framework entered Fault because of `fault` (called once per fault).
    fn on_error(&mut self, fault: &Fault) {
        let _ = fault;
    }
    /// Acknowledge the fault (Fault → Inactive), e.g. a CiA 402 fault reset.
    fn on_reset(&mut self) -> Result<(), Fault> {
        Ok(())
    }
    /// The process stops: release the hardware (after `on_deactivate`).
    fn on_shutdown(&mut self) {}
    /// Applies `tau` (joint side) for the next cycle of `period_s` seconds.
    fn write(&mut self, now_ns: u64, period_s: f64, tau: &JointVector) -> Result<(), Fault>;
    /// The measured state at `now_ns`.
    fn read(&mut self, now_ns: u64) -> Result<Measured, Fault>;
    /// Free-running: whether a cycle may run late when its torque command is late or
    /// missing. The framework then notices a missing command up to about a millisecond
    /// late and runs the cycle at that moment, which spares it moving its timer onto the
    /// CPU's next expiry every period (a hypervisor exit in a VM; see
    /// `microrobot_runtime::ArrivalTicker`). A bus with a fixed cycle, whose drives
    /// expect a frame every period, keeps the default: each cycle runs by its time,
    /// torque or not. A simulated arm loses nothing by a late step.
    fn cycle_may_run_late(&self) -> bool {
        false
    }
}
