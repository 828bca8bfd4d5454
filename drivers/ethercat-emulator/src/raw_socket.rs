//! The raw-socket transport (Linux): answers EtherCAT frames (EtherType 0x88A4) on an
//! AF_PACKET socket bound to one interface, e.g. one end of a veth pair whose other end
//! the MainDevice uses. Needs CAP_NET_RAW.

use std::io;
use std::os::fd::{AsRawFd, FromRawFd, OwnedFd};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use crate::emulator::{ETHERCAT_ETHERTYPE, Emulator, LateFrames};

/// An AF_PACKET raw socket receiving and sending EtherCAT frames on one interface.
#[derive(Debug)]
pub struct RawSocket {
    fd: OwnedFd,
    ifindex: i32,
}

impl RawSocket {
    /// Opens the socket on `interface` (needs CAP_NET_RAW).
    pub fn bind(interface: &str) -> io::Result<RawSocket> {
        let name = std::ffi::CString::new(interface)
            .map_err(|_| io::Error::new(io::ErrorKind::InvalidInput, "interface name has a NUL"))?;
        // SAFETY: a plain C string pointer, valid for the call.
        let ifindex = unsafe { libc::if_nametoindex(name.as_ptr()) };
        if ifindex == 0 {
            return Err(io::Error::new(
                io::ErrorKind::NotFound,
                format!("no network interface \"{interface}\""),
            ));
        }
        let proto = ETHERCAT_ETHERTYPE.to_be();
        // SAFETY: socket(2) with constant arguments; the result is checked.
        let raw = unsafe { libc::socket(libc::AF_PACKET, libc::SOCK_RAW, i32::from(proto)) };
        if raw < 0 {
            return Err(io::Error::last_os_error());
        }
        // SAFETY: `raw` is a fresh descriptor owned by nothing else.
        let fd = unsafe { OwnedFd::from_raw_fd(raw) };
        // SAFETY: zeroed sockaddr_ll is a valid value; fields set below.
        let mut addr: libc::sockaddr_ll = unsafe { std::mem::zeroed() };
        addr.sll_family = libc::AF_PACKET as u16;
        addr.sll_protocol = proto;
        addr.sll_ifindex = ifindex as i32;
        // SAFETY: pointer and length describe `addr`.
        let r = unsafe {
            libc::bind(
                fd.as_raw_fd(),
                (&addr as *const libc::sockaddr_ll).cast(),
                std::mem::size_of::<libc::sockaddr_ll>() as u32,
            )
        };
        if r < 0 {
            return Err(io::Error::last_os_error());
        }
        Ok(RawSocket {
            fd,
            ifindex: ifindex as i32,
        })
    }

    /// Waits up to `timeout` for a frame that arrived on the interface (frames this
    /// host sent are skipped); `Ok(None)` on timeout.
    pub fn recv(&self, buf: &mut [u8], timeout: Duration) -> io::Result<Option<usize>> {
        let mut pfd = libc::pollfd {
            fd: self.fd.as_raw_fd(),
            events: libc::POLLIN,
            revents: 0,
        };
        let ms = timeout.as_millis().min(i32::MAX as u128) as i32;
        // SAFETY: one valid pollfd.
        let r = unsafe { libc::poll(&mut pfd, 1, ms) };
        if r < 0 {
            let e = io::Error::last_os_error();
            return if e.kind() == io::ErrorKind::Interrupted {
                Ok(None)
            } else {
                Err(e)
            };
        }
        if r == 0 {
            return Ok(None);
        }
        // SAFETY: zeroed sockaddr_ll is valid; recvfrom fills it.
        let mut from: libc::sockaddr_ll = unsafe { std::mem::zeroed() };
        let mut from_len = std::mem::size_of::<libc::sockaddr_ll>() as u32;
        // SAFETY: buffer and address pointers with their lengths.
        let n = unsafe {
            libc::recvfrom(
                self.fd.as_raw_fd(),
                buf.as_mut_ptr().cast(),
                buf.len(),
                libc::MSG_DONTWAIT,
                (&mut from as *mut libc::sockaddr_ll).cast(),
                &mut from_len,
            )
        };
        if n < 0 {
            let e = io::Error::last_os_error();
            return if matches!(
                e.kind(),
                io::ErrorKind::WouldBlock | io::ErrorKind::Interrupted
            ) {
                Ok(None)
            } else {
                Err(e)
            };
        }
        if from.sll_pkttype == libc::PACKET_OUTGOING {
            return Ok(None);
        }
        Ok(Some(n as usize))
    }

    /// Sends one complete Ethernet frame.
    pub fn send(&self, frame: &[u8]) -> io::Result<()> {
        // SAFETY: zeroed sockaddr_ll is valid; fields set below.
        let mut to: libc::sockaddr_ll = unsafe { std::mem::zeroed() };
        to.sll_family = libc::AF_PACKET as u16;
        to.sll_protocol = ETHERCAT_ETHERTYPE.to_be();
        to.sll_ifindex = self.ifindex;
        to.sll_halen = 6;
        if let Some(dst) = frame.get(..6) {
            to.sll_addr[..6].copy_from_slice(dst);
        }
        // SAFETY: buffer and address pointers with their lengths.
        let n = unsafe {
            libc::sendto(
                self.fd.as_raw_fd(),
                frame.as_ptr().cast(),
                frame.len(),
                0,
                (&to as *const libc::sockaddr_ll).cast(),
                std::mem::size_of::<libc::sockaddr_ll>() as u32,
            )
        };
        if n < 0 {
            Err(io::Error::last_os_error())
        } else {
            Ok(())
        }
    }
}

/// Answers frames on `socket` until `stop` is set (checked every 50 ms). The socket's
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
        let wait = late.wait(Duration::from_millis(50));
        let Some(n) = socket.recv(&mut buf, wait)? else {
            continue;
        };
        let Some(frame) = buf.get(..n) else {
            continue;
        };
        match emulator.handle_frame(frame) {
            Some(reply) if reply.delay.is_zero() => socket.send(&reply.frame)?,
            Some(reply) => late.hold(reply),
            None => {}
        }
    }
    Ok(())
}
