//! What the driver writes to the log about lost exchanges, instead of ethercrab.
//!
//! A frame not back by the exchange's deadline is a lost cycle, ridden out up to
//! `max_lost_cycles` in a row ([`crate::master::LostCycles`]). When its answer arrives
//! after all, ethercrab (0.7.1) cannot match it to a waiting exchange and logs one
//! ERROR line per frame (`Failed to claim receiving frame …`, a `log` record of target
//! [`ETHERCRAB_LATE_FRAME_TARGET`]); over a long run on a loaded host those lines flood
//! the log. The driver process leaves that one line out ([`QUIET`]) and reports the lost
//! exchanges itself: the cycle only counts them (one relaxed atomic add), and a thread
//! of ordinary priority writes at most one summary line per period ([`LossReport`]),
//! only when there was a loss.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::thread::{self, JoinHandle};
use std::time::{Duration, Instant};

use microrobot_runtime::QuietLines;

/// The `log` target of ethercrab's per-late-frame ERROR line (its module
/// `pdu_loop::frame_element`). At exactly this target and level ethercrab 0.7.1 logs
/// nothing else; the modules below it (`receiving_frame`, `created_frame`, …) and every
/// other ethercrab target keep their errors.
pub const ETHERCRAB_LATE_FRAME_TARGET: &str = "ethercrab::pdu_loop::frame_element";

/// The lines the driver process leaves out of its log: ethercrab's ERROR per late
/// frame, which [`LossReport`] summarises.
pub const QUIET: QuietLines = QuietLines(&[(ETHERCRAB_LATE_FRAME_TARGET, tracing::Level::ERROR)]);

/// How often at most a summary line is written.
pub const REPORT_PERIOD: Duration = Duration::from_secs(1);

/// The lost-exchange counter the cycle increments and the thread that reports it: one
/// WARN line per period at most, naming the exchanges lost since the last line and since
/// start. Dropping it stops the thread after a last line for what was not reported yet.
#[derive(Debug)]
pub struct LossReport {
    lost: Arc<AtomicU64>,
    stop: Arc<AtomicBool>,
    thread: Option<JoinHandle<()>>,
}

impl LossReport {
    /// Starts the reporting thread (it logs to the tracing dispatcher current here);
    /// `context` ends each line (the deadline and the limit).
    pub fn spawn(period: Duration, context: String) -> std::io::Result<LossReport> {
        let lost = Arc::new(AtomicU64::new(0));
        let stop = Arc::new(AtomicBool::new(false));
        let (l, st) = (Arc::clone(&lost), Arc::clone(&stop));
        let dispatch = tracing::dispatcher::get_default(Clone::clone);
        let thread = thread::Builder::new()
            .name("ethercat-report".into())
            .spawn(move || {
                tracing::dispatcher::with_default(&dispatch, || {
                    let mut said = 0u64;
                    let mut since = Instant::now();
                    loop {
                        let next = since + period;
                        let stopping = st.load(Ordering::Acquire);
                        if !stopping && let Some(wait) = next.checked_duration_since(Instant::now()) {
                            thread::park_timeout(wait);
                            continue;
                        }
                        let total = l.load(Ordering::Relaxed);
                        if total > said {
                            tracing::warn!(
                                "EtherCAT: {} exchanges lost in the last {:.1} s, {total} since start ({context})",
                                total - said,
                                since.elapsed().as_secs_f64(),
                            );
                            said = total;
                        }
                        if stopping {
                            break;
                        }
                        since = Instant::now();
                    }
                });
            })?;
        Ok(LossReport {
            lost,
            stop,
            thread: Some(thread),
        })
    }

    /// One exchange lost (in the cycle: no lock, no allocation, no log).
    pub fn lost(&self) {
        self.lost.fetch_add(1, Ordering::Relaxed);
    }
}

impl Drop for LossReport {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Release);
        if let Some(t) = self.thread.take() {
            t.thread().unpark();
            let _ = t.join();
        }
    }
}
