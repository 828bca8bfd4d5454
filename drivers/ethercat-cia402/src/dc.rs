//! Distributed clocks: the SyncManager parameter objects 0x1C32 (SM2, outputs) and
//! 0x1C33 (SM3, inputs) of ETG.1020 / ETG.6010 (CiA 402 drive profile for EtherCAT),
//! as the master writes them and the emulator serves them.

/// SM output parameter (SM2, the RxPDO the master writes), ETG.1020 clause 5 / ETG.6010.
pub const SM_OUTPUT_PARAMETER: u16 = 0x1C32;
/// SM input parameter (SM3, the TxPDO the master reads).
pub const SM_INPUT_PARAMETER: u16 = 0x1C33;

/// Subindices of 0x1C32 / 0x1C33.
pub mod sub {
    /// Sync mode (u16, [`super::sync_mode`]); writable in PRE-OP.
    pub const SYNC_MODE: u8 = 0x01;
    /// Cycle time (u32, ns).
    pub const CYCLE_TIME: u8 = 0x02;
    /// Shift time (u32, ns): SYNC0 to outputs valid / inputs latched.
    pub const SHIFT_TIME: u8 = 0x03;
    /// Sync modes supported (u16, bit field, see [`super::sync_mode_supported`]).
    pub const SYNC_MODES_SUPPORTED: u8 = 0x04;
    /// Minimum cycle time (u32, ns).
    pub const MIN_CYCLE_TIME: u8 = 0x05;
    /// Calc and copy time (u32, ns).
    pub const CALC_AND_COPY_TIME: u8 = 0x06;
    /// SM-event missed counter (u16).
    pub const SM_EVENT_MISSED: u8 = 0x0B;
    /// Cycle time too small counter (u16).
    pub const CYCLE_TIME_TOO_SMALL: u8 = 0x0C;
    /// Sync error (BOOL, one byte).
    pub const SYNC_ERROR: u8 = 0x20;
}

/// Values of 0x1C32:01 / 0x1C33:01 (ETG.1020 table "sync mode").
pub mod sync_mode {
    /// Free run: the application runs on its own timer.
    pub const FREE_RUN: u16 = 0;
    /// Synchronous with the SM2 (outputs) event: the frame's arrival.
    pub const SM_SYNCHRONOUS: u16 = 1;
    /// Synchronous with the distributed clocks' SYNC0 event.
    pub const DC_SYNC0: u16 = 2;
    /// Synchronous with SYNC1.
    pub const DC_SYNC1: u16 = 3;
}

/// Whether 0x1C32:04 `supported` (ETG.1020: bit 0 free run, bit 1 synchronous with
/// the SM event, bits 2-3 DC type: 01 SYNC0, 10 SYNC1, 11 subordinated) allows sync
/// mode `mode`.
pub const fn sync_mode_supported(supported: u16, mode: u16) -> bool {
    let dc = (supported >> 2) & 0x3;
    match mode {
        sync_mode::FREE_RUN => supported & 0x1 != 0,
        sync_mode::SM_SYNCHRONOUS => supported & 0x2 != 0,
        sync_mode::DC_SYNC0 => dc == 0b01 || dc == 0b11,
        sync_mode::DC_SYNC1 => dc == 0b10 || dc == 0b11,
        _ => false,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn supported_modes_follow_the_bit_field() {
        // Free run, SM-synchronous, DC SYNC0.
        let s = 0x0007;
        assert!(sync_mode_supported(s, sync_mode::FREE_RUN));
        assert!(sync_mode_supported(s, sync_mode::SM_SYNCHRONOUS));
        assert!(sync_mode_supported(s, sync_mode::DC_SYNC0));
        assert!(!sync_mode_supported(s, sync_mode::DC_SYNC1));
        assert!(!sync_mode_supported(s, 7));
        // No DC at all.
        assert!(!sync_mode_supported(0x0003, sync_mode::DC_SYNC0));
    }
}
