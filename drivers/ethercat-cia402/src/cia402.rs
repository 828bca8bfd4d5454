//! The CiA 402 (IEC 61800-7-201) power drive state machine, without I/O.
//!
//! A drive reports its state in the statusword (object 0x6041) and is commanded through
//! the controlword (object 0x6040). [`Statusword::state`] decodes the state with the
//! standard's masks, [`Command`] holds the standard's controlword commands, and [`Axis`]
//! is the per-axis driver the master calls once per cycle: it takes the decoded state
//! and the drive's error code (object 0x603F) and returns the controlword to send.
//!
//! The standard's transitions, as numbered in its state diagram (and in the tests):
//!
//! | #  | from                    | to                     | cause                       |
//! |----|-------------------------|------------------------|-----------------------------|
//! | 0  | (start)                 | Not ready to switch on | power on, automatic         |
//! | 1  | Not ready to switch on  | Switch on disabled     | automatic                   |
//! | 2  | Switch on disabled      | Ready to switch on     | Shutdown                    |
//! | 3  | Ready to switch on      | Switched on            | Switch on                   |
//! | 4  | Switched on             | Operation enabled      | Enable operation            |
//! | 5  | Operation enabled       | Switched on            | Disable operation           |
//! | 6  | Switched on             | Ready to switch on     | Shutdown                    |
//! | 7  | Ready to switch on      | Switch on disabled     | Disable voltage, Quick stop |
//! | 8  | Operation enabled       | Ready to switch on     | Shutdown                    |
//! | 9  | Operation enabled       | Switch on disabled     | Disable voltage             |
//! | 10 | Switched on             | Switch on disabled     | Disable voltage, Quick stop |
//! | 11 | Operation enabled       | Quick stop active      | Quick stop                  |
//! | 12 | Quick stop active       | Switch on disabled     | stop done, Disable voltage  |
//! | 13 | any but the fault states| Fault reaction active  | fault detected by the drive |
//! | 14 | Fault reaction active   | Fault                  | automatic                   |
//! | 15 | Fault                   | Switch on disabled     | Fault reset (bit 7 rising)  |
//! | 16 | Quick stop active       | Operation enabled      | Enable operation (0x605A 5-8) |
//!
//! A fault reaction can finish within one bus cycle, so a state seen going straight to
//! Fault (13 and 14 between two samples) is legal too. Staying in a state is always
//! legal.

use std::fmt;

/// Statusword bit 7: a warning is present (the drive keeps running).
const SW_WARNING: u16 = 1 << 7;
/// Statusword bit 9: the drive accepts the controlword over the bus (remote).
const SW_REMOTE: u16 = 1 << 9;
/// Statusword bit 10: target reached (meaning depends on the mode of operation).
const SW_TARGET_REACHED: u16 = 1 << 10;
/// Statusword bit 11: an internal limit is active (e.g. torque or position limit).
const SW_INTERNAL_LIMIT: u16 = 1 << 11;
/// Controlword bit 7: fault reset, acting on its rising edge.
const CW_FAULT_RESET: u16 = 1 << 7;

/// The states of the CiA 402 power drive state machine, as decoded from the statusword
/// (0x6041).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum DriveState {
    /// Low-level power on, drive initialising; the controlword is ignored.
    NotReadyToSwitchOn,
    /// Initialised; power stage off, high voltage may be off. The resting state.
    SwitchOnDisabled,
    /// High voltage may be applied, power stage still off.
    ReadyToSwitchOn,
    /// Power stage ready, no torque.
    SwitchedOn,
    /// Power stage on: the drive follows its setpoints.
    OperationEnabled,
    /// The quick stop function is running (decelerating per 0x605A).
    QuickStopActive,
    /// The drive detected a fault and runs its fault reaction (0x605E).
    FaultReactionActive,
    /// Fault state: power stage off until a fault reset.
    Fault,
}

impl DriveState {
    /// All eight states, for exhaustive checks.
    pub const ALL: [DriveState; 8] = [
        DriveState::NotReadyToSwitchOn,
        DriveState::SwitchOnDisabled,
        DriveState::ReadyToSwitchOn,
        DriveState::SwitchedOn,
        DriveState::OperationEnabled,
        DriveState::QuickStopActive,
        DriveState::FaultReactionActive,
        DriveState::Fault,
    ];

    /// The standard's name of the state.
    pub const fn name(self) -> &'static str {
        match self {
            DriveState::NotReadyToSwitchOn => "Not ready to switch on",
            DriveState::SwitchOnDisabled => "Switch on disabled",
            DriveState::ReadyToSwitchOn => "Ready to switch on",
            DriveState::SwitchedOn => "Switched on",
            DriveState::OperationEnabled => "Operation enabled",
            DriveState::QuickStopActive => "Quick stop active",
            DriveState::FaultReactionActive => "Fault reaction active",
            DriveState::Fault => "Fault",
        }
    }

    /// Whether the state is one of the two fault states.
    pub const fn is_fault(self) -> bool {
        matches!(self, DriveState::FaultReactionActive | DriveState::Fault)
    }

    /// The number of the standard's transition from `self` to `to` (see the module
    /// table), `Some(None)` for staying in the state or for 13 and 14 seen as one step,
    /// `None` if the standard does not allow it.
    pub fn transition_to(self, to: DriveState) -> Option<Option<u8>> {
        use DriveState::*;
        let number = match (self, to) {
            (a, b) if a == b => return Some(None),
            (NotReadyToSwitchOn, SwitchOnDisabled) => 1,
            (SwitchOnDisabled, ReadyToSwitchOn) => 2,
            (ReadyToSwitchOn, SwitchedOn) => 3,
            (SwitchedOn, OperationEnabled) => 4,
            (OperationEnabled, SwitchedOn) => 5,
            (SwitchedOn, ReadyToSwitchOn) => 6,
            (ReadyToSwitchOn, SwitchOnDisabled) => 7,
            (OperationEnabled, ReadyToSwitchOn) => 8,
            (OperationEnabled, SwitchOnDisabled) => 9,
            (SwitchedOn, SwitchOnDisabled) => 10,
            (OperationEnabled, QuickStopActive) => 11,
            (QuickStopActive, SwitchOnDisabled) => 12,
            (FaultReactionActive, Fault) => 14,
            (Fault, SwitchOnDisabled) => 15,
            (QuickStopActive, OperationEnabled) => 16,
            (from, FaultReactionActive) if !from.is_fault() => 13,
            (from, Fault) if !from.is_fault() => return Some(None),
            _ => return None,
        };
        Some(Some(number))
    }

    /// Whether the standard allows the drive to go from `self` to `to` between two
    /// samples.
    pub fn may_go_to(self, to: DriveState) -> bool {
        self.transition_to(to).is_some()
    }
}

impl fmt::Display for DriveState {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// A statusword value that matches none of the standard's state patterns.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[error("statusword 0x{0:04X} (0x6041) matches no CiA 402 state")]
pub struct UndefinedStatusword(pub u16);

/// The statusword (object 0x6041) as read from the drive.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Statusword(pub u16);

impl Statusword {
    /// Bit 4: voltage enabled (high voltage applied to the power stage).
    pub const VOLTAGE_ENABLED: u16 = 1 << 4;
    /// Bit 9: remote (see [`Statusword::remote`]).
    pub const REMOTE: u16 = SW_REMOTE;
    /// Bit 10: target reached (see [`Statusword::target_reached`]).
    pub const TARGET_REACHED: u16 = SW_TARGET_REACHED;
    /// Bit 11: internal limit active (see [`Statusword::internal_limit_active`]).
    pub const INTERNAL_LIMIT: u16 = SW_INTERNAL_LIMIT;

    /// The bits 0-3, 5 and 6 a drive reports in `state`: the inverse of
    /// [`Statusword::state`], for the drive side (an emulated drive). Quick stop (bit 5)
    /// is set where the pattern leaves it free and the drive is not quick-stopping.
    pub const fn of_state(state: DriveState) -> Statusword {
        Statusword(match state {
            DriveState::NotReadyToSwitchOn => 0x0000,
            DriveState::SwitchOnDisabled => 0x0040,
            DriveState::ReadyToSwitchOn => 0x0021,
            DriveState::SwitchedOn => 0x0023,
            DriveState::OperationEnabled => 0x0027,
            DriveState::QuickStopActive => 0x0007,
            DriveState::FaultReactionActive => 0x000F,
            DriveState::Fault => 0x0008,
        })
    }

    /// Decodes the power drive state from bits 0-3, 5 and 6 with the standard's masks
    /// (x = don't care, bit 15 on the left):
    ///
    /// - `xxxx xxxx x0xx 0000` Not ready to switch on
    /// - `xxxx xxxx x1xx 0000` Switch on disabled
    /// - `xxxx xxxx x01x 0001` Ready to switch on
    /// - `xxxx xxxx x01x 0011` Switched on
    /// - `xxxx xxxx x01x 0111` Operation enabled
    /// - `xxxx xxxx x00x 0111` Quick stop active
    /// - `xxxx xxxx x0xx 1111` Fault reaction active
    /// - `xxxx xxxx x0xx 1000` Fault
    pub const fn state(self) -> Result<DriveState, UndefinedStatusword> {
        let w = self.0;
        // Bits 0-3 and 6, for the states where bit 5 (quick stop) is don't care.
        match w & 0x004F {
            0x0000 => return Ok(DriveState::NotReadyToSwitchOn),
            0x0040 => return Ok(DriveState::SwitchOnDisabled),
            0x000F => return Ok(DriveState::FaultReactionActive),
            0x0008 => return Ok(DriveState::Fault),
            _ => {}
        }
        // Bits 0-3, 5 and 6.
        match w & 0x006F {
            0x0021 => Ok(DriveState::ReadyToSwitchOn),
            0x0023 => Ok(DriveState::SwitchedOn),
            0x0027 => Ok(DriveState::OperationEnabled),
            0x0007 => Ok(DriveState::QuickStopActive),
            _ => Err(UndefinedStatusword(w)),
        }
    }

    /// Bit 7: a warning is present; the drive keeps operating.
    pub const fn warning(self) -> bool {
        self.0 & SW_WARNING != 0
    }

    /// Bit 9: remote — the drive takes its controlword from the bus. Without it the
    /// drive is under local control and ignores 0x6040.
    pub const fn remote(self) -> bool {
        self.0 & SW_REMOTE != 0
    }

    /// Bit 10: target reached (its meaning depends on the mode of operation, 0x6061).
    pub const fn target_reached(self) -> bool {
        self.0 & SW_TARGET_REACHED != 0
    }

    /// Bit 11: an internal limit is active (e.g. the drive clips torque or position).
    pub const fn internal_limit_active(self) -> bool {
        self.0 & SW_INTERNAL_LIMIT != 0
    }
}

/// The standard's device control commands, as controlword (object 0x6040) values with
/// the mode-specific bits (4-6, 8, 9) clear.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Command {
    /// 0x0006: transitions 2, 6, 8 (to Ready to switch on).
    Shutdown,
    /// 0x0007: transition 3 (to Switched on).
    SwitchOn,
    /// 0x000F: transitions 4 and 16 (to Operation enabled).
    EnableOperation,
    /// 0x0000: transitions 7, 9, 10, 12 (to Switch on disabled).
    DisableVoltage,
    /// 0x0002: transitions 7, 10, 11 (quick stop from Operation enabled).
    QuickStop,
    /// 0x0007: transition 5 (Operation enabled to Switched on); the same word as
    /// [`Command::SwitchOn`].
    DisableOperation,
    /// 0x0080: transition 15. The drive acts on the rising edge of bit 7 only, so the
    /// word before it must have bit 7 low; [`Axis`] takes care of that.
    FaultReset,
}

impl Command {
    /// The controlword value of the command.
    pub const fn controlword(self) -> Controlword {
        Controlword(match self {
            Command::Shutdown => 0x0006,
            Command::SwitchOn | Command::DisableOperation => 0x0007,
            Command::EnableOperation => 0x000F,
            Command::DisableVoltage => 0x0000,
            Command::QuickStop => 0x0002,
            Command::FaultReset => CW_FAULT_RESET,
        })
    }
}

/// The controlword (object 0x6040) to write to the drive.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Controlword(pub u16);

impl Controlword {
    /// The device control command in bits 0-3 (fault reset, bit 7, excluded: it acts on
    /// its edge, which only the drive can see), decoded with the standard's patterns
    /// (x = don't care, bit 3 on the left): `x110` Shutdown, `0111` Switch on (the same
    /// word as Disable operation), `1111` Enable operation, `xx0x` Disable voltage,
    /// `x01x` Quick stop. For the drive side (an emulated drive).
    pub const fn command(self) -> Command {
        let w = self.0;
        if w & 0x0002 == 0 {
            Command::DisableVoltage
        } else if w & 0x0004 == 0 {
            Command::QuickStop
        } else if w & 0x0001 == 0 {
            Command::Shutdown
        } else if w & 0x0008 == 0 {
            Command::SwitchOn
        } else {
            Command::EnableOperation
        }
    }

    /// The raw value for the process data.
    pub const fn bits(self) -> u16 {
        self.0
    }

    /// Bit 7, fault reset.
    pub const fn fault_reset(self) -> bool {
        self.0 & CW_FAULT_RESET != 0
    }
}

/// The state an [`Axis`] should bring its drive to.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Target {
    /// Operation enabled: torque on, following setpoints.
    Enabled,
    /// Switch on disabled, walked down through Switched on and Ready to switch on so
    /// the drive applies its disable-operation (0x605C) and shutdown (0x605B) reactions.
    #[default]
    Disabled,
    /// Quick stop: the drive decelerates per its quick stop option code (0x605A).
    QuickStop,
}

/// A fault of one axis: the drive's own, or one this driver detected.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum AxisFault {
    /// The drive is in Fault reaction active or Fault; `error_code` is its 0x603F.
    #[error("drive fault ({state}), error code 0x{error_code:04X} (0x603F)")]
    Drive {
        /// Fault reaction active or Fault.
        state: DriveState,
        /// The drive's error code, object 0x603F.
        error_code: u16,
    },
    /// The drive went between two states the standard does not connect.
    #[error("illegal transition from {from} to {to}")]
    IllegalTransition {
        /// The state seen in the previous cycle.
        from: DriveState,
        /// The state seen in this cycle.
        to: DriveState,
    },
}

/// What [`Axis::step`] decided for this cycle.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Step {
    /// The controlword to send this cycle.
    pub controlword: Controlword,
    /// The axis's fault, if any: the drive's (while it is in a fault state) or a latched
    /// illegal transition (until [`Axis::reset`]).
    pub fault: Option<AxisFault>,
}

/// Progress of a requested fault reset: bit 7 low for one cycle, then high.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum ResetPhase {
    /// No reset pending.
    Idle,
    /// Send bit 7 low this cycle.
    Low,
    /// Send bit 7 high this cycle (the rising edge).
    High,
    /// Edge sent; hold bit 7 high while the drive stays in Fault, never re-raising it.
    Held,
}

/// The per-axis CiA 402 state machine driver.
///
/// Call [`Axis::step`] once per bus cycle with the state decoded from the statusword
/// (0x6041) and the error code (0x603F); send the returned controlword (0x6040). It walks
/// the drive to the [`Target`] one transition per cycle, never resets a fault on its own
/// (only after [`Axis::reset`], as one rising edge of bit 7), and latches a transition
/// the standard does not allow as an [`AxisFault::IllegalTransition`]. While that is
/// latched the axis commands a quick stop whatever the target, until [`Axis::reset`].
#[derive(Debug, Clone)]
pub struct Axis {
    target: Target,
    last: Option<DriveState>,
    latched: Option<AxisFault>,
    reset: ResetPhase,
}

impl Default for Axis {
    fn default() -> Self {
        Axis::new()
    }
}

impl Axis {
    /// An axis with target [`Target::Disabled`] that has not seen its drive yet.
    pub const fn new() -> Axis {
        Axis {
            target: Target::Disabled,
            last: None,
            latched: None,
            reset: ResetPhase::Idle,
        }
    }

    /// Sets the state to bring the drive to.
    pub fn set_target(&mut self, target: Target) {
        self.target = target;
    }

    /// The state the drive is being brought to.
    pub const fn target(&self) -> Target {
        self.target
    }

    /// The state seen in the last [`Axis::step`], `None` before the first.
    pub const fn state(&self) -> Option<DriveState> {
        self.last
    }

    /// Whether the drive was in Operation enabled at the last step with no fault
    /// latched: only then do its setpoints act.
    pub fn is_enabled(&self) -> bool {
        self.last == Some(DriveState::OperationEnabled) && self.latched.is_none()
    }

    /// The latched illegal-transition fault, if any.
    pub const fn latched_fault(&self) -> Option<AxisFault> {
        self.latched
    }

    /// Asks for a fault reset: clears a latched illegal transition now and, if the drive
    /// is in Fault, sends one rising edge of controlword bit 7 (one cycle low, then
    /// high). Holding the request does not repeat the edge; call again for another.
    /// A request made outside Fault lapses at the next step. Once the drive is out of
    /// Fault (transition 15) the walk to the target resumes, so a reset with target
    /// [`Target::Enabled`] re-enables the axis.
    pub fn reset(&mut self) {
        self.latched = None;
        self.reset = ResetPhase::Low;
    }

    /// One cycle: `state` decoded from the statusword (0x6041), `error_code` the drive's
    /// 0x603F. Returns the controlword (0x6040) to send and the axis's fault.
    pub fn step(&mut self, state: DriveState, error_code: u16) -> Step {
        if let Some(from) = self.last
            && !from.may_go_to(state)
            && self.latched.is_none()
        {
            self.latched = Some(AxisFault::IllegalTransition { from, to: state });
        }
        self.last = Some(state);

        let controlword = if state.is_fault() {
            self.fault_controlword(state)
        } else {
            // Out of Fault: a finished or unneeded reset ends here.
            self.reset = ResetPhase::Idle;
            let target = if self.latched.is_some() {
                Target::QuickStop
            } else {
                self.target
            };
            Self::walk(state, target).controlword()
        };

        let fault = if state.is_fault() {
            Some(AxisFault::Drive { state, error_code })
        } else {
            self.latched
        };
        Step { controlword, fault }
    }

    /// The controlword while the drive is in a fault state: everything low except the
    /// fault-reset edge when one was asked for.
    fn fault_controlword(&mut self, state: DriveState) -> Controlword {
        let low = Command::DisableVoltage.controlword();
        if state == DriveState::FaultReactionActive {
            // The reaction is still running: a reset now would be lost; keep the request
            // for when the drive reaches Fault.
            return low;
        }
        match self.reset {
            ResetPhase::Idle => low,
            ResetPhase::Low => {
                self.reset = ResetPhase::High;
                low
            }
            ResetPhase::High => {
                self.reset = ResetPhase::Held;
                Command::FaultReset.controlword()
            }
            ResetPhase::Held => Command::FaultReset.controlword(),
        }
    }

    /// The command that moves a drive in the non-fault `state` one transition towards
    /// `target`.
    fn walk(state: DriveState, target: Target) -> Command {
        use DriveState::*;
        match target {
            Target::Enabled => match state {
                // Transition 1 is automatic: wait without asking for anything.
                NotReadyToSwitchOn => Command::DisableVoltage,
                SwitchOnDisabled => Command::Shutdown,  // 2
                ReadyToSwitchOn => Command::SwitchOn,   // 3
                SwitchedOn => Command::EnableOperation, // 4
                OperationEnabled => Command::EnableOperation,
                // 16 where the quick stop option code (0x605A) allows it; otherwise the
                // drive finishes the stop, goes to Switch on disabled (12) and is walked
                // up from there, without cutting torque mid-ramp.
                QuickStopActive => Command::EnableOperation,
                FaultReactionActive | Fault => Command::DisableVoltage,
            },
            Target::Disabled => match state {
                OperationEnabled => Command::DisableOperation, // 5
                SwitchedOn => Command::Shutdown,               // 6
                ReadyToSwitchOn => Command::DisableVoltage,    // 7
                QuickStopActive => Command::DisableVoltage,    // 12
                NotReadyToSwitchOn | SwitchOnDisabled | FaultReactionActive | Fault => {
                    Command::DisableVoltage
                }
            },
            // 11 from Operation enabled, 7 and 10 from Ready / Switched on; held in
            // Quick stop active until the drive finishes (12).
            Target::QuickStop => Command::QuickStop,
        }
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn drive_side_encoding_round_trips_through_the_decoders() {
        for state in DriveState::ALL {
            assert_eq!(Statusword::of_state(state).state(), Ok(state), "{state}");
        }
        for command in [
            Command::Shutdown,
            Command::SwitchOn,
            Command::EnableOperation,
            Command::DisableVoltage,
            Command::QuickStop,
        ] {
            assert_eq!(command.controlword().command(), command);
        }
        assert_eq!(
            Command::DisableOperation.controlword().command(),
            Command::SwitchOn
        );
    }

    use super::DriveState::*;
    use super::*;

    /// A statusword for `state`, with the don't-care bits set as given.
    fn sw(state: DriveState) -> Statusword {
        Statusword(match state {
            NotReadyToSwitchOn => 0x0000,
            SwitchOnDisabled => 0x0040,
            ReadyToSwitchOn => 0x0021,
            SwitchedOn => 0x0023,
            OperationEnabled => 0x0027,
            QuickStopActive => 0x0007,
            FaultReactionActive => 0x000F,
            Fault => 0x0008,
        })
    }

    #[test]
    fn statusword_decodes_every_state_whatever_the_dont_care_bits() {
        // Bits outside 0-3, 5, 6, plus bit 5 where it is don't care.
        let noise = [0x0000u16, 0x0010, 0x0080, 0x0200, 0x0400, 0x0800, 0xFF90];
        for state in DriveState::ALL {
            for n in noise {
                let mut w = sw(state).0 | n;
                assert_eq!(Statusword(w).state(), Ok(state), "0x{w:04X}");
                if matches!(
                    state,
                    NotReadyToSwitchOn | SwitchOnDisabled | FaultReactionActive | Fault
                ) {
                    w |= 0x0020;
                    assert_eq!(Statusword(w).state(), Ok(state), "0x{w:04X}");
                }
            }
        }
    }

    #[test]
    fn statusword_patterns_outside_the_standard_are_refused() {
        // Bit 6 with bit 0: no state; ready with bit 6 set; 0x0001 (quick stop clear).
        for w in [0x0041u16, 0x0061, 0x0001, 0x0003, 0x0004] {
            assert_eq!(Statusword(w).state(), Err(UndefinedStatusword(w)));
        }
        assert_eq!(
            UndefinedStatusword(0x41).to_string(),
            "statusword 0x0041 (0x6041) matches no CiA 402 state"
        );
    }

    #[test]
    fn statusword_flags() {
        let w = Statusword(0x0027 | 0x0080 | 0x0200 | 0x0400 | 0x0800);
        assert!(w.warning() && w.remote() && w.target_reached() && w.internal_limit_active());
        let w = Statusword(0x0027);
        assert!(!w.warning() && !w.remote() && !w.target_reached());
        assert!(!w.internal_limit_active());
    }

    #[test]
    fn controlword_values_are_the_standards() {
        let cw = |c: Command| c.controlword().bits();
        assert_eq!(cw(Command::Shutdown), 0x0006);
        assert_eq!(cw(Command::SwitchOn), 0x0007);
        assert_eq!(cw(Command::EnableOperation), 0x000F);
        assert_eq!(cw(Command::DisableVoltage), 0x0000);
        assert_eq!(cw(Command::QuickStop), 0x0002);
        assert_eq!(cw(Command::DisableOperation), 0x0007);
        assert_eq!(cw(Command::FaultReset), 0x0080);
        assert!(Command::FaultReset.controlword().fault_reset());
    }

    /// The standard's numbered transitions.
    const LEGAL: [(u8, DriveState, DriveState); 16] = [
        (1, NotReadyToSwitchOn, SwitchOnDisabled),
        (2, SwitchOnDisabled, ReadyToSwitchOn),
        (3, ReadyToSwitchOn, SwitchedOn),
        (4, SwitchedOn, OperationEnabled),
        (5, OperationEnabled, SwitchedOn),
        (6, SwitchedOn, ReadyToSwitchOn),
        (7, ReadyToSwitchOn, SwitchOnDisabled),
        (8, OperationEnabled, ReadyToSwitchOn),
        (9, OperationEnabled, SwitchOnDisabled),
        (10, SwitchedOn, SwitchOnDisabled),
        (11, OperationEnabled, QuickStopActive),
        (12, QuickStopActive, SwitchOnDisabled),
        (13, OperationEnabled, FaultReactionActive),
        (14, FaultReactionActive, Fault),
        (15, Fault, SwitchOnDisabled),
        (16, QuickStopActive, OperationEnabled),
    ];

    /// An axis that has seen `state` once.
    fn axis_in(state: DriveState, target: Target) -> Axis {
        let mut axis = Axis::new();
        axis.set_target(target);
        let step = axis.step(state, 0);
        assert_eq!(step.fault.is_some(), state.is_fault());
        axis
    }

    #[test]
    fn transition_0_any_first_state_is_accepted() {
        // Power on (0) happens before the master sees the drive; it may also join a
        // drive that is already running.
        for state in DriveState::ALL {
            let mut axis = Axis::new();
            let step = axis.step(state, 0);
            assert!(!matches!(
                step.fault,
                Some(AxisFault::IllegalTransition { .. })
            ));
        }
    }

    #[test]
    fn transitions_1_to_16_are_legal_and_numbered() {
        for (number, from, to) in LEGAL {
            assert_eq!(from.transition_to(to), Some(Some(number)), "{from} -> {to}");
            let mut axis = axis_in(from, Target::Disabled);
            let step = axis.step(to, 0);
            assert!(
                !matches!(step.fault, Some(AxisFault::IllegalTransition { .. })),
                "transition {number}: {from} -> {to}"
            );
        }
    }

    #[test]
    fn transition_13_from_every_non_fault_state_and_straight_to_fault() {
        for from in DriveState::ALL.into_iter().filter(|s| !s.is_fault()) {
            assert_eq!(from.transition_to(FaultReactionActive), Some(Some(13)));
            // A fast fault reaction: 13 and 14 between two samples.
            assert!(from.may_go_to(Fault), "{from} -> Fault");
        }
        assert!(!Fault.may_go_to(FaultReactionActive));
    }

    #[test]
    fn staying_is_legal() {
        for state in DriveState::ALL {
            assert_eq!(state.transition_to(state), Some(None));
        }
    }

    #[test]
    fn every_other_transition_is_illegal_and_latched() {
        let legal = |from: DriveState, to: DriveState| {
            from == to
                || LEGAL.iter().any(|&(_, f, t)| f == from && t == to)
                || (!from.is_fault() && to.is_fault())
        };
        let mut illegal = 0;
        for from in DriveState::ALL {
            for to in DriveState::ALL {
                assert_eq!(from.may_go_to(to), legal(from, to), "{from} -> {to}");
                if legal(from, to) {
                    continue;
                }
                illegal += 1;
                let mut axis = axis_in(from, Target::Enabled);
                let step = axis.step(to, 0);
                let own = AxisFault::IllegalTransition { from, to };
                if to.is_fault() {
                    assert!(matches!(step.fault, Some(AxisFault::Drive { .. })));
                } else {
                    assert_eq!(step.fault, Some(own));
                }
                assert_eq!(axis.latched_fault(), Some(own));
            }
        }
        // 64 pairs less 8 stays, 16 numbered, 5 more of 13 (from the other non-fault
        // states) and 6 straight to Fault (13 and 14 in one sample).
        assert_eq!(illegal, 64 - 8 - 16 - 5 - 6);
    }

    #[test]
    fn operation_enabled_to_not_ready_is_illegal_and_stops_the_axis() {
        let mut axis = axis_in(OperationEnabled, Target::Enabled);
        let step = axis.step(NotReadyToSwitchOn, 0);
        let fault = AxisFault::IllegalTransition {
            from: OperationEnabled,
            to: NotReadyToSwitchOn,
        };
        assert_eq!(step.fault, Some(fault));
        assert_eq!(
            fault.to_string(),
            "illegal transition from Operation enabled to Not ready to switch on"
        );
        // Latched: quick stop whatever the target, reported every cycle.
        let step = axis.step(SwitchOnDisabled, 0);
        assert_eq!(step.controlword, Command::QuickStop.controlword());
        assert_eq!(step.fault, Some(fault));
        assert!(!axis.is_enabled());
        // The first illegal transition stays latched.
        axis.step(NotReadyToSwitchOn, 0);
        axis.step(SwitchOnDisabled, 0);
        assert_eq!(axis.latched_fault(), Some(fault));
        // Only a reset clears it; then the walk resumes.
        axis.reset();
        let step = axis.step(SwitchOnDisabled, 0);
        assert_eq!(step.fault, None);
        assert_eq!(step.controlword, Command::Shutdown.controlword());
    }

    #[test]
    fn enable_walks_one_transition_per_cycle() {
        let mut axis = Axis::new();
        axis.set_target(Target::Enabled);
        let walk = [
            (NotReadyToSwitchOn, 0x0000), // 1 is automatic
            (SwitchOnDisabled, 0x0006),   // 2
            (SwitchOnDisabled, 0x0006),   // the drive has not moved yet: same command
            (ReadyToSwitchOn, 0x0007),    // 3
            (SwitchedOn, 0x000F),         // 4
            (OperationEnabled, 0x000F),   // held
        ];
        for (state, cw) in walk {
            let step = axis.step(state, 0);
            assert_eq!(step.controlword.bits(), cw, "in {state}");
            assert_eq!(step.fault, None);
        }
        assert!(axis.is_enabled());
    }

    #[test]
    fn disable_walks_down_through_5_6_7() {
        let mut axis = axis_in(OperationEnabled, Target::Enabled);
        axis.set_target(Target::Disabled);
        let walk = [
            (OperationEnabled, 0x0007), // 5
            (SwitchedOn, 0x0006),       // 6
            (ReadyToSwitchOn, 0x0000),  // 7
            (SwitchOnDisabled, 0x0000), // held
        ];
        for (state, cw) in walk {
            let step = axis.step(state, 0);
            assert_eq!(step.controlword.bits(), cw, "in {state}");
            assert_eq!(step.fault, None);
        }
        assert!(!axis.is_enabled());
    }

    #[test]
    fn disabled_target_leaves_quick_stop_by_12() {
        let mut axis = axis_in(QuickStopActive, Target::Disabled);
        assert_eq!(axis.step(QuickStopActive, 0).controlword.bits(), 0x0000);
    }

    #[test]
    fn quick_stop_from_operation_enabled_11_then_12() {
        let mut axis = axis_in(OperationEnabled, Target::Enabled);
        axis.set_target(Target::QuickStop);
        let step = axis.step(OperationEnabled, 0);
        assert_eq!(step.controlword.bits(), 0x0002); // 11
        // Held while the drive decelerates.
        let step = axis.step(QuickStopActive, 0);
        assert_eq!(step.controlword.bits(), 0x0002);
        assert_eq!(step.fault, None);
        // Stop done (0x605A 1-4): 12, and the quick stop stays requested.
        let step = axis.step(SwitchOnDisabled, 0);
        assert_eq!(step.controlword.bits(), 0x0002);
        assert_eq!(step.fault, None);
        assert!(!axis.is_enabled());
    }

    #[test]
    fn quick_stop_from_ready_and_switched_on_7_and_10() {
        for state in [ReadyToSwitchOn, SwitchedOn] {
            let mut axis = axis_in(state, Target::QuickStop);
            assert_eq!(axis.step(state, 0).controlword.bits(), 0x0002);
            assert_eq!(axis.step(SwitchOnDisabled, 0).fault, None);
        }
    }

    #[test]
    fn reenable_from_quick_stop_16_or_through_12() {
        // Option codes 5-8: the drive stays in Quick stop active and takes 16.
        let mut axis = axis_in(QuickStopActive, Target::Enabled);
        assert_eq!(axis.step(QuickStopActive, 0).controlword.bits(), 0x000F);
        assert_eq!(axis.step(OperationEnabled, 0).fault, None);
        assert!(axis.is_enabled());
        // Option codes 1-4: the drive goes on to Switch on disabled and is walked up.
        let mut axis = axis_in(QuickStopActive, Target::Enabled);
        let step = axis.step(SwitchOnDisabled, 0);
        assert_eq!(step.controlword.bits(), 0x0006);
        assert_eq!(step.fault, None);
    }

    #[test]
    fn fault_is_reported_with_its_error_code_and_not_reset_on_its_own() {
        let mut axis = axis_in(OperationEnabled, Target::Enabled);
        let step = axis.step(FaultReactionActive, 0x7500);
        assert_eq!(
            step.fault,
            Some(AxisFault::Drive {
                state: FaultReactionActive,
                error_code: 0x7500
            })
        );
        assert_eq!(step.controlword.bits(), 0x0000);
        for _ in 0..10 {
            let step = axis.step(Fault, 0x7500);
            assert_eq!(
                step.controlword.bits(),
                0x0000,
                "no reset without a request"
            );
            assert_eq!(
                step.fault,
                Some(AxisFault::Drive {
                    state: Fault,
                    error_code: 0x7500
                })
            );
        }
        assert_eq!(
            axis.step(Fault, 0x7500).fault.map(|f| f.to_string()),
            Some("drive fault (Fault), error code 0x7500 (0x603F)".to_string())
        );
    }

    #[test]
    fn fault_reset_is_one_rising_edge_of_bit_7() {
        let mut axis = axis_in(Fault, Target::Enabled);
        axis.reset();
        // One cycle low, then high.
        assert_eq!(axis.step(Fault, 0x2310).controlword.bits(), 0x0000);
        assert_eq!(axis.step(Fault, 0x2310).controlword.bits(), 0x0080);
        // The drive still in Fault (fault still present): bit 7 is held high, no
        // second edge.
        for _ in 0..5 {
            assert_eq!(axis.step(Fault, 0x2310).controlword.bits(), 0x0080);
        }
        // A second request lowers bit 7 for one cycle, then raises it again.
        axis.reset();
        assert_eq!(axis.step(Fault, 0x2310).controlword.bits(), 0x0000);
        assert_eq!(axis.step(Fault, 0x2310).controlword.bits(), 0x0080);
        // Transition 15: out of Fault, the reset is over and the walk resumes.
        let step = axis.step(SwitchOnDisabled, 0);
        assert_eq!(step.fault, None);
        assert_eq!(step.controlword.bits(), 0x0006);
        // A later fault is not reset by the old request.
        axis.step(FaultReactionActive, 0x2310);
        for _ in 0..5 {
            assert_eq!(axis.step(Fault, 0x2310).controlword.bits(), 0x0000);
        }
    }

    #[test]
    fn fault_reset_waits_for_the_fault_reaction_to_end() {
        let mut axis = axis_in(FaultReactionActive, Target::Disabled);
        axis.reset();
        assert_eq!(axis.step(FaultReactionActive, 1).controlword.bits(), 0x0000);
        assert_eq!(axis.step(FaultReactionActive, 1).controlword.bits(), 0x0000);
        assert_eq!(axis.step(Fault, 1).controlword.bits(), 0x0000);
        assert_eq!(axis.step(Fault, 1).controlword.bits(), 0x0080);
    }

    #[test]
    fn reset_outside_fault_sends_no_edge() {
        let mut axis = axis_in(SwitchOnDisabled, Target::Disabled);
        axis.reset();
        for _ in 0..3 {
            assert!(!axis.step(SwitchOnDisabled, 0).controlword.fault_reset());
        }
        // Nor later, when a fault comes.
        axis.step(Fault, 1);
        assert!(!axis.step(Fault, 1).controlword.fault_reset());
    }
}
