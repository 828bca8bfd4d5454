//! The services' wait: one level-triggered `epoll` over the file descriptors a loop
//! sleeps on (iceoryx2 event listeners, the timerfd, the shutdown eventfd).
//!
//! Why not iceoryx2's `WaitSet`: it is an epoll reactor too, but each
//! `wait_and_process_once` allocates (about twice per wake-up in callgrind) and walks a
//! callback per attachment. The control cycle allocates nothing, so the services wait
//! here instead: one `epoll_wait` into a fixed array, and a bit set of which sources
//! fired. The semantics are the WaitSet's: a listener stays ready until it is drained
//! (`Listener::try_wait`), a timerfd until it is read.

use std::marker::PhantomData;

use iceoryx2::prelude::FileDescriptorBased;

/// At most this many sources per reactor (a service waits on four).
pub const MAX_SOURCES: usize = 8;

/// A source registered with [`Reactor::add`]; test it in the [`Ready`] set.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Source(u8);

/// The sources that were ready when [`Reactor::wait`] returned.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Ready(u32);

impl Ready {
    /// Whether `source` was ready.
    pub fn contains(self, source: Source) -> bool {
        self.0 & (1 << source.0) != 0
    }

    /// Whether `source` (if there is one) was ready.
    pub fn contains_opt(self, source: Option<Source>) -> bool {
        source.is_some_and(|s| self.contains(s))
    }

    /// Whether nothing was ready (a timeout or a signal interrupted the wait).
    pub fn is_empty(self) -> bool {
        self.0 == 0
    }
}

/// An epoll instance over borrowed file descriptors: the borrow (`'fd`) keeps every
/// registered descriptor open for as long as the reactor can report it.
#[derive(Debug)]
pub struct Reactor<'fd> {
    epfd: i32,
    sources: u8,
    events: [libc::epoll_event; MAX_SOURCES],
    _fds: PhantomData<&'fd ()>,
}

impl<'fd> Reactor<'fd> {
    /// An empty reactor.
    pub fn new() -> std::io::Result<Self> {
        // SAFETY: plain syscall.
        let epfd = unsafe { libc::epoll_create1(libc::EPOLL_CLOEXEC) };
        if epfd < 0 {
            return Err(std::io::Error::last_os_error());
        }
        Ok(Self {
            epfd,
            sources: 0,
            events: [libc::epoll_event { events: 0, u64: 0 }; MAX_SOURCES],
            _fds: PhantomData,
        })
    }

    /// Registers `fd` for readability (level-triggered).
    pub fn add<F: FileDescriptorBased + ?Sized>(&mut self, fd: &'fd F) -> std::io::Result<Source> {
        if usize::from(self.sources) >= MAX_SOURCES {
            return Err(std::io::Error::other(format!(
                "a reactor holds at most {MAX_SOURCES} sources"
            )));
        }
        let index = self.sources;
        let mut ev = libc::epoll_event {
            events: libc::EPOLLIN as u32,
            u64: u64::from(index),
        };
        // SAFETY: `fd` is borrowed for 'fd, so the descriptor stays open while
        // registered; `ev` is a valid event.
        let r = unsafe {
            libc::epoll_ctl(
                self.epfd,
                libc::EPOLL_CTL_ADD,
                fd.file_descriptor().native_handle(),
                &mut ev,
            )
        };
        if r != 0 {
            return Err(std::io::Error::last_os_error());
        }
        self.sources += 1;
        Ok(Source(index))
    }

    /// Blocks until at least one source is ready. A signal that interrupts the wait
    /// returns an empty set (the caller checks its shutdown flag and waits again).
    pub fn wait(&mut self) -> std::io::Result<Ready> {
        self.wait_ms(-1)
    }

    /// As [`Reactor::wait`], but returns an empty set after `timeout_ms` (-1: never).
    pub fn wait_ms(&mut self, timeout_ms: i32) -> std::io::Result<Ready> {
        // SAFETY: `events` holds MAX_SOURCES entries, the count passed.
        let n = unsafe {
            libc::epoll_wait(
                self.epfd,
                self.events.as_mut_ptr(),
                MAX_SOURCES as i32,
                timeout_ms,
            )
        };
        if n < 0 {
            let e = std::io::Error::last_os_error();
            return if e.kind() == std::io::ErrorKind::Interrupted {
                Ok(Ready::default())
            } else {
                Err(e)
            };
        }
        let mut ready = 0u32;
        for ev in &self.events[..n as usize] {
            // Readable, or hung up / in error (then the owner's read reports it).
            ready |= 1 << (ev.u64 as u32 % MAX_SOURCES as u32);
        }
        Ok(Ready(ready))
    }
}

impl Drop for Reactor<'_> {
    fn drop(&mut self) {
        // SAFETY: we own `epfd`.
        unsafe { libc::close(self.epfd) };
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::TimerFd;
    use microrobot_messages::monotonic_ns;

    #[test]
    fn reports_exactly_the_sources_that_are_ready_and_stays_level_triggered() {
        let a = TimerFd::new().unwrap();
        let b = TimerFd::new().unwrap();
        let mut r = Reactor::new().unwrap();
        let sa = r.add(&a).unwrap();
        let sb = r.add(&b).unwrap();
        assert!(r.wait_ms(0).unwrap().is_empty());

        b.arm_absolute(monotonic_ns(), 0).unwrap();
        let ready = r.wait_ms(5_000).unwrap();
        assert!(ready.contains(sb) && !ready.contains(sa));
        // Level-triggered: still ready until read, then not.
        assert!(r.wait_ms(0).unwrap().contains(sb));
        assert_eq!(b.read_expirations(), 1);
        assert!(r.wait_ms(0).unwrap().is_empty());
    }

    #[test]
    fn refuses_more_sources_than_it_can_report() {
        let timers: Vec<TimerFd> = (0..=MAX_SOURCES).map(|_| TimerFd::new().unwrap()).collect();
        let mut r = Reactor::new().unwrap();
        for t in &timers[..MAX_SOURCES] {
            r.add(t).unwrap();
        }
        assert!(r.add(&timers[MAX_SOURCES]).is_err());
    }
}
