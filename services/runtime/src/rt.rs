//! Per-process real-time settings: CPU affinity, PM QoS (`/dev/cpu_dma_latency`), timer
//! slack, SCHED_FIFO and mlockall. Each one is applied independently; one that is not
//! permitted (or not possible on this machine) logs exactly one warning and the service
//! goes on without it. Defaults are the best measured on the reference 2-vCPU VM (a
//! three-process iceoryx2 chain, 60 s per setting, 2026-11-22): all stages pinned to one
//! CPU, PM QoS 0, 1 ns slack.

use std::fs::File;
use std::io::Write;

use crate::config::RealtimeConfig;

/// What was applied; keeps the PM QoS file open (the request lasts while it is open).
#[derive(Debug, Default)]
pub struct RtGuard {
    pm_qos: Option<File>,
    /// Settings that were applied, for the startup log line.
    pub applied: Vec<&'static str>,
    /// Settings that fell back (each was warned about once).
    pub fallbacks: Vec<&'static str>,
    /// The SCHED_FIFO priority the cycle runs at, when it was applied.
    pub fifo_priority: Option<i32>,
}

impl RtGuard {
    /// Whether the PM QoS request is being held.
    pub fn pm_qos_held(&self) -> bool {
        self.pm_qos.is_some()
    }
}

fn errno() -> std::io::Error {
    std::io::Error::last_os_error()
}

fn note(ok: Result<(), String>, name: &'static str, g: &mut RtGuard) {
    match ok {
        Ok(()) => g.applied.push(name),
        Err(e) => {
            tracing::warn!("real-time setting `{name}` not applied, continuing without it: {e}");
            g.fallbacks.push(name);
        }
    }
}

/// Applies `cfg` to the calling process (and, for the scheduler, its current thread):
/// [`prepare`] and [`enter_cycle`] at once (a bare timer loop has nothing to set up).
pub fn apply(cfg: &RealtimeConfig) -> RtGuard {
    let mut g = prepare(cfg);
    enter_cycle(cfg, &mut g);
    g
}

/// The settings a service takes before it sets up: PM QoS, timer slack and mlockall
/// (so everything it maps from here on is locked). Not the CPU and the scheduler: a
/// (re)starting service sets up — loads its model, opens its ports, faults in and locks
/// its shared memory, for milliseconds — as an ordinary task wherever the kernel puts it,
/// and so never holds up the running pipeline's SCHED_FIFO stages on their CPU.
pub fn prepare(cfg: &RealtimeConfig) -> RtGuard {
    let mut g = RtGuard::default();
    if cfg.pm_qos {
        match File::options().write(true).open("/dev/cpu_dma_latency") {
            Ok(mut f) => {
                let v: i32 = cfg.pm_qos_latency_us as i32;
                match f.write_all(&v.to_ne_bytes()) {
                    Ok(()) => {
                        g.pm_qos = Some(f);
                        g.applied.push("pm_qos");
                    }
                    Err(e) => note(
                        Err(format!("write /dev/cpu_dma_latency: {e}")),
                        "pm_qos",
                        &mut g,
                    ),
                }
            }
            Err(e) => note(
                Err(format!("open /dev/cpu_dma_latency: {e}")),
                "pm_qos",
                &mut g,
            ),
        }
    }
    if cfg.timer_slack_ns > 0 {
        // SAFETY: prctl with PR_SET_TIMERSLACK takes an unsigned long value.
        let r = unsafe {
            libc::prctl(
                libc::PR_SET_TIMERSLACK,
                cfg.timer_slack_ns as libc::c_ulong,
                0,
                0,
                0,
            )
        };
        note(
            if r == 0 {
                Ok(())
            } else {
                Err(format!("prctl(PR_SET_TIMERSLACK): {}", errno()))
            },
            "timer_slack_ns",
            &mut g,
        );
    }
    if cfg.mlockall {
        // SAFETY: plain syscall, no pointers.
        let r = unsafe { libc::mlockall(libc::MCL_CURRENT | libc::MCL_FUTURE) };
        note(
            if r == 0 {
                Ok(())
            } else {
                Err(format!("mlockall: {}", errno()))
            },
            "mlockall",
            &mut g,
        );
    }
    g
}

/// The settings for the cyclic loop, taken right before it starts: CPU affinity and
/// SCHED_FIFO (recorded in `g`).
pub fn enter_cycle(cfg: &RealtimeConfig, g: &mut RtGuard) {
    if !cfg.cpu_affinity.is_empty() {
        let r = set_affinity(&cfg.cpu_affinity);
        note(r, "cpu_affinity", g);
    }
    if cfg.sched_fifo_priority > 0 {
        let priority = cfg.sched_fifo_priority as i32;
        let ok = set_scheduler(libc::SCHED_FIFO, priority);
        if ok {
            g.fifo_priority = Some(priority);
        }
        note(
            if ok {
                Ok(())
            } else {
                Err(format!("sched_setscheduler(SCHED_FIFO): {}", errno()))
            },
            "sched_fifo_priority",
            g,
        );
    }
}

/// The settings for a thread the cycle blocks on (a bus transport that carries the
/// cycle's frames): the cycle's CPU affinity and SCHED_FIFO at the cycle's priority plus
/// `above` (at most 99), as `cfg` says, each applied independently. Returns the FIFO
/// priority taken (None when `cfg` asks for none), or the text of what was not applied;
/// it warns about nothing itself, so a caller that starts such a thread more than once
/// can say so once.
pub fn enter_helper_thread(cfg: &RealtimeConfig, above: u32) -> Result<Option<i32>, String> {
    let mut failed = Vec::new();
    if !cfg.cpu_affinity.is_empty()
        && let Err(e) = set_affinity(&cfg.cpu_affinity)
    {
        failed.push(format!("cpu_affinity: {e}"));
    }
    let mut fifo = None;
    if cfg.sched_fifo_priority > 0 {
        let priority = cfg.sched_fifo_priority.saturating_add(above).min(99) as i32;
        if set_scheduler(libc::SCHED_FIFO, priority) {
            fifo = Some(priority);
        } else {
            failed.push(format!(
                "sched_setscheduler(SCHED_FIFO, {priority}): {}",
                errno()
            ));
        }
    }
    if failed.is_empty() {
        Ok(fifo)
    } else {
        Err(failed.join("; "))
    }
}

/// Housekeeping a cycle does after its real work (its status: percentiles, CPU time,
/// memory, the publish) runs one step below the cycle's SCHED_FIFO priority: a stage
/// that this process's message just woke on the same CPU (equal priority, so it would
/// otherwise wait for this one to block) runs first, and the housekeeping takes the
/// CPU when the pipeline's hops are done. Two `sched_setscheduler` calls per use; a
/// cycle that is not SCHED_FIFO runs the work as it is.
#[derive(Debug)]
pub struct Housekeeping {
    fifo_priority: Option<i32>,
    /// A priority restore failed once (warned once; later failures are silent).
    restore_failed: bool,
}

impl Housekeeping {
    /// For a cycle running at `fifo_priority` (None: not real-time).
    pub fn new(fifo_priority: Option<i32>) -> Self {
        Self {
            fifo_priority,
            restore_failed: false,
        }
    }

    /// Runs `work` below the cycle's priority (SCHED_FIFO one lower, or SCHED_OTHER
    /// for priority 1) and restores the cycle's priority after it.
    pub fn run<R>(&mut self, work: impl FnOnce() -> R) -> R {
        let Some(p) = self.fifo_priority else {
            return work();
        };
        let (policy, below) = if p > 1 {
            (libc::SCHED_FIFO, p - 1)
        } else {
            (libc::SCHED_OTHER, 0)
        };
        let lowered = set_scheduler(policy, below);
        let out = work();
        if lowered && !set_scheduler(libc::SCHED_FIFO, p) && !self.restore_failed {
            self.restore_failed = true;
            tracing::warn!(
                "could not restore SCHED_FIFO priority {p} after the status work: {}",
                errno()
            );
        }
        out
    }
}

/// Sets the calling thread's policy and priority; true on success.
fn set_scheduler(policy: i32, priority: i32) -> bool {
    let param = libc::sched_param {
        sched_priority: priority,
    };
    // SAFETY: `param` is a valid sched_param; pid 0 is the calling thread.
    unsafe { libc::sched_setscheduler(0, policy, &param) == 0 }
}

fn set_affinity(cpus: &[usize]) -> Result<(), String> {
    // SAFETY: sysconf has no preconditions.
    let online = unsafe { libc::sysconf(libc::_SC_NPROCESSORS_ONLN) }.max(1) as usize;
    // SAFETY: an all-zero cpu_set_t is a valid empty set.
    let mut set: libc::cpu_set_t = unsafe { std::mem::zeroed() };
    let mut any = false;
    for &c in cpus {
        if c < online && c < libc::CPU_SETSIZE as usize {
            // SAFETY: `c` is below CPU_SETSIZE.
            unsafe { libc::CPU_SET(c, &mut set) };
            any = true;
        }
    }
    if !any {
        return Err(format!("none of CPUs {cpus:?} is online ({online} online)"));
    }
    // SAFETY: `set` is a valid cpu_set_t of the size passed.
    let r = unsafe { libc::sched_setaffinity(0, std::mem::size_of::<libc::cpu_set_t>(), &set) };
    if r == 0 {
        Ok(())
    } else {
        Err(format!("sched_setaffinity: {}", errno()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The calling thread's (policy, priority).
    fn scheduling() -> (i32, i32) {
        // SAFETY: pid 0 is the calling thread; `p` is a valid, writable sched_param.
        let policy = unsafe { libc::sched_getscheduler(0) };
        let mut p = libc::sched_param { sched_priority: 0 };
        // SAFETY: as above.
        unsafe { libc::sched_getparam(0, &mut p) };
        (policy, p.sched_priority)
    }

    #[test]
    fn a_helper_thread_runs_above_the_cycle_or_as_it_was() {
        std::thread::spawn(|| {
            let before = scheduling();
            let cfg = RealtimeConfig {
                cpu_affinity: Vec::new(),
                pm_qos: false,
                pm_qos_latency_us: 0,
                timer_slack_ns: 0,
                sched_fifo_priority: 0,
                mlockall: false,
                overrun: crate::config::OverrunPolicy::Skip,
            };
            assert_eq!(enter_helper_thread(&cfg, 1), Ok(None));
            assert_eq!(scheduling(), before, "nothing asked, nothing changed");
            let cfg = RealtimeConfig {
                sched_fifo_priority: 99,
                ..cfg
            };
            match enter_helper_thread(&cfg, 1) {
                // Capped at the highest SCHED_FIFO priority.
                Ok(p) => {
                    assert_eq!(p, Some(99));
                    assert_eq!(scheduling(), (libc::SCHED_FIFO, 99));
                }
                // Not permitted here: the thread keeps its scheduling.
                Err(e) => {
                    assert!(e.contains("SCHED_FIFO, 99"), "{e}");
                    assert_eq!(scheduling(), before);
                }
            }
        })
        .join()
        .expect("the helper thread");
    }

    #[test]
    fn housekeeping_runs_one_step_below_the_cycle_and_restores_it() {
        // Its own thread: the test harness's threads keep their scheduling.
        std::thread::spawn(|| {
            let before = scheduling();
            assert_eq!(Housekeeping::new(None).run(scheduling), before);
            if set_scheduler(libc::SCHED_FIFO, 10) {
                let mut h = Housekeeping::new(Some(10));
                assert_eq!(h.run(scheduling), (libc::SCHED_FIFO, 9));
                assert_eq!(scheduling(), (libc::SCHED_FIFO, 10));
                assert!(set_scheduler(libc::SCHED_FIFO, 1));
                let mut h = Housekeeping::new(Some(1));
                assert_eq!(h.run(scheduling), (libc::SCHED_OTHER, 0));
                assert_eq!(scheduling(), (libc::SCHED_FIFO, 1));
                assert!(!h.restore_failed);
            } else {
                // Not permitted here (no CAP_SYS_NICE or RLIMIT_RTPRIO): the lowering
                // fails too, the work runs as it is and nothing is changed.
                let mut h = Housekeeping::new(Some(10));
                assert_eq!(h.run(scheduling), before);
                assert_eq!(scheduling(), before);
            }
        })
        .join()
        .expect("the housekeeping thread");
    }
}
