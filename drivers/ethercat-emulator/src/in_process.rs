//! The in-process transport: answers the frames of an unchanged ethercrab `MainDevice`
//! straight from its PDU loop halves (`PduStorage::try_split` → `PduTx`/`PduRx`), on a
//! thread of its own. No sockets, no privileges: the fast path for unit tests.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::task::{Wake, Waker};
use std::thread::{self, JoinHandle, Thread};
use std::time::Duration;

use ethercrab::{PduRx, PduTx};

use crate::emulator::{Emulator, LateFrames};

/// Wakes the link thread when ethercrab has a frame to send.
struct ThreadWaker(Thread);

impl Wake for ThreadWaker {
    fn wake(self: Arc<Self>) {
        self.0.unpark();
    }
    fn wake_by_ref(self: &Arc<Self>) {
        self.0.unpark();
    }
}

/// A running in-process link between an ethercrab `MainDevice` and an [`Emulator`].
///
/// Each frame the MainDevice sends is answered at once, or after an injected delay
/// while later frames are answered meanwhile (the MainDevice may have given up on the
/// late one, as with a late frame on a real wire). Dropping the link stops its thread;
/// [`InProcessLink::stop`] also gives the PDU loop halves back for reuse.
#[derive(Debug)]
pub struct InProcessLink {
    stop: Arc<AtomicBool>,
    thread: Option<JoinHandle<(PduTx<'static>, PduRx<'static>)>>,
}

impl InProcessLink {
    /// Starts answering the frames of the PDU loop whose halves are `tx` and `rx`.
    pub fn spawn(
        emulator: Emulator,
        mut tx: PduTx<'static>,
        mut rx: PduRx<'static>,
    ) -> std::io::Result<InProcessLink> {
        let stop = Arc::new(AtomicBool::new(false));
        let stop2 = Arc::clone(&stop);
        let thread = thread::Builder::new()
            .name("ecat-emulator-link".into())
            .spawn(move || {
                let waker = Waker::from(Arc::new(ThreadWaker(thread::current())));
                let mut late = LateFrames::default();
                while !stop2.load(Ordering::Acquire) && !tx.should_exit() {
                    tx.replace_waker(&waker);
                    while let Some(frame) = tx.next_sendable_frame() {
                        let mut reply = None;
                        let sent = frame.send_blocking(|bytes| {
                            reply = emulator.handle_frame(bytes);
                            Ok(bytes.len())
                        });
                        match reply {
                            Some(r) if sent.is_ok() && r.delay.is_zero() => {
                                let _ = rx.receive_frame(&r.frame);
                            }
                            Some(r) if sent.is_ok() => late.hold(r),
                            _ => {}
                        }
                    }
                    emulator.check_watchdogs();
                    for frame in late.due() {
                        // A frame the MainDevice no longer waits for is refused:
                        // exactly what a late frame on the wire meets.
                        let _ = rx.receive_frame(&frame);
                    }
                    thread::park_timeout(late.wait(Duration::from_millis(2)));
                }
                (tx, rx)
            })?;
        Ok(InProcessLink {
            stop,
            thread: Some(thread),
        })
    }

    /// Stops the link, waits for its thread and returns the halves it was given (None
    /// if the thread panicked), e.g. for the next MainDevice on the same storage.
    pub fn stop(mut self) -> Option<(PduTx<'static>, PduRx<'static>)> {
        self.shutdown()
    }

    fn shutdown(&mut self) -> Option<(PduTx<'static>, PduRx<'static>)> {
        self.stop.store(true, Ordering::Release);
        let t = self.thread.take()?;
        t.thread().unpark();
        t.join().ok()
    }
}

impl Drop for InProcessLink {
    fn drop(&mut self) {
        let _ = self.shutdown();
    }
}
