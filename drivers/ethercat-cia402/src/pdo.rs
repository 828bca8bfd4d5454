//! The process data image of one axis and the CoE configuration that produces it, as
//! data: what the master writes over SDO in PRE-OP (CiA 402, ETG.1000.6 5.6.7) and
//! where each object sits in the cyclic image.
//!
//! RxPDO 0x1600 (master → drive, SM2), 8 bytes:
//!
//! | offset | object | |
//! |---|---|---|
//! | 0 | 0x6040 controlword | u16 |
//! | 2 | 0x6071 target torque | i16, per mille of 0x6076 |
//! | 4 | 0x607A target position | i32, counts |
//!
//! TxPDO 0x1A00 (drive → master, SM3), 14 bytes:
//!
//! | offset | object | |
//! |---|---|---|
//! | 0 | 0x6041 statusword | u16 |
//! | 2 | 0x6064 position actual | i32, counts |
//! | 6 | 0x606C velocity actual | i32, counts/s |
//! | 10 | 0x6077 torque actual | i16, per mille of 0x6076 |
//! | 12 | 0x603F error code | u16 |
//!
//! All values little endian (ETG.1000.4).

use crate::drive_file::AxisConfig;

/// RxPDO mapping object (CiA 301 0x1600).
pub const RXPDO_MAP: u16 = 0x1600;
/// TxPDO mapping object (CiA 301 0x1A00).
pub const TXPDO_MAP: u16 = 0x1A00;
/// SM2 (outputs) PDO assignment (ETG.1000.6 0x1C12).
pub const SM2_ASSIGN: u16 = 0x1C12;
/// SM3 (inputs) PDO assignment (ETG.1000.6 0x1C13).
pub const SM3_ASSIGN: u16 = 0x1C13;

/// A PDO mapping entry (CiA 301 7.5.2.36): index in bits 16-31, subindex in bits 8-15,
/// length in bits in bits 0-7.
pub const fn mapping_entry(index: u16, sub: u8, bits: u8) -> u32 {
    ((index as u32) << 16) | ((sub as u32) << 8) | bits as u32
}

/// The RxPDO entries in image order: controlword, target torque, target position.
pub const RXPDO_ENTRIES: [u32; 3] = [
    mapping_entry(0x6040, 0, 16),
    mapping_entry(0x6071, 0, 16),
    mapping_entry(0x607A, 0, 32),
];

/// The TxPDO entries in image order: statusword, position, velocity, torque, error code.
pub const TXPDO_ENTRIES: [u32; 5] = [
    mapping_entry(0x6041, 0, 16),
    mapping_entry(0x6064, 0, 32),
    mapping_entry(0x606C, 0, 32),
    mapping_entry(0x6077, 0, 16),
    mapping_entry(0x603F, 0, 16),
];

/// Bytes of the RxPDO image (outputs) per axis.
pub const RX_BYTES: usize = 8;
/// Bytes of the TxPDO image (inputs) per axis.
pub const TX_BYTES: usize = 14;

/// The length in bytes of an image mapped by `entries`.
pub const fn image_len(entries: &[u32]) -> usize {
    let mut bits = 0;
    let mut i = 0;
    while i < entries.len() {
        bits += (entries[i] & 0xFF) as usize;
        i += 1;
    }
    bits / 8
}

/// What the master sends one axis each cycle (RxPDO 0x1600).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Outputs {
    /// Controlword, 0x6040.
    pub controlword: u16,
    /// Target torque, 0x6071 (per mille of rated torque 0x6076).
    pub target_torque: i16,
    /// Target position, 0x607A (counts).
    pub target_position: i32,
}

impl Outputs {
    /// Writes the image into `out` (at least [`RX_BYTES`] long; shorter is left as is
    /// and reported false).
    pub fn encode(&self, out: &mut [u8]) -> bool {
        let Some(out) = out.get_mut(..RX_BYTES) else {
            return false;
        };
        out[0..2].copy_from_slice(&self.controlword.to_le_bytes());
        out[2..4].copy_from_slice(&self.target_torque.to_le_bytes());
        out[4..8].copy_from_slice(&self.target_position.to_le_bytes());
        true
    }
}

/// What one axis reports each cycle (TxPDO 0x1A00).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Inputs {
    /// Statusword, 0x6041.
    pub statusword: u16,
    /// Position actual, 0x6064 (counts).
    pub position: i32,
    /// Velocity actual, 0x606C (counts/s).
    pub velocity: i32,
    /// Torque actual, 0x6077 (per mille of rated torque).
    pub torque: i16,
    /// Error code, 0x603F.
    pub error_code: u16,
}

impl Inputs {
    /// Reads the image from `inp`; `None` if it is shorter than [`TX_BYTES`].
    pub fn decode(inp: &[u8]) -> Option<Inputs> {
        let b: &[u8; TX_BYTES] = inp.get(..TX_BYTES)?.try_into().ok()?;
        Some(Inputs {
            statusword: u16::from_le_bytes([b[0], b[1]]),
            position: i32::from_le_bytes([b[2], b[3], b[4], b[5]]),
            velocity: i32::from_le_bytes([b[6], b[7], b[8], b[9]]),
            torque: i16::from_le_bytes([b[10], b[11]]),
            error_code: u16::from_le_bytes([b[12], b[13]]),
        })
    }
}

/// A value written over SDO, with the object's data type.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SdoValue {
    /// UNSIGNED8.
    U8(u8),
    /// INTEGER8.
    I8(i8),
    /// UNSIGNED16.
    U16(u16),
    /// UNSIGNED32.
    U32(u32),
}

/// One SDO download of the PRE-OP configuration.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SdoWrite {
    /// Object index.
    pub index: u16,
    /// Subindex.
    pub sub: u8,
    /// Value.
    pub value: SdoValue,
    /// What it sets, for an error message.
    pub what: &'static str,
}

const fn w(index: u16, sub: u8, value: SdoValue, what: &'static str) -> SdoWrite {
    SdoWrite {
        index,
        sub,
        value,
        what,
    }
}

/// The SDO downloads that configure one axis in PRE-OP, in order: modes of operation
/// (0x6060), max torque (0x6072), then the PDO mapping the way ETG.1000.6 5.6.7 asks for
/// it: assignments cleared (0x1C12/0x1C13 sub 0 = 0), each mapping cleared, its entries
/// written, its count set, then the assignments written and enabled.
pub fn configuration_plan(axis: &AxisConfig) -> Vec<SdoWrite> {
    use SdoValue::*;
    let mut plan = vec![
        w(
            0x6060,
            0,
            I8(axis.mode.modes_of_operation()),
            "modes of operation",
        ),
        w(
            0x6072,
            0,
            U16(axis.scaling.max_torque_per_mille()),
            "max torque",
        ),
        w(SM2_ASSIGN, 0, U8(0), "RxPDO assignment (clear)"),
        w(SM3_ASSIGN, 0, U8(0), "TxPDO assignment (clear)"),
    ];
    for (map, entries, what) in [
        (RXPDO_MAP, &RXPDO_ENTRIES[..], "RxPDO mapping"),
        (TXPDO_MAP, &TXPDO_ENTRIES[..], "TxPDO mapping"),
    ] {
        plan.push(w(map, 0, U8(0), what));
        for (i, e) in entries.iter().enumerate() {
            plan.push(w(map, i as u8 + 1, U32(*e), what));
        }
        plan.push(w(map, 0, U8(entries.len() as u8), what));
    }
    plan.extend([
        w(SM2_ASSIGN, 1, U16(RXPDO_MAP), "RxPDO assignment"),
        w(SM2_ASSIGN, 0, U8(1), "RxPDO assignment"),
        w(SM3_ASSIGN, 1, U16(TXPDO_MAP), "TxPDO assignment"),
        w(SM3_ASSIGN, 0, U8(1), "TxPDO assignment"),
    ]);
    plan
}

/// The working counter a logical read-write (LRW) of the whole image returns when every
/// SubDevice takes part (ETG.1000.4 table 14): +1 per SubDevice with inputs read, +2
/// per SubDevice with outputs written. `images` are (input bytes, output bytes).
pub fn expected_working_counter(images: impl IntoIterator<Item = (usize, usize)>) -> u16 {
    images
        .into_iter()
        .map(|(i, o)| u16::from(i > 0) + 2 * u16::from(o > 0))
        .sum()
}

/// The ESC watchdog divider (register 0x0400) the master writes: 2498 gives a
/// watchdog unit of (2498 + 2) × 40 ns = 100 µs (ETG.1000.4 6.3).
pub const WATCHDOG_DIVIDER: u16 = 2498;
/// The watchdog unit with [`WATCHDOG_DIVIDER`] (ns).
pub const WATCHDOG_UNIT_NS: u64 = (WATCHDOG_DIVIDER as u64 + 2) * 40;

/// The process data watchdog time (ESC register 0x0420, in units of the divider) for a
/// drive watchdog of `ms`; `None` if it does not fit the 16-bit register or is zero.
pub fn sm_watchdog_time(ms: u32) -> Option<u16> {
    let units = u64::from(ms) * 1_000_000 / WATCHDOG_UNIT_NS;
    u16::try_from(units).ok().filter(|u| *u > 0)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::drive_file::DriveFile;

    #[test]
    fn images_have_the_documented_lengths_and_offsets() {
        assert_eq!(image_len(&RXPDO_ENTRIES), RX_BYTES);
        assert_eq!(image_len(&TXPDO_ENTRIES), TX_BYTES);
        let mut out = [0xAAu8; RX_BYTES];
        let o = Outputs {
            controlword: 0x000F,
            target_torque: -5,
            target_position: 0x0102_0304,
        };
        assert!(o.encode(&mut out));
        assert_eq!(out, [0x0F, 0, 0xFB, 0xFF, 4, 3, 2, 1]);
        assert!(!o.encode(&mut [0u8; 7]), "short image refused");
        let inp = [
            0x37, 0x02, 1, 0, 0, 0, 0xFF, 0xFF, 0xFF, 0xFF, 0x10, 0x00, 0x10, 0x23,
        ];
        assert_eq!(
            Inputs::decode(&inp),
            Some(Inputs {
                statusword: 0x0237,
                position: 1,
                velocity: -1,
                torque: 16,
                error_code: 0x2310,
            })
        );
        assert_eq!(Inputs::decode(&inp[..13]), None);
        assert_eq!(mapping_entry(0x607A, 0, 32), 0x607A_0020);
    }

    #[test]
    fn the_plan_sets_mode_limit_and_maps_before_assigning() {
        let f =
            DriveFile::from_toml_str(include_str!("../example.drive.toml"), "example.drive.toml")
                .expect("example");
        let plan = configuration_plan(&f.axes[0]);
        assert_eq!(plan[0].index, 0x6060);
        assert_eq!(plan[0].value, SdoValue::I8(10));
        // 3.8 N·m over 1.27 N·m rated: 2992 per mille, rounded down.
        assert_eq!(plan[1].value, SdoValue::U16(2992));
        let pos = |i: u16, s: u8, v: SdoValue| {
            plan.iter()
                .position(|x| x.index == i && x.sub == s && x.value == v)
                .unwrap_or_else(|| panic!("{i:#x}:{s} = {v:?} missing"))
        };
        let clear = pos(SM2_ASSIGN, 0, SdoValue::U8(0));
        let map_clear = pos(RXPDO_MAP, 0, SdoValue::U8(0));
        let entry = pos(RXPDO_MAP, 3, SdoValue::U32(0x607A_0020));
        let map_set = pos(RXPDO_MAP, 0, SdoValue::U8(3));
        let tx_set = pos(TXPDO_MAP, 0, SdoValue::U8(5));
        let assign = pos(SM2_ASSIGN, 1, SdoValue::U16(RXPDO_MAP));
        let enable = pos(SM2_ASSIGN, 0, SdoValue::U8(1));
        let enable3 = pos(SM3_ASSIGN, 0, SdoValue::U8(1));
        assert!(clear < map_clear && map_clear < entry && entry < map_set);
        assert!(map_set < assign && tx_set < assign && assign < enable && enable < enable3);
        assert_eq!(pos(TXPDO_MAP, 5, SdoValue::U32(0x603F_0010)), tx_set - 1);
    }

    #[test]
    fn working_counter_and_watchdog() {
        assert_eq!(
            expected_working_counter([(TX_BYTES, RX_BYTES); 6]),
            18,
            "6 × (1 + 2)"
        );
        assert_eq!(expected_working_counter([(14, 0), (0, 8), (0, 0)]), 3);
        assert_eq!(WATCHDOG_UNIT_NS, 100_000);
        assert_eq!(sm_watchdog_time(10), Some(100));
        assert_eq!(sm_watchdog_time(6553), Some(65530));
        assert_eq!(sm_watchdog_time(6554), None, "over 16 bits");
        assert_eq!(sm_watchdog_time(0), None);
    }
}
