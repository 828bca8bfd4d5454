//! The one owner of SIGINT/SIGTERM: `ctrlc` (termination feature) sets a flag and
//! signals an eventfd that every service attaches to its WaitSet, so a sleeping loop
//! wakes at once. iceoryx2's own signal handling is disabled on every Node and WaitSet.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

use iceoryx2::prelude::{FileDescriptor, FileDescriptorBased, SynchronousMultiplexing};

#[derive(Debug)]
struct Inner {
    flag: AtomicBool,
    fd: FileDescriptor,
}

/// A cloneable shutdown request: a flag plus an eventfd to attach to a WaitSet.
#[derive(Debug, Clone)]
pub struct Shutdown {
    inner: Arc<Inner>,
}

impl Shutdown {
    /// A request that nobody has made yet (not tied to signals; see [`Shutdown::install_signal_handler`]).
    pub fn new() -> std::io::Result<Self> {
        // SAFETY: plain syscall.
        let raw = unsafe { libc::eventfd(0, libc::EFD_NONBLOCK | libc::EFD_CLOEXEC) };
        if raw < 0 {
            return Err(std::io::Error::last_os_error());
        }
        let fd =
            FileDescriptor::new(raw).ok_or_else(|| std::io::Error::other("invalid eventfd"))?;
        Ok(Self {
            inner: Arc::new(Inner {
                flag: AtomicBool::new(false),
                fd,
            }),
        })
    }

    /// Makes this the process's SIGINT/SIGTERM handler (once per process).
    pub fn install_signal_handler(&self) -> Result<(), ctrlc::Error> {
        let me = self.clone();
        ctrlc::set_handler(move || me.request())
    }

    /// Asks every loop holding a clone to stop.
    pub fn request(&self) {
        self.inner.flag.store(true, Ordering::SeqCst);
        let one: u64 = 1;
        // SAFETY: writing 8 bytes from a valid u64 to our eventfd.
        unsafe {
            libc::write(
                self.inner.fd.native_handle(),
                (&one as *const u64).cast(),
                8,
            )
        };
    }

    /// Whether shutdown was requested.
    #[inline]
    pub fn is_requested(&self) -> bool {
        self.inner.flag.load(Ordering::Relaxed)
    }
}

impl FileDescriptorBased for Shutdown {
    fn file_descriptor(&self) -> &FileDescriptor {
        &self.inner.fd
    }
}

impl SynchronousMultiplexing for Shutdown {}
