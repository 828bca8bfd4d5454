//! The drive side of one CiA 402 (IEC 61800-7-201) servo axis: its object dictionary,
//! the power drive state machine (the bit layout is the master-side core's,
//! `microrobot_ethercat_cia402::cia402`), the CST and CSP modes, and the encoder and
//! torque scaling between the plant's joint SI units and the drive's units.

use std::f64::consts::TAU;

use microrobot_ethercat_cia402::cia402::{Command, Controlword, DriveState, Statusword};

use microrobot_ethercat_cia402::dc::{SM_INPUT_PARAMETER, SM_OUTPUT_PARAMETER, sub, sync_mode};

use crate::config::DriveConfig;
use crate::od::{
    Access, Mappable, ObjectDictionary, RXPDO_MAP, SM2_ASSIGN, SM3_ASSIGN, TXPDO_MAP, mapping,
};

/// Modes of operation (0x6060): cyclic synchronous position.
pub const MODE_CSP: i8 = 8;
/// Modes of operation (0x6060): cyclic synchronous torque.
pub const MODE_CST: i8 = 10;
/// Error code (0x603F) the drive latches when process data stop while it is enabled
/// (CiA 402 0x6007 abort connection reaction; 0x8130: heartbeat/life guard error).
pub const ERROR_COMMUNICATION: u16 = 0x8130;
/// 0x1C32:04 / 0x1C33:04 of every emulated drive: free run (bit 0), synchronous with
/// the SM event (bit 1), DC SYNC0 (bits 2-3 = 01).
pub const SYNC_MODES_SUPPORTED: u16 = 0x0007;
/// Speed (rad/s, joint side) under which a quick stop counts as done.
const QUICK_STOP_DONE_RAD_S: f64 = 1e-3;

/// One emulated drive.
#[derive(Debug, Clone)]
pub(crate) struct Drive {
    pub cfg: DriveConfig,
    pub od: ObjectDictionary,
    state: DriveState,
    last_controlword: u16,
    /// Joint torque applied in the last step (N·m).
    torque_nm: f64,
    limited: bool,
}

impl Drive {
    pub fn new(cfg: &DriveConfig) -> Drive {
        let mut od = ObjectDictionary::default();
        use Access::*;
        use Mappable as M;
        // CiA 301 communication area.
        // 0x1000 device type: profile 402, servo drive (CiA 402 6.1).
        od.insert(0x1000, 0, &0x0002_0192u32.to_le_bytes(), Ro, M::No);
        od.insert(0x1008, 0, cfg.name.as_bytes(), Ro, M::No);
        od.insert(0x1018, 0, &[4], Ro, M::No);
        let id = cfg.identity;
        for (sub, v) in [id.vendor_id, id.product_code, id.revision, id.serial]
            .into_iter()
            .enumerate()
        {
            od.insert(0x1018, sub as u8 + 1, &v.to_le_bytes(), Ro, M::No);
        }
        let rx = [
            mapping(0x6040, 0, 16),
            mapping(0x6071, 0, 16),
            mapping(0x607A, 0, 32),
        ];
        let tx = [
            mapping(0x6041, 0, 16),
            mapping(0x6064, 0, 32),
            mapping(0x606C, 0, 32),
            mapping(0x6077, 0, 16),
            mapping(0x603F, 0, 16),
        ];
        for (index, entries) in [(RXPDO_MAP, &rx[..]), (TXPDO_MAP, &tx[..])] {
            od.insert(index, 0, &[entries.len() as u8], RwPreOp, M::No);
            for sub in 1..=8u8 {
                let v = entries.get(usize::from(sub) - 1).copied().unwrap_or(0);
                od.insert(index, sub, &v.to_le_bytes(), RwPreOp, M::No);
            }
        }
        for (index, pdo) in [(SM2_ASSIGN, RXPDO_MAP), (SM3_ASSIGN, TXPDO_MAP)] {
            od.insert(index, 0, &[1], RwPreOp, M::No);
            od.insert(index, 1, &pdo.to_le_bytes(), RwPreOp, M::No);
        }
        // SyncManager parameters (ETG.1020 / ETG.6010): SM2 outputs, SM3 inputs. Free
        // run until the master asks for more; free run, SM-synchronous and DC SYNC0
        // supported.
        for index in [SM_OUTPUT_PARAMETER, SM_INPUT_PARAMETER] {
            od.insert(index, 0, &[sub::SYNC_ERROR], Ro, M::No);
            od.insert(
                index,
                sub::SYNC_MODE,
                &sync_mode::FREE_RUN.to_le_bytes(),
                RwPreOp,
                M::No,
            );
            od.insert(index, sub::CYCLE_TIME, &0u32.to_le_bytes(), Rw, M::No);
            od.insert(index, sub::SHIFT_TIME, &0u32.to_le_bytes(), Ro, M::No);
            od.insert(
                index,
                sub::SYNC_MODES_SUPPORTED,
                &SYNC_MODES_SUPPORTED.to_le_bytes(),
                Ro,
                M::No,
            );
            od.insert(
                index,
                sub::MIN_CYCLE_TIME,
                &cfg.min_cycle_time_ns.to_le_bytes(),
                Ro,
                M::No,
            );
            od.insert(
                index,
                sub::CALC_AND_COPY_TIME,
                &cfg.calc_copy_time_ns.to_le_bytes(),
                Ro,
                M::No,
            );
            od.insert(index, sub::SM_EVENT_MISSED, &0u16.to_le_bytes(), Ro, M::No);
            od.insert(
                index,
                sub::CYCLE_TIME_TOO_SMALL,
                &0u16.to_le_bytes(),
                Ro,
                M::No,
            );
            od.insert(index, sub::SYNC_ERROR, &[0], Ro, M::No);
        }
        // CiA 402 device profile area.
        od.insert(0x603F, 0, &0u16.to_le_bytes(), Ro, M::Tx);
        od.insert(0x6040, 0, &0u16.to_le_bytes(), Rw, M::Rx);
        od.insert(0x6041, 0, &0u16.to_le_bytes(), Ro, M::Tx);
        od.insert(0x6060, 0, &[0], Rw, M::Rx);
        od.insert(0x6061, 0, &[0], Ro, M::Tx);
        od.insert(0x6064, 0, &0i32.to_le_bytes(), Ro, M::Tx);
        od.insert(0x606C, 0, &0i32.to_le_bytes(), Ro, M::Tx);
        od.insert(0x6071, 0, &0i16.to_le_bytes(), Rw, M::Rx);
        od.insert(
            0x6072,
            0,
            &cfg.max_torque_per_mille.to_le_bytes(),
            Rw,
            M::Rx,
        );
        let rated_mnm = (cfg.rated_torque_nm * 1000.0)
            .round()
            .clamp(0.0, u32::MAX as f64) as u32;
        // 0x6076 rated torque, in mN·m (CiA 402 6.8.1).
        od.insert(0x6076, 0, &rated_mnm.to_le_bytes(), Ro, M::No);
        od.insert(0x6077, 0, &0i16.to_le_bytes(), Ro, M::Tx);
        od.insert(0x607A, 0, &0i32.to_le_bytes(), Rw, M::Rx);
        // 0x6502 supported drive modes: bit 7 CSP, bit 9 CST.
        od.insert(
            0x6502,
            0,
            &((1u32 << 7) | (1 << 9)).to_le_bytes(),
            Ro,
            M::No,
        );
        let mut d = Drive {
            cfg: cfg.clone(),
            od,
            state: DriveState::SwitchOnDisabled,
            last_controlword: 0,
            torque_nm: 0.0,
            limited: false,
        };
        d.publish_status();
        d
    }

    pub fn state(&self) -> DriveState {
        self.state
    }

    /// Joint torque applied in the last step (N·m).
    pub fn torque_nm(&self) -> f64 {
        self.torque_nm
    }

    /// Replaces the identity in 0x1018 (wrong-identity fault).
    pub fn set_identity(&mut self, vendor_id: u32, product_code: u32) {
        self.od.set(0x1018, 1, &vendor_id.to_le_bytes());
        self.od.set(0x1018, 2, &product_code.to_le_bytes());
    }

    /// A fault detected by the drive (transition 13): error code into 0x603F, fault
    /// reaction; the next step completes it to Fault (transition 14).
    pub fn fault(&mut self, error_code: u16) {
        if !self.state.is_fault() {
            self.state = DriveState::FaultReactionActive;
        }
        self.od.set(0x603F, 0, &error_code.to_le_bytes());
        self.torque_nm = 0.0;
        self.publish_status();
    }

    /// Process data stopped reaching the drive (its EtherCAT state left OP): an
    /// enabled power stage is a fault (CiA 402 0x6007 reaction "fault").
    pub fn outputs_lost(&mut self) {
        if matches!(
            self.state,
            DriveState::OperationEnabled | DriveState::QuickStopActive
        ) {
            self.fault(ERROR_COMMUNICATION);
        }
    }

    /// Runs the state machine on the controlword (0x6040) if `outputs_valid` (the
    /// device is in OP) and returns the joint torque to apply (N·m) and whether the
    /// brake holds the axis. `q`, `qd`: joint position and velocity now.
    pub fn control(&mut self, outputs_valid: bool, q: f64, qd: f64) -> (f64, bool) {
        if self.state == DriveState::FaultReactionActive {
            self.state = DriveState::Fault;
        }
        let before = self.state;
        if outputs_valid {
            let cw = self.od.u16(0x6040, 0);
            let rising_reset =
                Controlword(cw).fault_reset() && !Controlword(self.last_controlword).fault_reset();
            self.last_controlword = cw;
            self.state = next_state(self.state, Controlword(cw).command(), rising_reset);
            if self.state == DriveState::SwitchOnDisabled && rising_reset {
                self.od.set(0x603F, 0, &0u16.to_le_bytes());
            }
        }
        let max_nm = self.per_mille_to_joint_nm(f64::from(self.od.u16(0x6072, 0)));
        let (torque, braked) = match self.state {
            DriveState::OperationEnabled => {
                let asked = match self.mode() {
                    MODE_CST => {
                        self.per_mille_to_joint_nm(f64::from(self.od.u16(0x6071, 0) as i16))
                    }
                    MODE_CSP => {
                        let target = self.counts_to_joint_rad(self.od.u32(0x607A, 0) as i32);
                        self.cfg.csp_kp_nm_per_rad * (target - q)
                            - self.cfg.csp_kd_nm_s_per_rad * qd
                    }
                    _ => 0.0,
                };
                (asked, false)
            }
            DriveState::QuickStopActive => {
                if before == DriveState::QuickStopActive && qd.abs() < QUICK_STOP_DONE_RAD_S {
                    // Quick stop option code 2: stop, then to Switch on disabled.
                    self.state = DriveState::SwitchOnDisabled;
                    (0.0, true)
                } else {
                    (-qd.signum() * max_nm, false)
                }
            }
            _ => (0.0, true),
        };
        let torque = if torque.is_finite() { torque } else { 0.0 };
        self.limited = torque.abs() > max_nm;
        self.torque_nm = torque.clamp(-max_nm, max_nm);
        (self.torque_nm, braked)
    }

    /// Writes the plant's state and the drive's state into the input objects.
    pub fn sense(&mut self, q: f64, qd: f64) {
        let counts_per_joint_rad =
            f64::from(self.cfg.encoder_counts_per_rev) * self.cfg.gear_ratio / TAU;
        // An encoder wraps: keep the low 32 bits of the count.
        let pos = (q * counts_per_joint_rad).round() as i64 as i32;
        let vel = (qd * counts_per_joint_rad)
            .round()
            .clamp(f64::from(i32::MIN), f64::from(i32::MAX)) as i32;
        let per_mille = (self.torque_nm / self.cfg.gear_ratio / self.cfg.rated_torque_nm * 1000.0)
            .round()
            .clamp(f64::from(i16::MIN), f64::from(i16::MAX)) as i16;
        self.od.set(0x6064, 0, &pos.to_le_bytes());
        self.od.set(0x606C, 0, &vel.to_le_bytes());
        self.od.set(0x6077, 0, &per_mille.to_le_bytes());
        self.publish_status();
    }

    fn mode(&self) -> i8 {
        self.od.u8(0x6061, 0) as i8
    }

    fn publish_status(&mut self) {
        let mode = self.od.u8(0x6060, 0);
        self.od.set(0x6061, 0, &[mode]);
        let mut sw = Statusword::of_state(self.state).0 | Statusword::REMOTE;
        if !matches!(
            self.state,
            DriveState::NotReadyToSwitchOn | DriveState::SwitchOnDisabled | DriveState::Fault
        ) {
            sw |= Statusword::VOLTAGE_ENABLED;
        }
        if self.limited {
            sw |= Statusword::INTERNAL_LIMIT;
        }
        self.od.set(0x6041, 0, &sw.to_le_bytes());
    }

    fn per_mille_to_joint_nm(&self, per_mille: f64) -> f64 {
        per_mille / 1000.0 * self.cfg.rated_torque_nm * self.cfg.gear_ratio
    }

    fn counts_to_joint_rad(&self, counts: i32) -> f64 {
        f64::from(counts) / f64::from(self.cfg.encoder_counts_per_rev) / self.cfg.gear_ratio * TAU
    }
}

/// The drive's reaction to a controlword command (CiA 402 figure "state machine";
/// transitions 2-12, 15, 16). Not-ready and the fault reaction are left on their own.
fn next_state(state: DriveState, command: Command, rising_reset: bool) -> DriveState {
    use DriveState::*;
    match (state, command) {
        (Fault, _) if rising_reset => SwitchOnDisabled,
        (Fault | FaultReactionActive | NotReadyToSwitchOn, _) => state,
        (_, Command::DisableVoltage) if state != QuickStopActive => SwitchOnDisabled,
        (QuickStopActive, Command::DisableVoltage) => SwitchOnDisabled,
        (OperationEnabled, Command::QuickStop) => QuickStopActive,
        (ReadyToSwitchOn | SwitchedOn, Command::QuickStop) => SwitchOnDisabled,
        (QuickStopActive, Command::EnableOperation) => OperationEnabled,
        (QuickStopActive, _) => QuickStopActive,
        (SwitchOnDisabled, Command::Shutdown) => ReadyToSwitchOn,
        (SwitchOnDisabled, _) => SwitchOnDisabled,
        (ReadyToSwitchOn, Command::SwitchOn | Command::DisableOperation) => SwitchedOn,
        (ReadyToSwitchOn, Command::EnableOperation) => SwitchedOn,
        (ReadyToSwitchOn, _) => ReadyToSwitchOn,
        (SwitchedOn, Command::EnableOperation) => OperationEnabled,
        (SwitchedOn, Command::Shutdown) => ReadyToSwitchOn,
        (SwitchedOn, _) => SwitchedOn,
        (OperationEnabled, Command::SwitchOn | Command::DisableOperation) => SwitchedOn,
        (OperationEnabled, Command::Shutdown) => ReadyToSwitchOn,
        (OperationEnabled, _) => OperationEnabled,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::DriveConfig;

    fn run(d: &mut Drive, cw: u16) -> DriveState {
        d.od.set(0x6040, 0, &cw.to_le_bytes());
        d.control(true, 0.0, 0.0);
        d.sense(0.0, 0.0);
        Statusword(d.od.u16(0x6041, 0))
            .state()
            .expect("defined statusword")
    }

    #[test]
    fn enable_sequence_fault_and_reset_follow_the_standard() {
        let mut d = Drive::new(&DriveConfig::seed_axis(0));
        assert_eq!(run(&mut d, 0x0000), DriveState::SwitchOnDisabled);
        assert_eq!(run(&mut d, 0x0006), DriveState::ReadyToSwitchOn);
        assert_eq!(run(&mut d, 0x0007), DriveState::SwitchedOn);
        assert_eq!(run(&mut d, 0x000F), DriveState::OperationEnabled);
        assert_eq!(run(&mut d, 0x0002), DriveState::QuickStopActive);
        // At standstill the quick stop completes to Switch on disabled.
        assert_eq!(run(&mut d, 0x0002), DriveState::SwitchOnDisabled);
        d.fault(0x2310);
        assert_eq!(run(&mut d, 0x0000), DriveState::Fault);
        assert_eq!(d.od.u16(0x603F, 0), 0x2310);
        assert_eq!(
            run(&mut d, 0x0080),
            DriveState::SwitchOnDisabled,
            "rising edge"
        );
        assert_eq!(d.od.u16(0x603F, 0), 0);
        d.fault(0x7500);
        assert_eq!(
            run(&mut d, 0x0080),
            DriveState::Fault,
            "bit 7 held high: no edge"
        );
        assert_eq!(run(&mut d, 0x0000), DriveState::Fault);
        assert_eq!(run(&mut d, 0x0080), DriveState::SwitchOnDisabled);
    }

    #[test]
    fn torque_is_scaled_and_limited() {
        let mut d = Drive::new(&DriveConfig::seed_axis(0));
        d.od.set(0x6060, 0, &[MODE_CST as u8]);
        for cw in [0x0006u16, 0x0007, 0x000F] {
            run(&mut d, cw);
        }
        d.od.set(0x6071, 0, &500i16.to_le_bytes());
        let (tau, braked) = d.control(true, 0.0, 0.0);
        assert!(!braked);
        // 0.5 × 1.27 N·m × gear 100.
        assert!((tau - 63.5).abs() < 1e-9, "{tau}");
        d.sense(0.0, 0.0);
        assert_eq!(d.od.u16(0x6077, 0) as i16, 500);
        d.od.set(0x6071, 0, &5000i16.to_le_bytes());
        let (tau, _) = d.control(true, 0.0, 0.0);
        assert!(
            (tau - 381.0).abs() < 1e-9,
            "clipped at 0x6072 = 3000 ‰: {tau}"
        );
    }
}
