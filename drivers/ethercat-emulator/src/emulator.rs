//! The chain: frames in, frames out. Parses the EtherCAT frame (ETG.1000.4 5.3:
//! EtherType 0x88A4, frame header, DLPDUs), passes every datagram through the
//! SubDevices in bus order with the addressing and working counter rules of
//! ETG.1000.4 5.4, then steps the drives and the plant once per process data exchange.

use std::sync::{Arc, Mutex, MutexGuard};
use std::time::{Duration, Instant};

use microrobot_ethercat_cia402::cia402::DriveState;
use microrobot_ethercat_cia402::dc::{SM_OUTPUT_PARAMETER, sub};

use crate::config::{ChainConfig, ConfigError, PlantKind, TimeMode};
use crate::esc::{SubDevice, al};
use crate::fault::Fault;
use crate::plant::{InertiaPlant, Plant, SeedArmPlant};

/// The EtherCAT EtherType (ETG.1000.4 5.2), the driver's definition.
pub use microrobot_ethercat_cia402::raw_socket::ETHERCAT_ETHERTYPE;
/// Delay the emulated wire adds per SubDevice passed (for the DC receive times).
const HOP_NS: u64 = 100;

/// A frame to send back and when.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Reply {
    /// The processed frame, source MAC with the locally administered bit set as the
    /// first SubDevice sets it.
    pub frame: Vec<u8>,
    /// How long to hold it before sending (a late-frame fault), zero normally.
    pub delay: Duration,
}

/// Replies held back by a late-frame fault, released when due; the transports keep
/// answering other frames meanwhile.
#[derive(Debug, Default)]
pub(crate) struct LateFrames {
    held: Vec<(Instant, Vec<u8>)>,
}

impl LateFrames {
    /// Holds `reply` until `delay` from now.
    pub fn hold(&mut self, reply: Reply) {
        self.held.push((Instant::now() + reply.delay, reply.frame));
    }

    /// Takes the frames that are due.
    pub fn due(&mut self) -> Vec<Vec<u8>> {
        let now = Instant::now();
        let mut out = Vec::new();
        let mut i = 0;
        while i < self.held.len() {
            if self.held[i].0 <= now {
                out.push(self.held.remove(i).1);
            } else {
                i += 1;
            }
        }
        out
    }

    /// Time until the next frame is due, at most `cap`.
    pub fn wait(&self, cap: Duration) -> Duration {
        let now = Instant::now();
        self.held
            .iter()
            .map(|(t, _)| t.saturating_duration_since(now))
            .min()
            .unwrap_or(cap)
            .min(cap)
    }
}

/// Frame statistics since the start.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Counters {
    /// EtherCAT frames answered.
    pub answered: u64,
    /// Frames dropped because they were malformed (never a panic).
    pub malformed: u64,
    /// Frames dropped by an injected fault (lost frames, link down).
    pub dropped_by_fault: u64,
    /// Frames that were not EtherCAT.
    pub ignored: u64,
    /// Process data exchanges (frames with a logical datagram that reached a drive).
    pub exchanges: u64,
}

/// What one drive looks like now, for tests and the status command.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DriveSnapshot {
    /// CiA 402 state.
    pub state: DriveState,
    /// Statusword, 0x6041.
    pub statusword: u16,
    /// Error code, 0x603F.
    pub error_code: u16,
    /// Modes of operation display, 0x6061.
    pub mode: i8,
    /// Position actual, 0x6064 (counts).
    pub position_counts: i32,
    /// Joint position of the plant (rad).
    pub position_rad: f64,
    /// Joint velocity of the plant (rad/s).
    pub velocity_rad_s: f64,
    /// Joint torque the drive applies (N·m).
    pub torque_nm: f64,
    /// AL status state (1 INIT, 2 PRE-OP, 4 SAFE-OP, 8 OP).
    pub al_state: u8,
    /// AL status error bit.
    pub al_error: bool,
    /// AL status code, 0x0134.
    pub al_status_code: u16,
    /// Configured station address, 0x0010.
    pub station_address: u16,
    /// Sync mode, 0x1C32:01 (0 free run, 1 SM-synchronous, 2 DC SYNC0).
    pub sync_mode: u16,
    /// Cycle time, 0x1C32:02 (ns).
    pub cycle_time_ns: u32,
    /// SM-event missed counter, 0x1C32:0B.
    pub sm_event_missed: u16,
    /// Sync error, 0x1C32:20.
    pub sync_error: bool,
    /// SYNC0 events at which the drive took new outputs.
    pub sync0_latched: u64,
}

/// An injected fault aimed at a drive that is not in the chain.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("no drive {drive}: the chain has {len} drives (0-based)")]
pub struct NoSuchDrive {
    /// The drive asked for.
    pub drive: usize,
    /// Drives in the chain.
    pub len: usize,
}

struct Chain {
    subs: Vec<SubDevice>,
    plant: Box<dyn Plant>,
    time: TimeMode,
    dc_drift_ppm: f64,
    start: Instant,
    last_exchange: Option<Instant>,
    lose: u32,
    delay: (Duration, u32),
    link_down_at: Option<usize>,
    counters: Counters,
}

/// The emulated chain: a cheap, cloneable handle shared by the transport (in-process
/// or raw socket) and the test or control channel that injects faults.
#[derive(Clone)]
pub struct Emulator {
    chain: Arc<Mutex<Chain>>,
}

impl std::fmt::Debug for Emulator {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Emulator")
            .field("drives", &self.len())
            .finish()
    }
}

/// Datagram commands (ETG.1000.4 table 12).
mod cmd {
    pub const NOP: u8 = 0;
    pub const APRD: u8 = 1;
    pub const APWR: u8 = 2;
    pub const APRW: u8 = 3;
    pub const FPRD: u8 = 4;
    pub const FPWR: u8 = 5;
    pub const FPRW: u8 = 6;
    pub const BRD: u8 = 7;
    pub const BWR: u8 = 8;
    pub const BRW: u8 = 9;
    pub const LRD: u8 = 10;
    pub const LWR: u8 = 11;
    pub const LRW: u8 = 12;
    pub const ARMW: u8 = 13;
    pub const FRMW: u8 = 14;
}

impl Emulator {
    /// A chain as configured, with the configured plant.
    pub fn new(config: &ChainConfig) -> Result<Emulator, ConfigError> {
        config.validate("<chain config>")?;
        let plant: Box<dyn Plant> = match config.plant {
            PlantKind::SeedArm => Box::new(SeedArmPlant::new().map_err(|message| ConfigError {
                origin: "<chain config>".into(),
                key: "plant".into(),
                message,
            })?),
            PlantKind::Inertia { inertia_kg_m2 } => {
                Box::new(InertiaPlant::new(config.drives.len(), inertia_kg_m2))
            }
        };
        Emulator::with_plant(config, plant)
    }

    /// A chain on a plant of your own (one axis per drive).
    pub fn with_plant(
        config: &ChainConfig,
        plant: Box<dyn Plant>,
    ) -> Result<Emulator, ConfigError> {
        config.validate("<chain config>")?;
        if plant.axes() != config.drives.len() {
            return Err(ConfigError {
                origin: "<chain config>".into(),
                key: "plant".into(),
                message: format!(
                    "the plant has {} axes, the chain {} drives",
                    plant.axes(),
                    config.drives.len()
                ),
            });
        }
        let subs: Vec<SubDevice> = config.drives.iter().map(SubDevice::new).collect();
        let mut chain = Chain {
            subs,
            plant,
            time: config.time,
            dc_drift_ppm: config.dc_drift_ppm,
            start: Instant::now(),
            last_exchange: None,
            lose: 0,
            delay: (Duration::ZERO, 0),
            link_down_at: None,
            counters: Counters::default(),
        };
        chain.update_ports();
        // Inputs valid from power on (position of the plant at rest).
        for (i, s) in chain.subs.iter_mut().enumerate() {
            s.drive
                .sense(chain.plant.position(i), chain.plant.velocity(i));
        }
        Ok(Emulator {
            chain: Arc::new(Mutex::new(chain)),
        })
    }

    fn lock(&self) -> MutexGuard<'_, Chain> {
        // A panic elsewhere while holding the lock leaves a chain that is still
        // consistent frame by frame: keep serving.
        self.chain.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// Number of drives.
    pub fn len(&self) -> usize {
        self.lock().subs.len()
    }

    /// Whether the chain has no drives (never, once built).
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Processes one Ethernet frame as the chain would: `None` if it is not answered
    /// (not EtherCAT, malformed, lost, link down). Like a first SubDevice it answers
    /// whatever the source MAC; the transport must not feed it its own replies.
    pub fn handle_frame(&self, frame: &[u8]) -> Option<Reply> {
        self.lock().handle_frame(frame)
    }

    /// Runs every SubDevice's process data watchdog on the wall clock (ESC 0x0400,
    /// 0x0420, as the master armed it): a drive in OP whose outputs were not written for
    /// longer than its watchdog time leaves OP (0x001B) and, if its power stage is on,
    /// faults with [`crate::ERROR_COMMUNICATION`] (torque off). The transports call this
    /// between frames, every few milliseconds, and every frame runs it first. Returns
    /// the drives (bus positions) that expired now.
    pub fn check_watchdogs(&self) -> Vec<usize> {
        let mut c = self.lock();
        let now = c.now_ns();
        c.check_watchdogs(now)
    }

    /// Injects a fault.
    pub fn inject(&self, fault: Fault) -> Result<(), NoSuchDrive> {
        let mut c = self.lock();
        let len = c.subs.len();
        let check = |drive: usize| {
            if drive < len {
                Ok(drive)
            } else {
                Err(NoSuchDrive { drive, len })
            }
        };
        match fault {
            Fault::DriveFault { drive, error_code } => {
                c.subs[check(drive)?].drive.fault(error_code)
            }
            Fault::DropOutOfOp {
                drive,
                al_status_code,
            } => {
                let s = &mut c.subs[check(drive)?];
                let state = s.al_state().min(al::SAFE_OP);
                s.set_al(state, true, al_status_code);
            }
            Fault::LoseFrames { count } => c.lose = count,
            Fault::DelayFrames { delay, count } => c.delay = (delay, count),
            Fault::LinkDown { position } => {
                c.link_down_at = Some(position.min(len));
                c.update_ports();
            }
            Fault::ClearLink => {
                c.lose = 0;
                c.delay = (Duration::ZERO, 0);
                c.link_down_at = None;
                c.update_ports();
            }
            Fault::WrongIdentity {
                drive,
                vendor_id,
                product_code,
            } => c.subs[check(drive)?].set_identity(vendor_id, product_code),
        }
        Ok(())
    }

    /// The state of drive `i` (bus position), if it exists.
    pub fn drive(&self, i: usize) -> Option<DriveSnapshot> {
        let c = self.lock();
        let s = c.subs.get(i)?;
        let od = &s.drive.od;
        Some(DriveSnapshot {
            state: s.drive.state(),
            statusword: od.u16(0x6041, 0),
            error_code: od.u16(0x603F, 0),
            mode: od.u8(0x6061, 0) as i8,
            position_counts: od.u32(0x6064, 0) as i32,
            position_rad: c.plant.position(i),
            velocity_rad_s: c.plant.velocity(i),
            torque_nm: s.drive.torque_nm(),
            al_state: s.al_state(),
            al_error: s.al_error(),
            al_status_code: s.al_status_code(),
            station_address: s.station_address(),
            sync_mode: od.u16(SM_OUTPUT_PARAMETER, sub::SYNC_MODE),
            cycle_time_ns: od.u32(SM_OUTPUT_PARAMETER, sub::CYCLE_TIME),
            sm_event_missed: od.u16(SM_OUTPUT_PARAMETER, sub::SM_EVENT_MISSED),
            sync_error: od.u8(SM_OUTPUT_PARAMETER, sub::SYNC_ERROR) != 0,
            sync0_latched: s.sync0_latched,
        })
    }

    /// Frame statistics.
    pub fn counters(&self) -> Counters {
        self.lock().counters
    }
}

/// A datagram's place in the frame.
struct Datagram {
    /// Offset of its 10-byte header in the frame.
    at: usize,
    command: u8,
    len: usize,
}

/// Finds the datagrams of an EtherCAT frame; `None` if it is malformed.
fn parse(frame: &[u8]) -> Option<Vec<Datagram>> {
    let h = frame.get(14..16)?;
    let h = u16::from_le_bytes([h[0], h[1]]);
    let payload_len = usize::from(h & 0x07FF);
    if h >> 12 != 1 || payload_len < 12 || frame.len() < 16 + payload_len {
        return None;
    }
    let end = 16 + payload_len;
    let mut at = 16;
    let mut out = Vec::new();
    loop {
        let hdr = frame.get(at..at + 10)?;
        let flags = u16::from_le_bytes([hdr[6], hdr[7]]);
        let len = usize::from(flags & 0x07FF);
        if at + 10 + len + 2 > end {
            return None;
        }
        out.push(Datagram {
            at,
            command: hdr[0],
            len,
        });
        at += 10 + len + 2;
        if flags & 0x8000 == 0 {
            return Some(out);
        }
    }
}

impl Chain {
    /// The drives' local clock (ns): the host's monotonic time since the start, off by
    /// `dc_drift_ppm`.
    fn now_ns(&self) -> u64 {
        let t = self.start.elapsed().as_nanos() as u64;
        if self.dc_drift_ppm == 0.0 {
            return t;
        }
        let drift = (t as f64 * self.dc_drift_ppm * 1e-6) as i64;
        t.saturating_add_signed(drift)
    }

    /// Whether the outputs of drives in DC SYNC0 mode take effect at SYNC0: on the wall
    /// clock, where the drives' DC system time runs with real time. With a fixed
    /// simulated step per exchange (lockstep, faster or slower than real time) the
    /// plant's time is not the DC time, and the outputs take effect at the exchange.
    fn sync0_latching(&self) -> bool {
        matches!(self.time, TimeMode::WallClock { .. })
    }

    /// Runs the SYNC0 events up to `now` ([`SubDevice::sync0_events`]) and, if a drive
    /// took new outputs at one, steps the drives and the plant once: a drive
    /// synchronised to SYNC0 applies its targets at SYNC0, not at the frame's arrival.
    /// SYNC0 events without new outputs are counted, not stepped: as without DC, a
    /// paused master does not make the arm move (one step per exchange, as before).
    fn sync0(&mut self, now: u64) {
        if !self.sync0_latching() {
            return;
        }
        let mut any = false;
        for (i, s) in self.subs.iter_mut().enumerate() {
            let before = s.sync0_latched;
            s.sync0_events(now + HOP_NS * i as u64);
            any |= s.sync0_latched > before;
        }
        if any {
            self.step();
        }
    }

    /// Whether a drive of the chain takes its outputs at SYNC0 (then the plant steps at
    /// SYNC0 only).
    fn synchronous(&self) -> bool {
        self.sync0_latching() && self.subs.iter().any(SubDevice::latches_at_sync0)
    }

    /// How many SubDevices a frame reaches.
    fn reached(&self) -> usize {
        self.link_down_at
            .unwrap_or(self.subs.len())
            .min(self.subs.len())
    }

    fn update_ports(&mut self) {
        let reached = self.reached();
        for (i, s) in self.subs.iter_mut().enumerate() {
            s.set_port1_open(i + 1 < reached);
        }
    }

    fn check_watchdogs(&mut self, now: u64) -> Vec<usize> {
        self.sync0(now);
        let mut expired = Vec::new();
        for (i, s) in self.subs.iter_mut().enumerate() {
            if s.check_watchdog(now) {
                // The drive completes its fault reaction on its own (no exchange comes
                // to step it): to Fault, torque off, the axis braked where it is.
                let (q, qd) = (self.plant.position(i), self.plant.velocity(i));
                s.drive.control(false, q, qd);
                s.drive.sense(q, qd);
                s.objects_to_inputs();
                expired.push(i);
            }
        }
        expired
    }

    fn handle_frame(&mut self, frame: &[u8]) -> Option<Reply> {
        let now = self.now_ns();
        // Also the SYNC0 events before this frame's arrival, with the outputs received
        // so far.
        self.check_watchdogs(now);
        if frame.len() < 14 || u16::from_be_bytes([frame[12], frame[13]]) != ETHERCAT_ETHERTYPE {
            self.counters.ignored += 1;
            return None;
        }
        let Some(datagrams) = parse(frame) else {
            self.counters.malformed += 1;
            return None;
        };
        if self.lose > 0 {
            self.lose -= 1;
            self.counters.dropped_by_fault += 1;
            return None;
        }
        let reached = self.reached();
        if reached == 0 {
            self.counters.dropped_by_fault += 1;
            return None;
        }
        let mut out = frame.to_vec();
        let mut exchange = false;
        for d in &datagrams {
            exchange |= self.datagram(&mut out, d, reached, now);
        }
        if exchange {
            self.exchange();
        }
        out[6] |= 0x02;
        let delay = if self.delay.1 > 0 {
            self.delay.1 -= 1;
            self.delay.0
        } else {
            Duration::ZERO
        };
        self.counters.answered += 1;
        Some(Reply { frame: out, delay })
    }

    /// Passes one datagram through the reached SubDevices; true if a logical command
    /// reached a drive.
    fn datagram(&mut self, frame: &mut [u8], d: &Datagram, reached: usize, now: u64) -> bool {
        let (hdr_at, data_at) = (d.at, d.at + 10);
        let wkc_at = data_at + d.len;
        let mut adp = u16::from_le_bytes([frame[hdr_at + 2], frame[hdr_at + 3]]);
        let ado = u16::from_le_bytes([frame[hdr_at + 4], frame[hdr_at + 5]]);
        let laddr = u32::from_le_bytes([
            frame[hdr_at + 2],
            frame[hdr_at + 3],
            frame[hdr_at + 4],
            frame[hdr_at + 5],
        ]);
        let mut wkc = u16::from_le_bytes([frame[wkc_at], frame[wkc_at + 1]]);
        let mut logical = false;
        let mut buf = vec![0u8; d.len];
        for i in 0..reached {
            let t = now + HOP_NS * i as u64;
            let data = &mut frame[data_at..wkc_at];
            let s = &mut self.subs[i];
            let add: u16 = match d.command {
                cmd::APRD | cmd::APWR | cmd::APRW | cmd::ARMW => {
                    let me = adp == 0;
                    adp = adp.wrapping_add(1);
                    if !me && d.command != cmd::ARMW {
                        0
                    } else {
                        physical(s, d.command, me, ado, data, &mut buf, t)
                    }
                }
                cmd::FPRD | cmd::FPWR | cmd::FPRW | cmd::FRMW => {
                    let me = adp == s.station_address();
                    if !me && d.command != cmd::FRMW {
                        0
                    } else {
                        physical(s, d.command, me, ado, data, &mut buf, t)
                    }
                }
                cmd::BRD | cmd::BWR | cmd::BRW => {
                    adp = adp.wrapping_add(1);
                    physical(s, d.command, true, ado, data, &mut buf, t)
                }
                cmd::LRD | cmd::LWR | cmd::LRW => {
                    let r = matches!(d.command, cmd::LRD | cmd::LRW);
                    let w = matches!(d.command, cmd::LWR | cmd::LRW);
                    let add = s.logical(laddr, data, r, w, t);
                    logical |= add > 0;
                    add
                }
                _ => 0,
            };
            wkc = wkc.wrapping_add(add);
            if d.command == cmd::BWR && ado == 0x0900 {
                // Port 1 sees the frame come back after the later SubDevices.
                let back = now + HOP_NS * (2 * (reached - 1) - i) as u64;
                if i + 1 < reached {
                    s.set_port1_time(back);
                }
            }
        }
        frame[hdr_at + 2..hdr_at + 4].copy_from_slice(&adp.to_le_bytes());
        frame[wkc_at..wkc_at + 2].copy_from_slice(&wkc.to_le_bytes());
        logical
    }

    /// One process data exchange: outputs to the drives (those synchronised to SYNC0
    /// take them at SYNC0 instead), then, unless a drive is synchronised to SYNC0,
    /// drives and plant one step and inputs back.
    fn exchange(&mut self) {
        self.counters.exchanges += 1;
        let synchronous = self.synchronous();
        for s in self.subs.iter_mut() {
            if s.al_state() == al::OP && !(synchronous && s.latches_at_sync0()) {
                s.outputs_to_objects();
            }
        }
        if !synchronous {
            self.step();
        }
    }

    /// Drives and plant one step (targets as last taken), inputs into SM3.
    fn step(&mut self) {
        let dt = match self.time {
            TimeMode::PerExchange { cycle_s } => cycle_s,
            TimeMode::WallClock { max_step_s } => {
                let now = Instant::now();
                let dt = self
                    .last_exchange
                    .map(|t| now.duration_since(t).as_secs_f64())
                    .unwrap_or(0.0);
                self.last_exchange = Some(now);
                dt.min(max_step_s)
            }
        };
        let n = self.subs.len();
        let mut torque = vec![0.0; n];
        let mut braked = vec![true; n];
        for (i, s) in self.subs.iter_mut().enumerate() {
            let op = s.al_state() == al::OP;
            if !op {
                s.drive.outputs_lost();
            }
            let (tau, brake) = s
                .drive
                .control(op, self.plant.position(i), self.plant.velocity(i));
            torque[i] = tau;
            braked[i] = brake;
        }
        self.plant.step(&torque, &braked, dt);
        for (i, s) in self.subs.iter_mut().enumerate() {
            s.drive
                .sense(self.plant.position(i), self.plant.velocity(i));
            if matches!(s.al_state(), al::SAFE_OP | al::OP) {
                s.objects_to_inputs();
            }
        }
    }
}

/// A physical-address command at one SubDevice; returns the working counter increment
/// (read +1, write +1, read-write: read +1 and write +2; RMW: the addressed device
/// reads, the others write).
fn physical(
    s: &mut SubDevice,
    command: u8,
    addressed: bool,
    ado: u16,
    data: &mut [u8],
    buf: &mut [u8],
    t: u64,
) -> u16 {
    match command {
        cmd::APRD | cmd::FPRD => u16::from(s.read(ado, data, t)),
        cmd::BRD if s.read(ado, buf, t) => {
            for (d, b) in data.iter_mut().zip(buf.iter()) {
                *d |= *b;
            }
            1
        }
        cmd::BRD => 0,
        cmd::APWR | cmd::FPWR | cmd::BWR => u16::from(s.write(ado, data, t)),
        cmd::APRW | cmd::FPRW | cmd::BRW => {
            let written = data.to_vec();
            let r = s.read(ado, buf, t);
            let w = s.write(ado, &written, t);
            if r {
                if command == cmd::BRW {
                    for (d, b) in data.iter_mut().zip(buf.iter()) {
                        *d |= *b;
                    }
                } else {
                    data.copy_from_slice(buf);
                }
            }
            u16::from(r) + 2 * u16::from(w)
        }
        cmd::ARMW | cmd::FRMW => {
            if addressed {
                u16::from(s.read(ado, data, t))
            } else {
                u16::from(s.write(ado, data, t))
            }
        }
        cmd::NOP => 0,
        _ => 0,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frame(command: u8, adp: u16, ado: u16, data: &[u8]) -> Vec<u8> {
        let mut f = vec![0xFF; 6];
        f.extend_from_slice(&[0x10; 6]);
        f.extend_from_slice(&ETHERCAT_ETHERTYPE.to_be_bytes());
        let len = 10 + data.len() + 2;
        f.extend_from_slice(&((len as u16) | 0x1000).to_le_bytes());
        f.extend_from_slice(&[command, 0x42]);
        f.extend_from_slice(&adp.to_le_bytes());
        f.extend_from_slice(&ado.to_le_bytes());
        f.extend_from_slice(&(data.len() as u16).to_le_bytes());
        f.extend_from_slice(&[0, 0]);
        f.extend_from_slice(data);
        f.extend_from_slice(&[0, 0]);
        f
    }

    fn wkc(f: &[u8]) -> u16 {
        u16::from_le_bytes([f[f.len() - 2], f[f.len() - 1]])
    }

    #[test]
    fn broadcast_read_counts_every_device_and_malformed_frames_are_counted() {
        let e = Emulator::new(&ChainConfig::inertia_chain(3)).expect("chain");
        let r = e
            .handle_frame(&frame(cmd::BRD, 0, 0, &[0, 0]))
            .expect("answer");
        assert_eq!(wkc(&r.frame), 3);
        assert_eq!(r.frame[6], 0x12, "locally administered bit set");
        assert_eq!(r.frame[16 + 10], 0x11, "ESC type");
        let mut bad = frame(cmd::BRD, 0, 0, &[0, 0]);
        bad.truncate(bad.len() - 3);
        assert!(e.handle_frame(&bad).is_none());
        assert!(e.handle_frame(&[1, 2, 3]).is_none());
        for cut in 0..bad.len() {
            assert!(e.handle_frame(&bad[..cut]).is_none());
        }
        assert_eq!(e.counters().malformed, bad.len() as u64 - 13);
    }

    #[test]
    fn random_and_truncated_frames_never_panic() {
        let e = Emulator::new(&ChainConfig::inertia_chain(2)).expect("chain");
        let mut x: u64 = 0x9E37_79B9_7F4A_7C15;
        let mut next = move || {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            x
        };
        for _ in 0..20_000 {
            let r = next();
            let command = (r % 16) as u8;
            let adp = if r & 0x100 != 0 {
                0x1000
            } else {
                (r >> 16) as u16
            };
            // Mostly registers and the process RAM, sometimes anywhere.
            let ado = if r & 0x200 != 0 {
                (r >> 32) as u16
            } else {
                ((r >> 32) % 0x2100) as u16
            };
            let len = ((r >> 48) % 80) as usize;
            let data: Vec<u8> = (0..len).map(|_| next() as u8).collect();
            let mut f = frame(command, adp, ado, &data);
            match next() % 4 {
                0 => f.truncate((next() as usize) % f.len()),
                1 => {
                    let i = 14 + (next() as usize) % (f.len() - 14);
                    f[i] = next() as u8;
                }
                _ => {}
            }
            let _ = e.handle_frame(&f);
        }
        let c = e.counters();
        assert!(c.malformed > 0 && c.answered > 0, "{c:?}");
    }

    #[test]
    fn auto_increment_write_then_configured_read() {
        let e = Emulator::new(&ChainConfig::inertia_chain(3)).expect("chain");
        let r = e
            .handle_frame(&frame(
                cmd::APWR,
                0u16.wrapping_sub(2),
                0x0010,
                &0x1002u16.to_le_bytes(),
            ))
            .expect("answer");
        assert_eq!(wkc(&r.frame), 1);
        let r = e
            .handle_frame(&frame(cmd::FPRD, 0x1002, 0x0010, &[0, 0]))
            .expect("answer");
        assert_eq!(wkc(&r.frame), 1);
        assert_eq!(e.drive(2).map(|d| d.station_address), Some(0x1002));
        // A read-only register keeps its value, the write still counts.
        let r = e
            .handle_frame(&frame(cmd::FPWR, 0x1002, 0x0130, &[8, 0]))
            .expect("answer");
        assert_eq!(wkc(&r.frame), 1);
        assert_eq!(e.drive(2).map(|d| d.al_state), Some(al::INIT));
    }

    #[test]
    fn refused_state_change_sets_the_error_and_code() {
        let e = Emulator::new(&ChainConfig::inertia_chain(1)).expect("chain");
        e.handle_frame(&frame(cmd::APWR, 0, 0x0120, &[al::OP, 0]))
            .expect("answer");
        let d = e.drive(0).expect("drive");
        assert_eq!(
            (d.al_state, d.al_error, d.al_status_code),
            (al::INIT, true, 0x0011)
        );
        // Without acknowledge the request is ignored; with it the error clears.
        e.handle_frame(&frame(cmd::APWR, 0, 0x0120, &[al::INIT, 0]))
            .expect("answer");
        assert!(e.drive(0).expect("drive").al_error);
        e.handle_frame(&frame(cmd::APWR, 0, 0x0120, &[al::INIT | 0x10, 0]))
            .expect("answer");
        assert!(!e.drive(0).expect("drive").al_error);
        e.handle_frame(&frame(cmd::APWR, 0, 0x0120, &[al::PRE_OP, 0]))
            .expect("answer");
        let d = e.drive(0).expect("drive");
        assert_eq!(
            (d.al_state, d.al_status_code),
            (al::INIT, 0x0016),
            "no mailbox SMs"
        );
    }
}
