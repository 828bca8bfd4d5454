//! The raw-socket transport (Linux): ethercrab's PDU loop halves carried over an
//! AF_PACKET socket bound to the bus interface (EtherType 0x88A4, ETG.1000.4 5.2), by
//! one thread: it sends the frames ethercrab queues (its waker writes an eventfd the
//! thread polls beside the socket) and hands every received frame to ethercrab. One
//! thread, so a frame is marked sent before its answer can be taken in.
//!
//! The thread runs real-time when the service does ([`TransportRt`]): the cycle thread
//! blocks on every frame it carries, so its wake-up latency is part of each exchange.
//! It waits in poll(2) on the socket and the eventfd only; nothing on its path sleeps.
//!
//! ethercrab's own `tx_rx_task` ends at the first frame it cannot match (the late
//! answer to an exchange the master gave up on), and with it the bus. Here such a frame
//! is dropped and the loop goes on: a late frame costs one lost cycle, as it should.

use std::io;
use std::os::fd::{AsRawFd, FromRawFd, OwnedFd};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::task::{Wake, Waker};
use std::thread::{self, JoinHandle};
use std::time::Duration;

use ethercrab::{PduRx, PduTx};
use microrobot_runtime::config::RealtimeConfig;

use crate::master::{FrameGuard, Link};

/// The EtherCAT EtherType (ETG.1000.4 5.2).
pub const ETHERCAT_ETHERTYPE: u16 = 0x88A4;
/// `PACKET_IGNORE_OUTGOING` (linux/if_packet.h), not in the libc crate.
const PACKET_IGNORE_OUTGOING: libc::c_int = 23;
/// How often the threads look at the stop flag (a stop also wakes them at once).
const POLL: Duration = Duration::from_millis(10);

/// The transport thread's real-time settings: the service's `[realtime]`
/// ([`PipelineConfig::service_realtime`](microrobot_runtime::config::PipelineConfig::service_realtime)),
/// applied with [`microrobot_runtime::rt::enter_helper_thread`].
///
/// Same CPU affinity as the cycle, SCHED_FIFO one step above it ([`TransportRt::ABOVE`]):
/// the cycle thread blocks until the frame is back, so the transport never takes CPU time
/// the cycle could use, while at the same priority a frame arriving when the cycle thread
/// (between its wake and its park) or another stage of that priority on the CPU is
/// running would wait until that task blocks — time added to the exchange. Its work per
/// wake-up is bounded (a copy and a syscall per frame the master queued), so it starves
/// nothing. Where SCHED_FIFO or the affinity is not permitted the thread runs as an
/// ordinary thread, as it was created, and the process logs that once.
#[derive(Debug, Clone, PartialEq)]
pub struct TransportRt(pub RealtimeConfig);

impl TransportRt {
    /// Priority steps above the cycle's.
    pub const ABOVE: u32 = 1;

    /// Applies the settings to the calling thread; says once per process when they
    /// could not be applied (later transports fail the same way).
    fn enter(&self) {
        static SAID: AtomicBool = AtomicBool::new(false);
        match microrobot_runtime::rt::enter_helper_thread(&self.0, Self::ABOVE) {
            Ok(Some(p)) => {
                if !SAID.swap(true, Ordering::Relaxed) {
                    tracing::info!("EtherCAT transport thread: SCHED_FIFO priority {p}");
                }
            }
            Ok(None) => {}
            Err(e) => {
                if !SAID.swap(true, Ordering::Relaxed) {
                    tracing::warn!(
                        "EtherCAT transport thread: real-time settings not applied, it runs as an ordinary thread: {e}"
                    );
                }
            }
        }
    }
}

/// An AF_PACKET raw socket for EtherCAT frames on one interface: the driver's bus and
/// the emulated drive chain's end of a veth pair.
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
        // SAFETY: a valid C string, alive for the call.
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
        // SAFETY: an all-zero sockaddr_ll is valid; the fields used are set below.
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
        // The socket's own frames are not delivered back to it (Linux 4.20+), so a send
        // does not wake the receiver; on older kernels `try_recv` skips them.
        let one: libc::c_int = 1;
        // SAFETY: pointer and length describe `one`; a failure changes nothing.
        let _ = unsafe {
            libc::setsockopt(
                fd.as_raw_fd(),
                libc::SOL_PACKET,
                PACKET_IGNORE_OUTGOING,
                (&one as *const libc::c_int).cast(),
                std::mem::size_of::<libc::c_int>() as u32,
            )
        };
        Ok(RawSocket {
            fd,
            ifindex: ifindex as i32,
        })
    }

    /// A frame from the wire if one is queued (frames this host sent are skipped as
    /// `Ok(Some(0))`); `Ok(None)` when none is.
    pub fn try_recv(&self, buf: &mut [u8]) -> io::Result<Option<usize>> {
        // SAFETY: an all-zero sockaddr_ll is valid; recvfrom fills it.
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
            return Ok(Some(0));
        }
        Ok(Some(n as usize))
    }

    /// Waits up to `timeout` for a frame from the wire; `Ok(None)` on timeout or when
    /// what arrived was a frame this host sent.
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
        Ok(self.try_recv(buf)?.filter(|n| *n > 0))
    }

    /// Sends one complete Ethernet frame.
    pub fn send(&self, frame: &[u8]) -> io::Result<usize> {
        // SAFETY: an all-zero sockaddr_ll is valid; the fields used are set below.
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
            Ok(n as usize)
        }
    }
}

/// Wakes the link thread out of poll(2) by writing its eventfd.
struct EventFdWaker(OwnedFd);

impl EventFdWaker {
    fn new() -> io::Result<EventFdWaker> {
        // SAFETY: eventfd(2) with constant arguments; the result is checked.
        let fd = unsafe { libc::eventfd(0, libc::EFD_NONBLOCK | libc::EFD_CLOEXEC) };
        if fd < 0 {
            return Err(io::Error::last_os_error());
        }
        // SAFETY: a fresh descriptor owned by nothing else.
        Ok(EventFdWaker(unsafe { OwnedFd::from_raw_fd(fd) }))
    }

    fn clear(&self) {
        let mut v = 0u64;
        // SAFETY: reads 8 bytes into `v`; non-blocking, a failure leaves it set.
        let _ = unsafe { libc::read(self.0.as_raw_fd(), (&mut v as *mut u64).cast(), 8) };
    }
}

impl Wake for EventFdWaker {
    fn wake(self: Arc<Self>) {
        self.wake_by_ref();
    }
    fn wake_by_ref(self: &Arc<Self>) {
        let one = 1u64;
        // SAFETY: writes 8 bytes from `one`; non-blocking (a full counter is still set).
        let _ = unsafe { libc::write(self.0.as_raw_fd(), (&one as *const u64).cast(), 8) };
    }
}

/// The running transport; dropping it stops its thread (woken through its eventfd).
/// As a [`Link`] it stops and gives back the PDU loop halves.
pub struct RawSocketLink {
    stop: Arc<AtomicBool>,
    wake: Arc<EventFdWaker>,
    thread: Option<JoinHandle<(PduTx<'static>, PduRx<'static>)>>,
}

impl RawSocketLink {
    /// Opens `interface` and starts carrying the frames of `tx` and `rx` on a thread
    /// with the real-time settings `rt` (None: as created).
    pub fn spawn(
        interface: &str,
        mut tx: PduTx<'static>,
        mut rx: PduRx<'static>,
        guard: Arc<FrameGuard>,
        rt: Option<TransportRt>,
    ) -> io::Result<RawSocketLink> {
        let socket = RawSocket::bind(interface)?;
        let wake = Arc::new(EventFdWaker::new()?);
        let stop = Arc::new(AtomicBool::new(false));
        let st = Arc::clone(&stop);
        let wake_thread = Arc::clone(&wake);
        let thread = thread::Builder::new()
            .name("ethercat-tx-rx".into())
            .spawn(move || {
                let wake = wake_thread;
                if let Some(rt) = rt {
                    rt.enter();
                }
                let waker = Waker::from(Arc::clone(&wake));
                let mut buf = [0u8; 2048];
                let mut txbuf = [0u8; 2048];
                let ms = POLL.as_millis() as i32;
                while !st.load(Ordering::Acquire) && !tx.should_exit() {
                    tx.replace_waker(&waker);
                    // Claim the frame and copy it out under the guard (ethercrab marks it
                    // sent there: no answer can come before the copy is on the wire), then
                    // send it outside: the guard is held for a copy, never for a syscall.
                    loop {
                        let len = guard.hold(|| {
                            tx.next_sendable_frame().map(|frame| {
                                frame.send_blocking(|bytes| {
                                    let out = txbuf
                                        .get_mut(..bytes.len())
                                        .ok_or(ethercrab::error::Error::SendFrame)?;
                                    out.copy_from_slice(bytes);
                                    Ok(bytes.len())
                                })
                            })
                        });
                        match len {
                            // A frame that cannot be sent times out in the master: a
                            // lost cycle.
                            Some(Ok(n)) => {
                                let _ = socket.send(&txbuf[..n]);
                            }
                            Some(Err(_)) => {}
                            None => break,
                        }
                    }
                    let mut pfd = [
                        libc::pollfd {
                            fd: socket.fd.as_raw_fd(),
                            events: libc::POLLIN,
                            revents: 0,
                        },
                        libc::pollfd {
                            fd: wake.0.as_raw_fd(),
                            events: libc::POLLIN,
                            revents: 0,
                        },
                    ];
                    // SAFETY: two valid pollfds.
                    let r = unsafe { libc::poll(pfd.as_mut_ptr(), 2, ms) };
                    if r <= 0 {
                        continue;
                    }
                    if pfd[1].revents != 0 {
                        wake.clear();
                    }
                    loop {
                        match socket.try_recv(&mut buf) {
                            Ok(Some(0)) => {}
                            Ok(Some(n)) => {
                                // A frame nobody waits for any more (late) is dropped.
                                let _ = guard.hold(|| rx.receive_frame(&buf[..n]));
                            }
                            // A receive error (a pending socket error, which the failed
                            // call consumes) ends the drain: back to poll(2), which
                            // blocks until the next frame, without a sleep that would
                            // hold up the frames behind it.
                            Ok(None) | Err(_) => break,
                        }
                    }
                }
                (tx, rx)
            })?;
        Ok(RawSocketLink {
            stop,
            wake,
            thread: Some(thread),
        })
    }
}

impl RawSocketLink {
    fn shut_down(&mut self) -> Option<(PduTx<'static>, PduRx<'static>)> {
        self.stop.store(true, Ordering::Release);
        self.wake.wake_by_ref();
        self.thread.take().and_then(|t| t.join().ok())
    }
}

impl Link for RawSocketLink {
    fn stop(mut self: Box<Self>) -> Option<(PduTx<'static>, PduRx<'static>)> {
        self.shut_down()
    }
}

impl Drop for RawSocketLink {
    fn drop(&mut self) {
        let _ = self.shut_down();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// (policy, rt_priority) of this process's thread named `name`, from
    /// /proc/self/task/*/stat (fields 41 and 40, counted from 1).
    fn thread_scheduling(name: &str) -> Option<(i32, i32)> {
        for task in std::fs::read_dir("/proc/self/task").ok()?.flatten() {
            let comm = std::fs::read_to_string(task.path().join("comm")).unwrap_or_default();
            if comm.trim_end() != name {
                continue;
            }
            let stat = std::fs::read_to_string(task.path().join("stat")).ok()?;
            // Fields after the parenthesised command, which may hold spaces.
            let rest = &stat[stat.rfind(')')? + 2..];
            let f: Vec<&str> = rest.split(' ').collect();
            // `rest` starts at field 3 (state).
            return Some((f.get(38)?.parse().ok()?, f.get(37)?.parse().ok()?));
        }
        None
    }

    #[test]
    fn the_transport_thread_runs_one_step_above_the_cycle_or_as_created() {
        let (tx, rx, _pdu_loop) = crate::master::pdu_loop().expect("storage");
        let mut cfg = microrobot_runtime::config::PipelineConfig::default().realtime;
        cfg.cpu_affinity.clear();
        cfg.sched_fifo_priority = 10;
        let guard = Arc::new(FrameGuard::default());
        let link = match RawSocketLink::spawn("lo", tx, rx, guard, Some(TransportRt(cfg))) {
            Ok(l) => l,
            // Where raw sockets are required (CI), their absence is a failure.
            Err(e) if std::env::var("MICROROBOT_REQUIRE_NETNS").as_deref() == Ok("1") => {
                panic!("no raw socket on lo ({e}); needs CAP_NET_RAW (MICROROBOT_REQUIRE_NETNS=1)")
            }
            Err(e) => {
                println!("SKIPPED: no raw socket on lo ({e}); needs CAP_NET_RAW");
                return;
            }
        };
        // The thread names and sets itself up first thing; give it a moment (a generous
        // guard).
        let deadline = std::time::Instant::now() + Duration::from_secs(5);
        let sched = loop {
            let s = thread_scheduling("ethercat-tx-rx");
            let past = std::time::Instant::now() > deadline;
            match s {
                Some(s) if s.0 == libc::SCHED_FIFO || past => break s,
                None if past => panic!("no thread named ethercat-tx-rx"),
                _ => thread::sleep(Duration::from_millis(5)),
            }
        };
        // Where SCHED_FIFO is permitted it is the cycle's priority plus one; elsewhere
        // the thread keeps the scheduling it was created with (the test's: SCHED_OTHER).
        // SAFETY: plain syscall on the calling thread.
        let fifo_permitted = unsafe {
            let p = libc::sched_param { sched_priority: 1 };
            let ok = libc::sched_setscheduler(0, libc::SCHED_FIFO, &p) == 0;
            let p0 = libc::sched_param { sched_priority: 0 };
            libc::sched_setscheduler(0, libc::SCHED_OTHER, &p0);
            ok
        };
        if fifo_permitted {
            assert_eq!(sched, (libc::SCHED_FIFO, 10 + TransportRt::ABOVE as i32));
        } else {
            assert_eq!(sched, (libc::SCHED_OTHER, 0));
        }
        drop(link);
        assert!(thread_scheduling("ethercat-tx-rx").is_none(), "stopped");
    }
}
