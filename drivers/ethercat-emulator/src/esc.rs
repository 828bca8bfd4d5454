//! One emulated SubDevice: the EtherCAT SubDevice Controller (ESC) memory with the
//! registers a MainDevice uses (ETG.1000.4 clause 6 / table 31 register map), the SII
//! EEPROM interface (0x0500-0x050F), the AL state machine (ETG.1000.6 6.4), the mailbox
//! SyncManagers with CoE SDO (ETG.1000.6 5.6), FMMUs (0x0600) and the drive behind it.

use crate::config::DriveConfig;
use crate::drive::Drive;
use crate::od::MappedObject;
use crate::sii::{self, MBX_IN_START, MBX_OUT_START, MBX_SIZE};
use microrobot_ethercat_cia402::dc::{SM_INPUT_PARAMETER, SM_OUTPUT_PARAMETER, sub, sync_mode};

/// ESC memory: 4 KiB registers plus 4 KiB process RAM.
pub(crate) const MEM_SIZE: usize = 0x2000;

/// AL states (AL control 0x0120 / AL status 0x0130, bits 0-3).
pub(crate) mod al {
    pub const INIT: u8 = 1;
    pub const PRE_OP: u8 = 2;
    pub const BOOT: u8 = 3;
    pub const SAFE_OP: u8 = 4;
    pub const OP: u8 = 8;
}

/// AL status codes (0x0134, ETG.1000.6 table 11) the emulator reports.
pub mod al_status_code {
    /// Invalid requested state change.
    pub const INVALID_STATE_CHANGE: u16 = 0x0011;
    /// Unknown requested state.
    pub const UNKNOWN_STATE: u16 = 0x0012;
    /// Bootstrap not supported.
    pub const BOOTSTRAP_NOT_SUPPORTED: u16 = 0x0013;
    /// Invalid mailbox configuration (PRE-OP).
    pub const INVALID_MAILBOX_CONFIG: u16 = 0x0016;
    /// Sync manager watchdog: process data stopped (the default for a dropped drive).
    pub const SM_WATCHDOG: u16 = 0x001B;
    /// Invalid output configuration (SM2 does not match the RxPDO mapping).
    pub const INVALID_OUTPUT_CONFIG: u16 = 0x001D;
    /// Invalid input configuration (SM3 does not match the TxPDO mapping).
    pub const INVALID_INPUT_CONFIG: u16 = 0x001E;
    /// Invalid DC SYNC configuration: sync mode DC SYNC0 (0x1C32:01 = 2) without SYNC0
    /// activated (0x0981).
    pub const INVALID_DC_SYNC_CONFIG: u16 = 0x0030;
    /// DC invalid sync cycle time: the SYNC0 cycle (0x09A0) is below the minimum cycle
    /// time (0x1C32:05).
    pub const INVALID_SYNC_CYCLE_TIME: u16 = 0x0035;
}

const REG_STATION_ADDRESS: u16 = 0x0010;
const REG_DL_STATUS: u16 = 0x0110;
const REG_AL_CONTROL: u16 = 0x0120;
const REG_AL_STATUS: u16 = 0x0130;
const REG_AL_STATUS_CODE: u16 = 0x0134;
const REG_SII_CONTROL: u16 = 0x0502;
const REG_SII_ADDRESS: u16 = 0x0504;
const REG_SII_DATA: u16 = 0x0508;
const REG_FMMU: u16 = 0x0600;
const REG_SM: u16 = 0x0800;
const REG_DC_PORT_TIMES: u16 = 0x0900;
const REG_DC_SYSTEM_TIME: u16 = 0x0910;
const REG_DC_RECEIVE_TIME: u16 = 0x0918;
const REG_DC_OFFSET: u16 = 0x0920;
const REG_DC_SYNC_ACTIVE: u16 = 0x0981;
const REG_DC_SYNC_START: u16 = 0x0990;
const REG_DC_SYNC0_CYCLE: u16 = 0x09A0;
/// 0x0981: cyclic operation enabled (bit 0) and SYNC0 activated (bit 1).
const SYNC0_ON: u8 = 0x03;
const REG_WATCHDOG_DIVIDER: u16 = 0x0400;
const REG_WATCHDOG_PD: u16 = 0x0420;
const REG_WATCHDOG_STATUS: u16 = 0x0440;
const REG_WATCHDOG_COUNTER_PD: u16 = 0x0442;

/// A SyncManager channel as configured in 0x0800 + 8n (ETG.1000.4 table 58).
#[derive(Debug, Clone, Copy)]
pub(crate) struct Sm {
    pub start: u16,
    pub len: u16,
    pub control: u8,
    pub enabled: bool,
}

impl Sm {
    fn is_mailbox(&self) -> bool {
        self.control & 0x03 == 0x02
    }
    /// The master writes this buffer.
    fn master_writes(&self) -> bool {
        self.control & 0x0C == 0x04
    }
    fn covers(&self, addr: u32) -> bool {
        self.enabled
            && self.len > 0
            && addr >= u32::from(self.start)
            && addr < u32::from(self.start) + u32::from(self.len)
    }
    fn last(&self) -> u32 {
        u32::from(self.start) + u32::from(self.len) - 1
    }
}

/// One emulated SubDevice.
#[derive(Debug, Clone)]
pub(crate) struct SubDevice {
    mem: Vec<u8>,
    pub sii: Vec<u8>,
    pub drive: Drive,
    rx_layout: Vec<MappedObject>,
    tx_layout: Vec<MappedObject>,
    /// When the outputs (SM2) were last written in OP, or OP was entered: the process
    /// data watchdog's start (local clock, ns). `None` outside OP.
    outputs_written_ns: Option<u64>,
    /// System time (ns) up to which SYNC0 events are accounted for, while the outputs
    /// are latched at SYNC0 ([`SubDevice::latches_at_sync0`]); `None` otherwise.
    sync0_seen: Option<u64>,
    /// Outputs (SM2) written since the last SYNC0 event.
    outputs_fresh: bool,
    /// SYNC0 events that latched outputs since power on.
    pub sync0_latched: u64,
    /// When SM2 was last written (local clock, ns), for the SM-synchronous mode's
    /// cycle-time-too-small count.
    last_sm2_write_ns: Option<u64>,
}

fn overlaps(addr: u32, len: usize, reg: u16, reg_len: u32) -> bool {
    let end = addr + len as u32;
    addr < u32::from(reg) + reg_len && end > u32::from(reg)
}

impl SubDevice {
    pub fn new(cfg: &DriveConfig) -> SubDevice {
        let drive = Drive::new(cfg);
        let sii = sii::image(cfg, &drive.od);
        let mut s = SubDevice {
            mem: vec![0; MEM_SIZE],
            sii,
            drive,
            rx_layout: Vec::new(),
            tx_layout: Vec::new(),
            outputs_written_ns: None,
            sync0_seen: None,
            outputs_fresh: false,
            sync0_latched: 0,
            last_sm2_write_ns: None,
        };
        // Type, revision, build; FMMUs, SMs, RAM size (KiB), ports 0 and 1 MII.
        s.mem[0x0000] = 0x11;
        s.mem[0x0002..0x0004].copy_from_slice(&1u16.to_le_bytes());
        s.mem[0x0004] = 8;
        s.mem[0x0005] = 8;
        s.mem[0x0006] = 4;
        s.mem[0x0007] = 0x0F;
        // Support flags (0x0008): DC supported (bit 2), 64-bit DC (bit 3).
        s.mem[0x0008..0x000A].copy_from_slice(&0x000Cu16.to_le_bytes());
        s.set_al(al::INIT, false, 0);
        s.set_port1_open(true);
        s.mem[0x0502] = 0x40;
        s
    }

    pub fn station_address(&self) -> u16 {
        self.u16(REG_STATION_ADDRESS)
    }

    pub fn al_state(&self) -> u8 {
        self.mem[REG_AL_STATUS as usize] & 0x0F
    }

    pub fn al_error(&self) -> bool {
        self.mem[REG_AL_STATUS as usize] & 0x10 != 0
    }

    pub fn al_status_code(&self) -> u16 {
        self.u16(REG_AL_STATUS_CODE)
    }

    fn u16(&self, reg: u16) -> u16 {
        let r = usize::from(reg);
        u16::from_le_bytes([self.mem[r], self.mem[r + 1]])
    }

    fn u32(&self, reg: u16) -> u32 {
        let r = usize::from(reg);
        u32::from_le_bytes([
            self.mem[r],
            self.mem[r + 1],
            self.mem[r + 2],
            self.mem[r + 3],
        ])
    }

    fn u64(&self, reg: u16) -> u64 {
        let r = usize::from(reg);
        let mut b = [0u8; 8];
        b.copy_from_slice(&self.mem[r..r + 8]);
        u64::from_le_bytes(b)
    }

    fn put(&mut self, reg: u16, bytes: &[u8]) {
        let r = usize::from(reg);
        self.mem[r..r + bytes.len()].copy_from_slice(bytes);
    }

    /// DL status (0x0110): port 0 link and communication; port 1 link and
    /// communication when a SubDevice follows, else its loop closed.
    pub fn set_port1_open(&mut self, open: bool) {
        let mut dl: u16 = 0x0001 | (1 << 4) | (1 << 9);
        dl |= if open { (1 << 5) | (1 << 11) } else { 1 << 10 };
        self.put(REG_DL_STATUS, &dl.to_le_bytes());
    }

    /// Sets AL status and status code.
    pub fn set_al(&mut self, state: u8, error: bool, code: u16) {
        if state != al::OP {
            self.outputs_written_ns = None;
            self.sync0_seen = None;
            self.outputs_fresh = false;
        }
        self.mem[REG_AL_STATUS as usize] = state | if error { 0x10 } else { 0 };
        self.put(REG_AL_STATUS_CODE, &code.to_le_bytes());
    }

    pub fn sm(&self, n: usize) -> Sm {
        let b = usize::from(REG_SM) + 8 * n;
        Sm {
            start: u16::from_le_bytes([self.mem[b], self.mem[b + 1]]),
            len: u16::from_le_bytes([self.mem[b + 2], self.mem[b + 3]]),
            control: self.mem[b + 4],
            enabled: self.mem[b + 6] & 0x01 != 0,
        }
    }

    fn set_mailbox_full(&mut self, n: usize, full: bool) {
        let b = usize::from(REG_SM) + 8 * n + 5;
        if full {
            self.mem[b] |= 0x08;
        } else {
            self.mem[b] &= !0x08;
        }
    }

    fn mailbox_full(&self, n: usize) -> bool {
        self.mem[usize::from(REG_SM) + 8 * n + 5] & 0x08 != 0
    }

    /// Which SyncManager (0-3) covers `addr`, if any.
    fn sm_at(&self, addr: u32) -> Option<(usize, Sm)> {
        (0..4)
            .map(|n| (n, self.sm(n)))
            .find(|(_, sm)| sm.covers(addr))
    }

    /// A physical read of `out.len()` bytes at `addr` (APRD/FPRD/BRD and the read half
    /// of the RW and RMW commands); false if the ESC refuses it (an empty mailbox: no
    /// working counter). `now_ns` is the local clock.
    pub fn read(&mut self, addr: u16, out: &mut [u8], now_ns: u64) -> bool {
        let a = u32::from(addr);
        if a as usize + out.len() > MEM_SIZE {
            return false;
        }
        if overlaps(a, out.len(), REG_DC_SYSTEM_TIME, 8) {
            let offset = self.u64(REG_DC_OFFSET);
            self.put(
                REG_DC_SYSTEM_TIME,
                &now_ns.wrapping_add(offset).to_le_bytes(),
            );
        }
        let mut clear_full = None;
        if let Some((n, sm)) = self.sm_at(a).filter(|(_, sm)| sm.is_mailbox()) {
            if sm.master_writes() || !self.mailbox_full(n) {
                return false;
            }
            if a + out.len() as u32 > sm.last() {
                clear_full = Some(n);
            }
        }
        let s = usize::from(addr);
        out.copy_from_slice(&self.mem[s..s + out.len()]);
        if let Some(n) = clear_full {
            self.set_mailbox_full(n, false);
        }
        true
    }

    /// A physical write (APWR/FPWR/BWR and the write half of RW and RMW); false if
    /// the ESC refuses it (a full mailbox). Read-only registers keep their value.
    pub fn write(&mut self, addr: u16, data: &[u8], now_ns: u64) -> bool {
        let a = u32::from(addr);
        if a as usize + data.len() > MEM_SIZE {
            return false;
        }
        let mut mailbox_written = None;
        if let Some((n, sm)) = self.sm_at(a).filter(|(_, sm)| sm.is_mailbox()) {
            if !sm.master_writes() || self.mailbox_full(n) {
                return false;
            }
            if a + data.len() as u32 > sm.last() {
                mailbox_written = Some(n);
            }
        }
        for (i, &b) in data.iter().enumerate() {
            let r = addr as usize + i;
            if writable(r) {
                self.mem[r] = b;
            }
        }
        if overlaps(a, data.len(), REG_AL_CONTROL, 2) {
            self.al_control_written();
        }
        if overlaps(a, data.len(), REG_SII_CONTROL, 2) {
            self.sii_command();
        }
        if overlaps(a, data.len(), REG_DC_PORT_TIMES, 4) {
            self.latch_receive_times(now_ns);
        }
        if overlaps(a, data.len(), REG_DC_SYSTEM_TIME, 8) && data.len() >= 8 {
            // System time written (FRMW from the reference clock): take it over.
            let mut b = [0u8; 8];
            let off = (REG_DC_SYSTEM_TIME as usize).saturating_sub(addr as usize);
            if let Some(src) = data.get(off..off + 8) {
                b.copy_from_slice(src);
                let offset = u64::from_le_bytes(b).wrapping_sub(now_ns);
                self.put(REG_DC_OFFSET, &offset.to_le_bytes());
            }
        }
        if let Some(n) = mailbox_written {
            self.set_mailbox_full(n, true);
            self.mailbox_request(n);
        }
        true
    }

    /// Latches the DC receive times (0x0900 port times, 0x0918 receive time of the
    /// processing unit); `now_ns` is the frame's arrival at port 0. The return on port 1
    /// is not timed (reported equal to port 0 plus 100 ns per later hop).
    fn latch_receive_times(&mut self, now_ns: u64) {
        self.put(REG_DC_PORT_TIMES, &(now_ns as u32).to_le_bytes());
        self.put(REG_DC_RECEIVE_TIME, &now_ns.to_le_bytes());
    }

    /// Port 1 receive time, set by the chain that knows the hops after this device.
    pub fn set_port1_time(&mut self, t_ns: u64) {
        self.put(REG_DC_PORT_TIMES + 4, &(t_ns as u32).to_le_bytes());
    }

    /// SII EEPROM command (ETG.1000.4 6.4.3): read 8 bytes, or write one word.
    fn sii_command(&mut self) {
        let ctl = self.u16(REG_SII_CONTROL);
        let word = usize::from(self.u16(REG_SII_ADDRESS));
        if ctl & 0x0100 != 0 {
            for i in 0..8 {
                let b = self.sii.get(word * 2 + i).copied().unwrap_or(0xFF);
                self.mem[REG_SII_DATA as usize + i] = b;
            }
        } else if ctl & 0x0200 != 0
            && let Some(w) = self.sii.get_mut(word * 2..word * 2 + 2)
        {
            w.copy_from_slice(&self.mem[REG_SII_DATA as usize..REG_SII_DATA as usize + 2]);
        }
        // Done at once: not busy, no error; 8-byte reads (bit 6).
        self.mem[REG_SII_CONTROL as usize] = 0x40 | (ctl as u8 & 0x01);
        self.mem[REG_SII_CONTROL as usize + 1] = 0;
    }

    /// The AL state machine on a write of AL control (ETG.1000.6 6.4.1).
    fn al_control_written(&mut self) {
        use al_status_code as code;
        let ctl = self.u16(REG_AL_CONTROL);
        let requested = (ctl & 0x0F) as u8;
        let ack = ctl & 0x10 != 0;
        let current = self.al_state();
        if self.al_error() && !ack {
            return;
        }
        let result = match (current, requested) {
            (_, al::INIT) => Ok(al::INIT),
            (al::INIT, al::PRE_OP) => self.check_mailbox().map(|_| al::PRE_OP),
            (al::PRE_OP | al::SAFE_OP | al::OP, al::PRE_OP) => Ok(al::PRE_OP),
            (al::PRE_OP, al::SAFE_OP) => self.freeze_process_data().map(|_| {
                self.reset_sync_counters();
                al::SAFE_OP
            }),
            (al::SAFE_OP | al::OP, al::SAFE_OP) => Ok(al::SAFE_OP),
            (al::SAFE_OP, al::OP) => self.check_sync_config().map(|_| al::OP),
            (al::OP, al::OP) => Ok(al::OP),
            (_, al::BOOT) => Err(code::BOOTSTRAP_NOT_SUPPORTED),
            (_, al::SAFE_OP | al::OP) => Err(code::INVALID_STATE_CHANGE),
            _ => Err(code::UNKNOWN_STATE),
        };
        match result {
            Ok(state) => {
                if state == al::INIT {
                    self.set_mailbox_full(0, false);
                    self.set_mailbox_full(1, false);
                }
                self.set_al(state, false, 0);
            }
            Err(c) => self.set_al(current, true, c),
        }
    }

    /// SAFE-OP to OP with sync mode DC SYNC0 (0x1C32:01 = 2): SYNC0 must be activated
    /// (0x0981 bits 0 and 1) at a cycle (0x09A0) no shorter than the minimum cycle time
    /// (0x1C32:05), ETG.1020 / ETG.1000.6 table 11.
    fn check_sync_config(&self) -> Result<(), u16> {
        if self.drive.od.u16(SM_OUTPUT_PARAMETER, sub::SYNC_MODE) != sync_mode::DC_SYNC0 {
            return Ok(());
        }
        let Some((_, cycle)) = self.sync0() else {
            return Err(al_status_code::INVALID_DC_SYNC_CONFIG);
        };
        if cycle < u64::from(self.drive.od.u32(SM_OUTPUT_PARAMETER, sub::MIN_CYCLE_TIME)) {
            return Err(al_status_code::INVALID_SYNC_CYCLE_TIME);
        }
        Ok(())
    }

    /// SYNC0 start time (0x0990, system time) and cycle (0x09A0, ns) if activated.
    fn sync0(&self) -> Option<(u64, u64)> {
        let cycle = u64::from(self.u32(REG_DC_SYNC0_CYCLE));
        (self.mem[usize::from(REG_DC_SYNC_ACTIVE)] & SYNC0_ON == SYNC0_ON && cycle > 0)
            .then(|| (self.u64(REG_DC_SYNC_START), cycle))
    }

    /// Whether the drive takes its outputs at SYNC0 rather than at the frame: in OP,
    /// sync mode DC SYNC0, SYNC0 activated.
    pub fn latches_at_sync0(&self) -> bool {
        self.al_state() == al::OP
            && self.drive.od.u16(SM_OUTPUT_PARAMETER, sub::SYNC_MODE) == sync_mode::DC_SYNC0
            && self.sync0().is_some()
    }

    /// The SYNC0 events up to local time `now_ns` not yet accounted for (ETG.1020 DC
    /// synchronous mode): at the first one the newest outputs received (SM2) are copied
    /// into the RxPDO objects; every event with no new outputs since the previous one
    /// counts in 0x1C32:0B (SM-event missed) and sets 0x1C32:20 (sync error). Returns
    /// the number of events (0 when the outputs are not latched at SYNC0). A system
    /// time stepped back fires no event twice (the ESC's next pulse time stays).
    pub fn sync0_events(&mut self, now_ns: u64) -> u64 {
        if !self.latches_at_sync0() {
            self.sync0_seen = None;
            return 0;
        }
        let Some((start, cycle)) = self.sync0() else {
            return 0;
        };
        let sys = now_ns.wrapping_add(self.u64(REG_DC_OFFSET));
        let Some(seen) = self.sync0_seen else {
            // Entered OP (or SYNC0 activated) since: events from here on.
            self.sync0_seen = Some(sys);
            return 0;
        };
        if sys <= seen {
            return 0;
        }
        // Events at start + k·cycle (k >= 0) in (seen, sys].
        let upto = |t: u64| {
            if t < start {
                0
            } else {
                (t - start) / cycle + 1
            }
        };
        let events = upto(sys) - upto(seen);
        self.sync0_seen = Some(sys);
        if events == 0 {
            return 0;
        }
        let missed = if self.outputs_fresh {
            self.outputs_to_objects();
            self.outputs_fresh = false;
            self.sync0_latched += 1;
            events - 1
        } else {
            events
        };
        if missed > 0 {
            self.count(sub::SM_EVENT_MISSED, missed);
            for index in [SM_OUTPUT_PARAMETER, SM_INPUT_PARAMETER] {
                self.drive.od.set(index, sub::SYNC_ERROR, &[1]);
            }
        }
        events
    }

    /// Adds `n` to counter `sub` of 0x1C32 and 0x1C33 (saturating at u16::MAX).
    fn count(&mut self, sub: u8, n: u64) {
        for index in [SM_OUTPUT_PARAMETER, SM_INPUT_PARAMETER] {
            let v = u64::from(self.drive.od.u16(index, sub)).saturating_add(n);
            let v = u16::try_from(v).unwrap_or(u16::MAX);
            self.drive.od.set(index, sub, &v.to_le_bytes());
        }
    }

    /// The sync counters and the sync error start from zero (PRE-OP to SAFE-OP).
    fn reset_sync_counters(&mut self) {
        for index in [SM_OUTPUT_PARAMETER, SM_INPUT_PARAMETER] {
            for s in [sub::SM_EVENT_MISSED, sub::CYCLE_TIME_TOO_SMALL] {
                self.drive.od.set(index, s, &0u16.to_le_bytes());
            }
            self.drive.od.set(index, sub::SYNC_ERROR, &[0]);
        }
    }

    fn check_mailbox(&self) -> Result<(), u16> {
        let (out, inp) = (self.sm(0), self.sm(1));
        let ok = out.enabled
            && inp.enabled
            && out.start == MBX_OUT_START
            && inp.start == MBX_IN_START
            && out.len == MBX_SIZE
            && inp.len == MBX_SIZE
            && out.is_mailbox()
            && out.master_writes()
            && inp.is_mailbox()
            && !inp.master_writes();
        if ok {
            Ok(())
        } else {
            Err(al_status_code::INVALID_MAILBOX_CONFIG)
        }
    }

    /// PRE-OP to SAFE-OP: SM2/SM3 must match the PDO mapping (ETG.1000.6 6.4.2).
    fn freeze_process_data(&mut self) -> Result<(), u16> {
        let rx = self.drive.od.layout(true);
        let tx = self.drive.od.layout(false);
        let bytes =
            |l: &[MappedObject]| l.iter().map(|m| u32::from(m.bits)).sum::<u32>().div_ceil(8);
        let (sm2, sm3) = (self.sm(2), self.sm(3));
        let fits = |sm: Sm, n: u32, writes: bool| {
            if n == 0 {
                !sm.enabled || sm.len == 0
            } else {
                sm.enabled
                    && u32::from(sm.len) == n
                    && !sm.is_mailbox()
                    && sm.master_writes() == writes
                    && u32::from(sm.start) + n <= MEM_SIZE as u32
            }
        };
        if !fits(sm2, bytes(&rx), true) {
            return Err(al_status_code::INVALID_OUTPUT_CONFIG);
        }
        if !fits(sm3, bytes(&tx), false) {
            return Err(al_status_code::INVALID_INPUT_CONFIG);
        }
        self.rx_layout = rx;
        self.tx_layout = tx;
        Ok(())
    }

    /// A logical access (LRD/LWR/LRW) through the FMMUs; returns the working counter
    /// increment: +1 if inputs were read, +1 (LWR) or +2 (LRW) if outputs were written.
    pub fn logical(
        &mut self,
        laddr: u32,
        data: &mut [u8],
        read: bool,
        write: bool,
        now_ns: u64,
    ) -> u16 {
        let (mut did_read, mut did_write) = (false, false);
        let end = laddr as u64 + data.len() as u64;
        for f in 0..8 {
            let b = usize::from(REG_FMMU) + 16 * f;
            let reg = &self.mem[b..b + 16];
            if reg[12] & 0x01 == 0 {
                continue;
            }
            let lstart = u64::from(u32::from_le_bytes([reg[0], reg[1], reg[2], reg[3]]));
            let llen = u64::from(u16::from_le_bytes([reg[4], reg[5]]));
            let pstart = u64::from(u16::from_le_bytes([reg[8], reg[9]]));
            let kind = reg[11];
            let lo = lstart.max(laddr as u64);
            let hi = (lstart + llen).min(end);
            if lo >= hi || pstart + (hi - lstart) > MEM_SIZE as u64 {
                continue;
            }
            let p0 = (pstart + (lo - lstart)) as usize;
            let d0 = (lo - laddr as u64) as usize;
            let n = (hi - lo) as usize;
            let gate = self.process_data_gate(p0 as u32);
            if kind & 0x01 != 0 && read && gate.read {
                data[d0..d0 + n].copy_from_slice(&self.mem[p0..p0 + n]);
                did_read = true;
            }
            if kind & 0x02 != 0 && write && gate.write {
                self.mem[p0..p0 + n].copy_from_slice(&data[d0..d0 + n]);
                did_write = true;
            }
        }
        if did_write && self.al_state() == al::OP {
            self.outputs_written_ns = Some(now_ns);
            self.outputs_fresh = true;
            let mode = self.drive.od.u16(SM_OUTPUT_PARAMETER, sub::SYNC_MODE);
            let min = u64::from(self.drive.od.u32(SM_OUTPUT_PARAMETER, sub::MIN_CYCLE_TIME));
            if mode == sync_mode::SM_SYNCHRONOUS
                && self
                    .last_sm2_write_ns
                    .is_some_and(|t| now_ns.saturating_sub(t) < min)
            {
                self.count(sub::CYCLE_TIME_TOO_SMALL, 1);
            }
            self.last_sm2_write_ns = Some(now_ns);
            // Watchdog status (0x0440 bit 0): process data active, not expired.
            self.mem[usize::from(REG_WATCHDOG_STATUS)] |= 0x01;
        }
        u16::from(did_read)
            + if did_write {
                if read { 2 } else { 1 }
            } else {
                0
            }
    }

    /// The application deactivates the process data SyncManagers outside their states:
    /// inputs (SM3) in SAFE-OP and OP, outputs (SM2) in OP only.
    fn process_data_gate(&self, paddr: u32) -> Gate {
        match self.sm_at(paddr) {
            Some((2, _)) => Gate {
                read: false,
                write: self.al_state() == al::OP,
            },
            Some((3, _)) => Gate {
                read: matches!(self.al_state(), al::SAFE_OP | al::OP),
                write: false,
            },
            Some(_) => Gate {
                read: false,
                write: false,
            },
            None => Gate {
                read: true,
                write: true,
            },
        }
    }

    /// Copies the outputs in SM2 into the RxPDO objects (in OP).
    pub fn outputs_to_objects(&mut self) {
        let mut off = usize::from(self.sm(2).start);
        for m in self.rx_layout.clone() {
            let n = usize::from(m.bits / 8);
            if off + n <= MEM_SIZE {
                let bytes = self.mem[off..off + n].to_vec();
                self.drive.od.set(m.index, m.sub, &bytes);
            }
            off += n;
        }
    }

    /// Copies the TxPDO objects into SM3 (in SAFE-OP and OP).
    pub fn objects_to_inputs(&mut self) {
        let mut off = usize::from(self.sm(3).start);
        for m in &self.tx_layout {
            let n = usize::from(m.bits / 8);
            if let Some(src) = self.drive.od.get(m.index, m.sub)
                && off + n <= MEM_SIZE
                && src.len() >= n
            {
                self.mem[off..off + n].copy_from_slice(&src[..n]);
            }
            off += n;
        }
    }

    /// Answers the request in the write mailbox (SM0) into the read mailbox (SM1).
    fn mailbox_request(&mut self, n: usize) {
        let out = self.sm(n);
        self.set_mailbox_full(n, false);
        if self.al_state() < al::PRE_OP {
            return;
        }
        let start = usize::from(out.start);
        let req = self.mem[start..start + usize::from(out.len)].to_vec();
        let pre_op = self.al_state() == al::PRE_OP;
        let Some(resp) = crate::coe::answer(&req, &mut self.drive.od, pre_op, MBX_SIZE as usize)
        else {
            return;
        };
        // The master may have rewritten SM1 since PRE-OP: answer only into RAM.
        let inp = self.sm(1);
        let s = usize::from(inp.start);
        let len = usize::from(inp.len).min(MEM_SIZE.saturating_sub(s));
        if len == 0 {
            return;
        }
        self.mem[s..s + len].fill(0);
        let n = resp.len().min(len);
        self.mem[s..s + n].copy_from_slice(&resp[..n]);
        self.set_mailbox_full(1, true);
    }

    /// The process data watchdog time (ns): ESC 0x0420 in units of
    /// (0x0400 + 2) × 40 ns (ETG.1000.4 6.3); 0 = off.
    pub fn watchdog_ns(&self) -> u64 {
        let divider = u64::from(self.u16(REG_WATCHDOG_DIVIDER));
        (divider + 2) * 40 * u64::from(self.u16(REG_WATCHDOG_PD))
    }

    /// The process data watchdog at `now_ns` (local clock): in OP, outputs not written
    /// for longer than [`SubDevice::watchdog_ns`] expire it. The ESC clears 0x0440 bit 0
    /// and counts in 0x0442; the drive application reacts as a drive's does: an enabled
    /// power stage faults (`Drive::outputs_lost`, torque off at once) and the device
    /// leaves OP for SAFE-OP with the error bit and 0x001B (sync manager watchdog).
    /// Returns whether it expired now.
    pub fn check_watchdog(&mut self, now_ns: u64) -> bool {
        if self.al_state() != al::OP {
            return false;
        }
        let wd = self.watchdog_ns();
        let Some(since) = self.outputs_written_ns else {
            // OP entered since the last check: the watchdog runs from here.
            self.outputs_written_ns = Some(now_ns);
            return false;
        };
        if wd == 0 || now_ns.saturating_sub(since) <= wd {
            return false;
        }
        self.mem[usize::from(REG_WATCHDOG_STATUS)] &= !0x01;
        let count = self.mem[usize::from(REG_WATCHDOG_COUNTER_PD)];
        self.mem[usize::from(REG_WATCHDOG_COUNTER_PD)] = count.saturating_add(1);
        self.drive.outputs_lost();
        self.set_al(al::SAFE_OP, true, al_status_code::SM_WATCHDOG);
        true
    }

    /// Replaces the identity (SII words 0x0008-0x000B and object 0x1018).
    pub fn set_identity(&mut self, vendor_id: u32, product_code: u32) {
        sii::set_identity(&mut self.sii, vendor_id, product_code);
        self.drive.set_identity(vendor_id, product_code);
    }
}

/// Which process data directions an address takes now.
struct Gate {
    read: bool,
    write: bool,
}

/// Whether the master may change a byte of ESC memory (the rest is read-only: device
/// information, DL status, AL status, SyncManager status and PDI control, DC receive
/// times).
fn writable(r: usize) -> bool {
    match r {
        0x0000..=0x000F => false,
        0x0110..=0x0111 => false,
        0x0130..=0x0135 => false,
        0x0440..=0x0441 => false,
        0x0800..=0x087F => !matches!((r - 0x0800) % 8, 5 | 7),
        0x0900..=0x090F | 0x0918..=0x091F => false,
        _ => r < MEM_SIZE,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use microrobot_ethercat_cia402::cia402::DriveState;

    fn enabled(s: &mut SubDevice) {
        for cw in [0x0006u16, 0x0007, 0x000F] {
            s.drive.od.set(0x6040, 0, &cw.to_le_bytes());
            s.drive.control(true, 0.0, 0.0);
        }
        assert_eq!(s.drive.state(), DriveState::OperationEnabled);
    }

    /// A drive in SAFE-OP with SM2 (8 bytes at 0x1000) and SM3 (14 bytes at 0x1100)
    /// mapped, FMMU 0 writing logical 0..8 into SM2.
    fn safe_op() -> SubDevice {
        let mut s = SubDevice::new(&DriveConfig::seed_axis(0));
        let sm = |start: u16, len: u16, control: u8| {
            let mut b = [0u8; 8];
            b[..2].copy_from_slice(&start.to_le_bytes());
            b[2..4].copy_from_slice(&len.to_le_bytes());
            b[4] = control;
            b[6] = 1;
            b
        };
        assert!(s.write(REG_SM + 16, &sm(0x1000, 8, 0x64), 0));
        assert!(s.write(REG_SM + 24, &sm(0x1100, 14, 0x20), 0));
        let mut f = [0u8; 16];
        f[4..6].copy_from_slice(&8u16.to_le_bytes());
        f[7] = 7;
        f[8..10].copy_from_slice(&0x1000u16.to_le_bytes());
        f[11] = 0x02;
        f[12] = 1;
        assert!(s.write(REG_FMMU, &f, 0));
        s.set_al(al::PRE_OP, false, 0);
        s.freeze_process_data().expect("mapping");
        s.set_al(al::SAFE_OP, false, 0);
        s
    }

    /// SYNC0 at `start` every `cycle` ns, activated.
    fn sync0_on(s: &mut SubDevice, start: u64, cycle: u32) {
        assert!(s.write(REG_DC_SYNC_START, &start.to_le_bytes(), 0));
        assert!(s.write(REG_DC_SYNC0_CYCLE, &cycle.to_le_bytes(), 0));
        assert!(s.write(REG_DC_SYNC_ACTIVE, &[SYNC0_ON], 0));
    }

    fn request(s: &mut SubDevice, state: u8) -> (u8, bool, u16) {
        assert!(s.write(REG_AL_CONTROL, &[state | 0x10, 0], 0));
        (s.al_state(), s.al_error(), s.al_status_code())
    }

    /// Outputs through the FMMU: controlword 0x000F, target torque `torque`.
    fn outputs(s: &mut SubDevice, torque: i16, now: u64) {
        let mut d = [0u8; 8];
        d[..2].copy_from_slice(&0x000Fu16.to_le_bytes());
        d[2..4].copy_from_slice(&torque.to_le_bytes());
        assert_eq!(s.logical(0, &mut d, false, true, now), 1);
    }

    #[test]
    fn sm_parameter_objects_read_write_and_abort_as_etg_1020_says() {
        use crate::od::abort;
        let mut s = safe_op();
        let od = &mut s.drive.od;
        for index in [SM_OUTPUT_PARAMETER, SM_INPUT_PARAMETER] {
            assert_eq!(od.u16(index, sub::SYNC_MODE), sync_mode::FREE_RUN);
            assert_eq!(od.u16(index, sub::SYNC_MODES_SUPPORTED), 0x0007);
            assert_eq!(od.u32(index, sub::MIN_CYCLE_TIME), 125_000);
            assert_eq!(od.u32(index, sub::CALC_AND_COPY_TIME), 20_000);
            assert_eq!(od.u8(index, 0), 0x20);
            // Supported modes are written in PRE-OP; others are refused.
            assert_eq!(
                od.download(index, sub::SYNC_MODE, &2u16.to_le_bytes(), true),
                Ok(())
            );
            assert_eq!(
                od.download(index, sub::SYNC_MODE, &3u16.to_le_bytes(), true),
                Err(abort::VALUE_RANGE),
                "SYNC1 is not in 0x{index:04X}:04"
            );
            assert_eq!(
                od.download(index, sub::SYNC_MODE, &0u16.to_le_bytes(), false),
                Err(abort::DEVICE_STATE),
                "PRE-OP only"
            );
            assert_eq!(
                od.download(index, sub::SYNC_MODE, &[2], true),
                Err(abort::LENGTH_MISMATCH)
            );
            assert_eq!(
                od.download(index, sub::CYCLE_TIME, &1_000_000u32.to_le_bytes(), false),
                Ok(())
            );
            assert_eq!(od.u32(index, sub::CYCLE_TIME), 1_000_000);
            for ro in [
                sub::SYNC_MODES_SUPPORTED,
                sub::MIN_CYCLE_TIME,
                sub::SM_EVENT_MISSED,
            ] {
                let len = od.upload(index, ro).expect("exists").len();
                assert_eq!(
                    od.download(index, ro, &vec![0; len], true),
                    Err(abort::READ_ONLY)
                );
            }
        }
    }

    #[test]
    fn op_with_dc_sync0_mode_needs_sync0_activated_at_a_cycle_the_drive_supports() {
        let mut s = safe_op();
        s.drive
            .od
            .download(
                SM_OUTPUT_PARAMETER,
                sub::SYNC_MODE,
                &2u16.to_le_bytes(),
                true,
            )
            .expect("DC mode");
        assert_eq!(
            request(&mut s, al::OP),
            (al::SAFE_OP, true, al_status_code::INVALID_DC_SYNC_CONFIG)
        );
        sync0_on(&mut s, 0, 100_000);
        assert_eq!(
            request(&mut s, al::OP),
            (al::SAFE_OP, true, al_status_code::INVALID_SYNC_CYCLE_TIME),
            "100 µs is below the 125 µs minimum"
        );
        sync0_on(&mut s, 0, 1_000_000);
        assert_eq!(request(&mut s, al::OP), (al::OP, false, 0));
        // Free run needs no SYNC0.
        let mut s = safe_op();
        assert_eq!(request(&mut s, al::OP), (al::OP, false, 0));
    }

    #[test]
    fn outputs_take_effect_at_sync0_and_a_sync0_without_new_outputs_is_missed() {
        let mut s = safe_op();
        s.drive
            .od
            .download(
                SM_OUTPUT_PARAMETER,
                sub::SYNC_MODE,
                &2u16.to_le_bytes(),
                true,
            )
            .expect("DC mode");
        // SYNC0 every 1 ms from system time 0 (the DC offset is 0: local = system).
        sync0_on(&mut s, 0, 1_000_000);
        assert_eq!(request(&mut s, al::OP), (al::OP, false, 0));
        let torque = |s: &SubDevice| s.drive.od.u16(0x6071, 0) as i16;
        let missed = |s: &SubDevice| s.drive.od.u16(SM_OUTPUT_PARAMETER, sub::SM_EVENT_MISSED);
        assert_eq!(s.sync0_events(100_000), 0, "tracking starts in OP");
        outputs(&mut s, 100, 200_000);
        assert_eq!(torque(&s), 0, "not at the frame's arrival");
        assert_eq!(s.sync0_events(999_999), 0);
        assert_eq!(torque(&s), 0);
        assert_eq!(s.sync0_events(1_000_000), 1);
        assert_eq!(torque(&s), 100, "taken at SYNC0");
        assert_eq!((missed(&s), s.sync0_latched), (0, 1));
        // Two frames before one SYNC0: the newer counts, nothing is missed.
        outputs(&mut s, 200, 1_100_000);
        outputs(&mut s, 300, 1_900_000);
        assert_eq!(s.sync0_events(2_000_500), 1);
        assert_eq!((torque(&s), missed(&s)), (300, 0));
        assert_eq!(s.drive.od.u8(SM_OUTPUT_PARAMETER, sub::SYNC_ERROR), 0);
        // No frame before the next SYNC0: missed, sync error.
        assert_eq!(s.sync0_events(3_000_000), 1);
        assert_eq!(missed(&s), 1);
        assert_eq!(s.drive.od.u8(SM_OUTPUT_PARAMETER, sub::SYNC_ERROR), 1);
        // A frame, then three SYNC0 events at once: one takes it, two are missed.
        outputs(&mut s, -50, 3_500_000);
        assert_eq!(s.sync0_events(6_000_000), 3);
        assert_eq!((torque(&s), missed(&s)), (-50, 3));
        assert_eq!(s.drive.od.u16(SM_INPUT_PARAMETER, sub::SM_EVENT_MISSED), 3);
        // A system time stepped back fires no event twice.
        assert!(s.write(REG_DC_OFFSET, &(-500_000i64).to_le_bytes(), 0));
        outputs(&mut s, 7, 6_100_000);
        assert_eq!(s.sync0_events(6_400_000), 0, "system time 5.9 ms");
        assert_eq!(s.sync0_events(7_000_000), 0, "system time 6.5 ms");
        assert_eq!(s.sync0_events(7_500_000), 1, "system time 7.0 ms");
        assert_eq!((torque(&s), missed(&s)), (7, 3));
        // Out of OP and back through PRE-OP: the counters start from zero.
        assert_eq!(request(&mut s, al::PRE_OP).0, al::PRE_OP);
        s.freeze_process_data().expect("mapping");
        s.reset_sync_counters();
        assert_eq!(missed(&s), 0);
        assert_eq!(s.sync0_events(9_000_000), 0, "not in OP");
    }

    #[test]
    fn the_process_data_watchdog_expires_in_op_only_and_faults_an_enabled_drive() {
        let mut s = SubDevice::new(&DriveConfig::seed_axis(0));
        s.set_al(al::OP, false, 0);
        assert!(
            !s.check_watchdog(0) && !s.check_watchdog(10_000_000_000),
            "off at 0"
        );
        // 100 µs units (divider 2498), 10 ms.
        assert!(s.write(REG_WATCHDOG_DIVIDER, &2498u16.to_le_bytes(), 0));
        assert!(s.write(REG_WATCHDOG_PD, &100u16.to_le_bytes(), 0));
        assert_eq!(s.watchdog_ns(), 10_000_000);
        enabled(&mut s);
        s.set_al(al::SAFE_OP, false, 0);
        s.set_al(al::OP, false, 0);
        assert!(!s.check_watchdog(1_000_000), "runs from OP on");
        assert!(!s.check_watchdog(11_000_000), "not longer than 10 ms yet");
        assert!(s.check_watchdog(11_000_001));
        assert_eq!(
            (s.al_state(), s.al_error(), s.al_status_code()),
            (al::SAFE_OP, true, al_status_code::SM_WATCHDOG)
        );
        assert_eq!(s.drive.state(), DriveState::FaultReactionActive);
        assert_eq!(s.drive.od.u16(0x603F, 0), crate::drive::ERROR_COMMUNICATION);
        assert_eq!(s.drive.torque_nm(), 0.0);
        assert_eq!(s.mem[usize::from(REG_WATCHDOG_STATUS)] & 1, 0, "expired");
        assert_eq!(s.mem[usize::from(REG_WATCHDOG_COUNTER_PD)], 1);
        assert!(!s.check_watchdog(50_000_000), "once: no longer in OP");

        // A drive whose power stage is off only leaves OP.
        let mut s = SubDevice::new(&DriveConfig::seed_axis(1));
        assert!(s.write(REG_WATCHDOG_DIVIDER, &2498u16.to_le_bytes(), 0));
        assert!(s.write(REG_WATCHDOG_PD, &100u16.to_le_bytes(), 0));
        s.set_al(al::OP, false, 0);
        assert!(!s.check_watchdog(0));
        assert!(s.check_watchdog(20_000_000));
        assert_eq!(s.al_state(), al::SAFE_OP);
        assert_eq!(s.drive.state(), DriveState::SwitchOnDisabled);
        assert_eq!(s.drive.od.u16(0x603F, 0), 0);
    }
}
