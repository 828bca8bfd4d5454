//! The drive's CoE object dictionary (CiA 301 communication area, CiA 402 device
//! profile area) and its SDO server (ETG.1000.6 5.6.2: expedited and normal upload and
//! download, abort with the CiA 301 abort codes).

use std::collections::BTreeMap;

use microrobot_ethercat_cia402::dc::{self, SM_INPUT_PARAMETER, SM_OUTPUT_PARAMETER};

/// SDO abort codes (CiA 301 7.2.4.3.17, ETG.1000.6 table 41) the server answers with.
pub mod abort {
    /// Client/server command specifier not valid or unknown.
    pub const COMMAND_SPECIFIER: u32 = 0x0504_0001;
    /// Unsupported access to an object (complete access is not supported).
    pub const UNSUPPORTED_ACCESS: u32 = 0x0601_0000;
    /// Attempt to write a read-only object.
    pub const READ_ONLY: u32 = 0x0601_0002;
    /// Subindex cannot be written, subindex 0 must be 0 for write access.
    pub const SUBINDEX0_NOT_ZERO: u32 = 0x0601_0003;
    /// The object does not exist in the object dictionary.
    pub const NO_OBJECT: u32 = 0x0602_0000;
    /// The object cannot be mapped into the PDO.
    pub const NOT_MAPPABLE: u32 = 0x0604_0041;
    /// The number and length of the objects to be mapped would exceed the PDO length.
    pub const PDO_LENGTH: u32 = 0x0604_0042;
    /// Data type does not match, length of service parameter does not match.
    pub const LENGTH_MISMATCH: u32 = 0x0607_0010;
    /// Subindex does not exist.
    pub const NO_SUBINDEX: u32 = 0x0609_0011;
    /// Value range of parameter exceeded.
    pub const VALUE_RANGE: u32 = 0x0609_0030;
    /// Data cannot be transferred or stored because of the present device state.
    pub const DEVICE_STATE: u32 = 0x0800_0022;
}

/// Who may write an entry.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Access {
    /// Read only over SDO.
    Ro,
    /// Read-write in every state.
    Rw,
    /// Read-write in PRE-OP only (PDO mapping and assignment, ETG.1000.6 5.6.7).
    RwPreOp,
}

/// Which process data direction an entry may be mapped into.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Mappable {
    /// Not mappable.
    No,
    /// RxPDO (master outputs, SM2).
    Rx,
    /// TxPDO (master inputs, SM3).
    Tx,
}

#[derive(Debug, Clone)]
struct Entry {
    data: Vec<u8>,
    access: Access,
    mappable: Mappable,
}

/// Index of the RxPDO mapping object (controlword, target torque, target position).
pub(crate) const RXPDO_MAP: u16 = 0x1600;
/// Index of the TxPDO mapping object (statusword, position, velocity, torque, error).
pub(crate) const TXPDO_MAP: u16 = 0x1A00;
/// RxPDO assignment of SM2.
pub(crate) const SM2_ASSIGN: u16 = 0x1C12;
/// TxPDO assignment of SM3.
pub(crate) const SM3_ASSIGN: u16 = 0x1C13;
/// Most entries a mapping object takes.
const MAX_MAPPED: u8 = 8;

/// One mapped object: index, subindex, length in bits.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct MappedObject {
    pub index: u16,
    pub sub: u8,
    pub bits: u16,
}

/// The object dictionary of one drive.
#[derive(Debug, Clone, Default)]
pub(crate) struct ObjectDictionary {
    entries: BTreeMap<(u16, u8), Entry>,
}

impl ObjectDictionary {
    /// Adds (or replaces) an entry.
    pub fn insert(&mut self, index: u16, sub: u8, data: &[u8], access: Access, mappable: Mappable) {
        self.entries.insert(
            (index, sub),
            Entry {
                data: data.to_vec(),
                access,
                mappable,
            },
        );
    }

    /// Raw bytes of an entry.
    pub fn get(&self, index: u16, sub: u8) -> Option<&[u8]> {
        self.entries.get(&(index, sub)).map(|e| e.data.as_slice())
    }

    /// Overwrites an existing entry's value from the drive side (no access check);
    /// the length is kept.
    pub fn set(&mut self, index: u16, sub: u8, data: &[u8]) {
        if let Some(e) = self.entries.get_mut(&(index, sub)) {
            let n = e.data.len().min(data.len());
            e.data[..n].copy_from_slice(&data[..n]);
        }
    }

    pub fn u8(&self, index: u16, sub: u8) -> u8 {
        self.get(index, sub)
            .and_then(|d| d.first().copied())
            .unwrap_or(0)
    }

    pub fn u16(&self, index: u16, sub: u8) -> u16 {
        self.get(index, sub)
            .and_then(|d| d.get(..2))
            .and_then(|d| d.try_into().ok())
            .map(u16::from_le_bytes)
            .unwrap_or(0)
    }

    pub fn u32(&self, index: u16, sub: u8) -> u32 {
        self.get(index, sub)
            .and_then(|d| d.get(..4))
            .and_then(|d| d.try_into().ok())
            .map(u32::from_le_bytes)
            .unwrap_or(0)
    }

    fn object_exists(&self, index: u16) -> bool {
        self.entries
            .range((index, 0)..=(index, u8::MAX))
            .next()
            .is_some()
    }

    /// SDO upload (read) of one entry.
    pub fn upload(&self, index: u16, sub: u8) -> Result<Vec<u8>, u32> {
        match self.entries.get(&(index, sub)) {
            Some(e) => Ok(e.data.clone()),
            None if self.object_exists(index) => Err(abort::NO_SUBINDEX),
            None => Err(abort::NO_OBJECT),
        }
    }

    /// SDO download (write) of one entry with the checks a master meets on a real
    /// drive; `pre_op` is whether the EtherCAT state is PRE-OP.
    pub fn download(&mut self, index: u16, sub: u8, data: &[u8], pre_op: bool) -> Result<(), u32> {
        let entry = match self.entries.get(&(index, sub)) {
            Some(e) => e,
            None if self.object_exists(index) => return Err(abort::NO_SUBINDEX),
            None => return Err(abort::NO_OBJECT),
        };
        match entry.access {
            Access::Ro => return Err(abort::READ_ONLY),
            Access::RwPreOp if !pre_op => return Err(abort::DEVICE_STATE),
            _ => {}
        }
        if data.len() != entry.data.len() {
            return Err(abort::LENGTH_MISMATCH);
        }
        let is_pdo_object = matches!(index, RXPDO_MAP | TXPDO_MAP | SM2_ASSIGN | SM3_ASSIGN);
        if is_pdo_object {
            if sub != 0 && self.u8(index, 0) != 0 {
                return Err(abort::SUBINDEX0_NOT_ZERO);
            }
            if sub == 0 {
                let n = data.first().copied().unwrap_or(0);
                self.check_pdo_object(index, n)?;
            }
        }
        if matches!(index, SM_OUTPUT_PARAMETER | SM_INPUT_PARAMETER) && sub == dc::sub::SYNC_MODE {
            let mode = u16::from_le_bytes([
                data.first().copied().unwrap_or(0),
                data.get(1).copied().unwrap_or(0),
            ]);
            if !dc::sync_mode_supported(self.u16(index, dc::sub::SYNC_MODES_SUPPORTED), mode) {
                return Err(abort::VALUE_RANGE);
            }
        }
        if index == 0x6060 {
            let mode = data.first().copied().unwrap_or(0) as i8;
            if !matches!(mode, 0 | crate::drive::MODE_CSP | crate::drive::MODE_CST) {
                return Err(abort::VALUE_RANGE);
            }
        }
        self.set(index, sub, data);
        Ok(())
    }

    /// Checks that subindices 1..=n of a mapping or assignment object are consistent
    /// before subindex 0 enables them.
    fn check_pdo_object(&self, index: u16, n: u8) -> Result<(), u32> {
        match index {
            RXPDO_MAP | TXPDO_MAP => {
                if n > MAX_MAPPED {
                    return Err(abort::PDO_LENGTH);
                }
                let want = if index == RXPDO_MAP {
                    Mappable::Rx
                } else {
                    Mappable::Tx
                };
                let mut total_bits = 0u32;
                for i in 1..=n {
                    let m = decode_mapping(self.u32(index, i));
                    let Some(e) = self.entries.get(&(m.index, m.sub)) else {
                        return Err(abort::NOT_MAPPABLE);
                    };
                    if e.mappable != want || u32::from(m.bits) != 8 * e.data.len() as u32 {
                        return Err(abort::NOT_MAPPABLE);
                    }
                    total_bits += u32::from(m.bits);
                }
                if total_bits > 8 * 64 {
                    return Err(abort::PDO_LENGTH);
                }
                Ok(())
            }
            SM2_ASSIGN | SM3_ASSIGN => {
                let pdo = if index == SM2_ASSIGN {
                    RXPDO_MAP
                } else {
                    TXPDO_MAP
                };
                if n > 1 {
                    return Err(abort::VALUE_RANGE);
                }
                for i in 1..=n {
                    if self.u16(index, i) != pdo {
                        return Err(abort::VALUE_RANGE);
                    }
                }
                Ok(())
            }
            _ => Ok(()),
        }
    }

    /// The objects mapped into SM2 (`rx`) or SM3, in process image order, as assigned
    /// in 0x1C12/0x1C13 and mapped in 0x1600/0x1A00.
    pub fn layout(&self, rx: bool) -> Vec<MappedObject> {
        let assign = if rx { SM2_ASSIGN } else { SM3_ASSIGN };
        let mut out = Vec::new();
        for a in 1..=self.u8(assign, 0) {
            let pdo = self.u16(assign, a);
            for i in 1..=self.u8(pdo, 0) {
                out.push(decode_mapping(self.u32(pdo, i)));
            }
        }
        out
    }
}

/// A PDO mapping entry (CiA 301 7.5.2.36): index in bits 16-31, subindex 8-15,
/// length in bits 0-7.
pub(crate) fn decode_mapping(v: u32) -> MappedObject {
    MappedObject {
        index: (v >> 16) as u16,
        sub: (v >> 8) as u8,
        bits: (v & 0xFF) as u16,
    }
}

/// The inverse of [`decode_mapping`].
pub(crate) const fn mapping(index: u16, sub: u8, bits: u8) -> u32 {
    ((index as u32) << 16) | ((sub as u32) << 8) | bits as u32
}

#[cfg(test)]
mod tests {
    use super::*;

    fn od() -> ObjectDictionary {
        let mut od = ObjectDictionary::default();
        od.insert(0x6040, 0, &[0, 0], Access::Rw, Mappable::Rx);
        od.insert(0x6041, 0, &[0, 0], Access::Ro, Mappable::Tx);
        od.insert(RXPDO_MAP, 0, &[1], Access::RwPreOp, Mappable::No);
        for i in 1..=MAX_MAPPED {
            let v = if i == 1 { mapping(0x6040, 0, 16) } else { 0 };
            od.insert(
                RXPDO_MAP,
                i,
                &v.to_le_bytes(),
                Access::RwPreOp,
                Mappable::No,
            );
        }
        od
    }

    #[test]
    fn mapping_rules_match_the_standard() {
        let mut od = od();
        let v = mapping(0x6041, 0, 16).to_le_bytes();
        assert_eq!(
            od.download(RXPDO_MAP, 1, &v, true),
            Err(abort::SUBINDEX0_NOT_ZERO)
        );
        od.download(RXPDO_MAP, 0, &[0], true).expect("clear");
        od.download(RXPDO_MAP, 1, &v, true).expect("entry");
        assert_eq!(
            od.download(RXPDO_MAP, 0, &[1], true),
            Err(abort::NOT_MAPPABLE)
        );
        assert_eq!(
            od.download(RXPDO_MAP, 0, &[0], false),
            Err(abort::DEVICE_STATE)
        );
        assert_eq!(od.upload(0x2000, 0), Err(abort::NO_OBJECT));
        assert_eq!(od.upload(0x6040, 1), Err(abort::NO_SUBINDEX));
        assert_eq!(od.download(0x6041, 0, &[1, 0], true), Err(abort::READ_ONLY));
        assert_eq!(
            od.download(0x6040, 0, &[1], true),
            Err(abort::LENGTH_MISMATCH)
        );
    }
}
