//! The mailbox protocol layer (ETG.1000.4 5.6: mailbox header) and the CoE SDO server
//! (ETG.1000.6 5.6.2: SDO download/upload, expedited and normal, SDO abort).

use crate::od::{ObjectDictionary, abort};

/// Mailbox type CoE (ETG.1000.4 table 29).
const MBX_TYPE_COE: u8 = 0x03;
/// Mailbox type: error reply.
const MBX_TYPE_ERR: u8 = 0x00;
/// CoE service: SDO request / SDO response (ETG.1000.6 table 29).
const COE_SDO_REQUEST: u8 = 2;
const COE_SDO_RESPONSE: u8 = 3;
/// Mailbox error codes (ETG.1000.4 table 30).
const MBXERR_UNSUPPORTED_PROTOCOL: u16 = 0x0002;
const MBXERR_INVALID_SIZE: u16 = 0x0008;

/// Answers one mailbox request; `None` if there is nothing to answer. `mbx_size` is the
/// size of the read mailbox.
pub(crate) fn answer(
    req: &[u8],
    od: &mut ObjectDictionary,
    pre_op: bool,
    mbx_size: usize,
) -> Option<Vec<u8>> {
    let header = req.get(..6)?;
    let len = usize::from(u16::from_le_bytes([header[0], header[1]]));
    let kind = header[5] & 0x0F;
    let counter = header[5] & 0x70;
    let Some(body) = req.get(6..6 + len) else {
        return Some(mailbox_error(counter, MBXERR_INVALID_SIZE));
    };
    if kind != MBX_TYPE_COE {
        return Some(mailbox_error(counter, MBXERR_UNSUPPORTED_PROTOCOL));
    }
    if body.len() < 10 {
        return Some(mailbox_error(counter, MBXERR_INVALID_SIZE));
    }
    let service = body[1] >> 4;
    let cmd = body[2];
    let index = u16::from_le_bytes([body[3], body[4]]);
    let sub = body[5];
    if service != COE_SDO_REQUEST {
        return Some(sdo_abort(counter, index, sub, abort::COMMAND_SPECIFIER));
    }
    if cmd & 0x10 != 0 {
        return Some(sdo_abort(counter, index, sub, abort::UNSUPPORTED_ACCESS));
    }
    let resp = match cmd >> 5 {
        // Download (write) request.
        1 => {
            let data: &[u8] = if cmd & 0x02 != 0 {
                // Expedited: size in bits 2-3 (bytes not used) if size indicated.
                let n = if cmd & 0x01 != 0 {
                    4 - usize::from((cmd >> 2) & 0x03)
                } else {
                    4
                };
                &body[6..6 + n]
            } else {
                // Normal: complete size, then the data in this mailbox.
                let size = u32::from_le_bytes([body[6], body[7], body[8], body[9]]) as usize;
                match body.get(10..10 + size) {
                    Some(d) => d,
                    None => return Some(sdo_abort(counter, index, sub, abort::LENGTH_MISMATCH)),
                }
            };
            match od.download(index, sub, data, pre_op) {
                Ok(()) => sdo_response(counter, 0x60, index, sub, &[0; 4]),
                Err(code) => sdo_abort(counter, index, sub, code),
            }
        }
        // Upload (read) request.
        2 => match od.upload(index, sub) {
            Ok(data) if data.len() <= 4 => {
                let unused = (4 - data.len()) as u8;
                let mut d = [0u8; 4];
                d[..data.len()].copy_from_slice(&data);
                sdo_response(counter, 0x43 | (unused << 2), index, sub, &d)
            }
            Ok(data) if data.len() + 16 <= mbx_size => {
                let mut d = (data.len() as u32).to_le_bytes().to_vec();
                d.extend_from_slice(&data);
                sdo_response(counter, 0x41, index, sub, &d)
            }
            // Segmented transfer is not emulated; nothing in the dictionary needs it.
            Ok(_) => sdo_abort(counter, index, sub, abort::UNSUPPORTED_ACCESS),
            Err(code) => sdo_abort(counter, index, sub, code),
        },
        _ => sdo_abort(counter, index, sub, abort::COMMAND_SPECIFIER),
    };
    Some(resp)
}

fn mailbox(counter: u8, kind: u8, body: &[u8]) -> Vec<u8> {
    let mut v = Vec::with_capacity(6 + body.len());
    v.extend_from_slice(&(body.len() as u16).to_le_bytes());
    v.extend_from_slice(&[0, 0, 0, kind | counter]);
    v.extend_from_slice(body);
    v
}

fn sdo_response(counter: u8, cmd: u8, index: u16, sub: u8, data: &[u8]) -> Vec<u8> {
    let mut b = vec![0, COE_SDO_RESPONSE << 4, cmd];
    b.extend_from_slice(&index.to_le_bytes());
    b.push(sub);
    b.extend_from_slice(data);
    mailbox(counter, MBX_TYPE_COE, &b)
}

/// SDO abort transfer (command specifier 4) with its abort code.
fn sdo_abort(counter: u8, index: u16, sub: u8, code: u32) -> Vec<u8> {
    let mut b = vec![0, COE_SDO_REQUEST << 4, 0x80];
    b.extend_from_slice(&index.to_le_bytes());
    b.push(sub);
    b.extend_from_slice(&code.to_le_bytes());
    mailbox(counter, MBX_TYPE_COE, &b)
}

fn mailbox_error(counter: u8, code: u16) -> Vec<u8> {
    let mut b = vec![0x01, 0x00];
    b.extend_from_slice(&code.to_le_bytes());
    mailbox(counter, MBX_TYPE_ERR, &b)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::od::{Access, Mappable};

    fn request(cmd: u8, index: u16, sub: u8, data: &[u8]) -> Vec<u8> {
        let mut body = vec![0, COE_SDO_REQUEST << 4, cmd];
        body.extend_from_slice(&index.to_le_bytes());
        body.push(sub);
        body.extend_from_slice(data);
        let mut m = mailbox(0x10, MBX_TYPE_COE, &body);
        m.resize(128, 0);
        m
    }

    fn od() -> ObjectDictionary {
        let mut od = ObjectDictionary::default();
        od.insert(0x6040, 0, &[0, 0], Access::Rw, Mappable::Rx);
        od.insert(0x1008, 0, b"a long device name", Access::Ro, Mappable::No);
        od
    }

    #[test]
    fn normal_download_and_upload_and_the_aborts() {
        let mut od = od();
        // Normal download: size 2, then the data.
        let r = answer(
            &request(0x21, 0x6040, 0, &[2, 0, 0, 0, 0x0F, 0x00]),
            &mut od,
            true,
            128,
        )
        .expect("answer");
        assert_eq!(r[8], 0x60, "download response");
        assert_eq!(od.u16(0x6040, 0), 0x000F);
        // Expedited without size: 4 bytes into a 2-byte object.
        let r =
            answer(&request(0x22, 0x6040, 0, &[1, 0, 0, 0]), &mut od, true, 128).expect("answer");
        assert_eq!(r[8], 0x80, "abort");
        assert_eq!(r[12..16], abort::LENGTH_MISMATCH.to_le_bytes());
        // Normal upload: size indicated, complete size, data.
        let r = answer(&request(0x40, 0x1008, 0, &[0; 4]), &mut od, true, 128).expect("answer");
        assert_eq!(r[8], 0x41);
        assert_eq!(r[12..16], 18u32.to_le_bytes());
        assert_eq!(&r[16..34], b"a long device name");
        // Complete access is refused; another protocol gets a mailbox error.
        let r = answer(&request(0x50, 0x1008, 0, &[0; 4]), &mut od, true, 128).expect("answer");
        assert_eq!(r[12..16], abort::UNSUPPORTED_ACCESS.to_le_bytes());
        let mut foe = request(0x40, 0x1008, 0, &[0; 4]);
        foe[5] = 0x04;
        let r = answer(&foe, &mut od, true, 128).expect("answer");
        assert_eq!(r[5] & 0x0F, MBX_TYPE_ERR);
        // A length beyond the mailbox is an error reply, not a panic.
        let mut long = request(0x40, 0x1008, 0, &[0; 4]);
        long[0] = 0xFF;
        assert_eq!(
            answer(&long, &mut od, true, 128).expect("answer")[5] & 0x0F,
            MBX_TYPE_ERR
        );
    }
}
