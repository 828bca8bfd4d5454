//! The SII EEPROM image of one drive (ETG.2010): the fixed header words and the
//! Strings, General, FMMU, SyncManager, TxPDO and RxPDO categories.

use crate::config::DriveConfig;
use crate::od::{ObjectDictionary, RXPDO_MAP, TXPDO_MAP, decode_mapping};

/// Physical start of SM0, the mailbox the master writes (ESC process RAM).
pub(crate) const MBX_OUT_START: u16 = 0x1000;
/// Physical start of SM1, the mailbox the master reads.
pub(crate) const MBX_IN_START: u16 = 0x1080;
/// Size of each mailbox (bytes).
pub(crate) const MBX_SIZE: u16 = 0x0080;
/// Physical start of SM2 (outputs, RxPDO).
pub(crate) const PD_OUT_START: u16 = 0x1100;
/// Physical start of SM3 (inputs, TxPDO).
pub(crate) const PD_IN_START: u16 = 0x1180;
/// Mailbox protocols word (0x001C): CoE.
const MBX_PROTO_COE: u16 = 0x0004;

/// SyncManager control bytes as in ESI files: mailbox write, mailbox read, buffered
/// write with watchdog, buffered read (ETG.1000.4 table 58).
pub(crate) const SM_CONTROL: [u8; 4] = [0x26, 0x22, 0x64, 0x20];

/// The SII CRC over words 0-6 (ETG.2010 2.2: CRC-8, polynomial x⁸+x²+x+1, seed 0xFF).
fn crc8(data: &[u8]) -> u8 {
    let mut crc = 0xFFu8;
    for &b in data {
        crc ^= b;
        for _ in 0..8 {
            crc = if crc & 0x80 != 0 {
                (crc << 1) ^ 0x07
            } else {
                crc << 1
            };
        }
    }
    crc
}

fn push_u16(v: &mut Vec<u8>, x: u16) {
    v.extend_from_slice(&x.to_le_bytes());
}

fn push_category(image: &mut Vec<u8>, kind: u16, mut data: Vec<u8>) {
    if data.len() % 2 == 1 {
        data.push(0);
    }
    push_u16(image, kind);
    push_u16(image, (data.len() / 2) as u16);
    image.extend_from_slice(&data);
}

/// Builds the EEPROM image of a drive; the PDO categories follow the default mapping
/// in `od`.
pub(crate) fn image(cfg: &DriveConfig, od: &ObjectDictionary) -> Vec<u8> {
    let mut v = Vec::with_capacity(512);
    // Words 0x0000-0x0007: ESC configuration area; word 7 its checksum.
    let config_area = [0x0C80u16, 0x0000, 0x0000, 0x0000, 0x0000, 0x0000, 0x0000];
    for w in config_area {
        push_u16(&mut v, w);
    }
    let crc = crc8(&v[..14]);
    push_u16(&mut v, u16::from(crc));
    // Words 0x0008-0x000F: identity.
    let id = cfg.identity;
    for x in [id.vendor_id, id.product_code, id.revision, id.serial] {
        v.extend_from_slice(&x.to_le_bytes());
    }
    // 0x0010-0x0013 reserved, 0x0014-0x0017 bootstrap mailbox (none).
    v.resize(0x18 * 2, 0);
    // 0x0018-0x001C standard mailbox: receive offset/size, send offset/size, protocols.
    for w in [
        MBX_OUT_START,
        MBX_SIZE,
        MBX_IN_START,
        MBX_SIZE,
        MBX_PROTO_COE,
    ] {
        push_u16(&mut v, w);
    }
    v.resize(0x3E * 2, 0);
    // 0x003E: EEPROM size in kbit - 1 (2 kbit); 0x003F: version 1.
    push_u16(&mut v, 1);
    push_u16(&mut v, 1);
    // Categories from word 0x0040.
    // Strings: 1 = name (order number), 2 = group, 3 = PDO names.
    let strings = [cfg.name.as_str(), "Servo drives", "Process data"];
    let mut s = vec![strings.len() as u8];
    for st in strings {
        s.push(st.len() as u8);
        s.extend_from_slice(st.as_bytes());
    }
    push_category(&mut v, 10, s);
    // General (ETG.2010 table 7): group 2, image 0, order 1, name 1; CoE details:
    // SDO, PDO assign and PDO config (no SDO info, no complete access).
    let mut g = vec![0u8; 32];
    g[0] = 2;
    g[2] = 1;
    g[3] = 1;
    g[5] = 0x01 | 0x04 | 0x08;
    g[9] = 1; // DS402 channels
    push_category(&mut v, 30, g);
    // FMMU usage: outputs, inputs, SyncManager status.
    push_category(&mut v, 40, vec![1, 2, 3, 0]);
    // SyncManagers: start, length, control, status, enable, type.
    let mut sm = Vec::new();
    let rx_bytes = pdo_bytes(od, RXPDO_MAP);
    let tx_bytes = pdo_bytes(od, TXPDO_MAP);
    for (i, (start, len, kind)) in [
        (MBX_OUT_START, MBX_SIZE, 1u8),
        (MBX_IN_START, MBX_SIZE, 2),
        (PD_OUT_START, rx_bytes, 3),
        (PD_IN_START, tx_bytes, 4),
    ]
    .into_iter()
    .enumerate()
    {
        push_u16(&mut sm, start);
        push_u16(&mut sm, len);
        sm.extend_from_slice(&[SM_CONTROL[i], 0, 1, kind]);
    }
    push_category(&mut v, 41, sm);
    // TxPDO (50) on SM3 and RxPDO (51) on SM2.
    for (kind, pdo, smi) in [(50u16, TXPDO_MAP, 3u8), (51, RXPDO_MAP, 2)] {
        let n = od.u8(pdo, 0);
        let mut p = Vec::new();
        push_u16(&mut p, pdo);
        p.extend_from_slice(&[n, smi, 0, 3]);
        push_u16(&mut p, 0);
        for i in 1..=n {
            let m = decode_mapping(od.u32(pdo, i));
            push_u16(&mut p, m.index);
            // Data types (ETG.1000.6 table 64): INTEGER16/32, UNSIGNED16.
            let data_type = match m.bits {
                8 => 0x0002,
                16 => 0x0006,
                _ => 0x0004,
            };
            p.extend_from_slice(&[m.sub, 0, data_type, m.bits as u8]);
            push_u16(&mut p, 0);
        }
        push_category(&mut v, kind, p);
    }
    push_u16(&mut v, 0xFFFF);
    push_u16(&mut v, 0);
    v.resize(256, 0xFF);
    v
}

fn pdo_bytes(od: &ObjectDictionary, pdo: u16) -> u16 {
    let bits: u16 = (1..=od.u8(pdo, 0))
        .map(|i| decode_mapping(od.u32(pdo, i)).bits)
        .sum();
    bits.div_ceil(8)
}

/// Writes a new identity into an image (words 0x0008-0x000B).
pub(crate) fn set_identity(image: &mut [u8], vendor_id: u32, product_code: u32) {
    if let Some(w) = image.get_mut(0x10..0x18) {
        w[..4].copy_from_slice(&vendor_id.to_le_bytes());
        w[4..].copy_from_slice(&product_code.to_le_bytes());
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn crc_matches_a_published_configuration_area() {
        let bytes = [0x04, 0x01, 0, 0, 0, 0, 0xFF, 0, 0, 0, 0, 0, 0, 0];
        assert_eq!(crc8(&bytes), 0xE2);
    }
}
