//! The raw-socket transport (Linux): answers EtherCAT frames (EtherType 0x88A4) on an
//! AF_PACKET socket bound to one interface, e.g. one end of a veth pair whose other end
//! the MainDevice uses. Needs CAP_NET_RAW.

use std::io;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use crate::emulator::{Emulator, LateFrames};

/// The driver's AF_PACKET socket: one implementation for both ends of the veth pair.
pub use microrobot_ethercat_cia402::raw_socket::RawSocket;

/// How often the drives' process data watchdogs run while no frame arrives.
const WATCHDOG_POLL: Duration = Duration::from_millis(2);

/// Answers frames on `socket` until `stop` is set (checked every 2 ms, when the drives'
/// process data watchdogs run too). The socket's
/// own outgoing frames (its replies) are skipped by [`RawSocket::recv`]; malformed
/// frames are dropped and counted in [`Emulator::counters`]. Frames are answered
/// whatever their source MAC, as a first SubDevice does (a master using its NIC's
/// locally administered veth address works too).
pub fn serve(emulator: &Emulator, socket: &RawSocket, stop: &AtomicBool) -> io::Result<()> {
    let mut buf = vec![0u8; 2048];
    let mut late = LateFrames::default();
    while !stop.load(Ordering::Acquire) {
        for frame in late.due() {
            socket.send(&frame)?;
        }
        emulator.check_watchdogs();
        let wait = late.wait(WATCHDOG_POLL);
        let Some(n) = socket.recv(&mut buf, wait)? else {
            continue;
        };
        let Some(frame) = buf.get(..n) else {
            continue;
        };
        match emulator.handle_frame(frame) {
            Some(reply) if reply.delay.is_zero() => {
                socket.send(&reply.frame)?;
            }
            Some(reply) => late.hold(reply),
            None => {}
        }
    }
    Ok(())
}
