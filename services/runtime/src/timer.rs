//! Absolute monotonic deadlines from a `timerfd` (CLOCK_MONOTONIC, TFD_TIMER_ABSTIME,
//! periodic), attachable to an iceoryx2 WaitSet. The kernel keeps the grid
//! `start + n·period`, so the clock never drifts; a read returns how many grid points
//! passed, which is how overruns are seen. Never `WaitSet::attach_interval`: its 1 ms
//! resolution stretches a 1 kHz period to ~1.09 ms (measured with iceoryx2 0.10).

use std::cell::Cell;

use iceoryx2::prelude::{FileDescriptor, FileDescriptorBased, SynchronousMultiplexing};
use microrobot_messages::monotonic_ns;

use crate::config::OverrunPolicy;

/// A non-blocking CLOCK_MONOTONIC timerfd.
#[derive(Debug)]
pub struct TimerFd {
    fd: FileDescriptor,
}

impl FileDescriptorBased for TimerFd {
    fn file_descriptor(&self) -> &FileDescriptor {
        &self.fd
    }
}

impl SynchronousMultiplexing for TimerFd {}

fn ts(ns: u64) -> libc::timespec {
    libc::timespec {
        tv_sec: (ns / 1_000_000_000) as libc::time_t,
        tv_nsec: (ns % 1_000_000_000) as libc::c_long,
    }
}

impl TimerFd {
    /// Creates an unarmed timer.
    pub fn new() -> std::io::Result<Self> {
        // SAFETY: plain syscall.
        let raw = unsafe {
            libc::timerfd_create(
                libc::CLOCK_MONOTONIC,
                libc::TFD_NONBLOCK | libc::TFD_CLOEXEC,
            )
        };
        if raw < 0 {
            return Err(std::io::Error::last_os_error());
        }
        let fd =
            FileDescriptor::new(raw).ok_or_else(|| std::io::Error::other("invalid timerfd"))?;
        Ok(Self { fd })
    }

    /// Arms the timer to fire at absolute `first_ns` and every `period_ns` after it
    /// (`period_ns` 0: once).
    pub fn arm_absolute(&self, first_ns: u64, period_ns: u64) -> std::io::Result<()> {
        let spec = libc::itimerspec {
            it_interval: ts(period_ns),
            it_value: ts(first_ns.max(1)),
        };
        // SAFETY: `spec` is valid; the old value pointer may be null.
        let r = unsafe {
            libc::timerfd_settime(
                self.fd.native_handle(),
                libc::TFD_TIMER_ABSTIME,
                &spec,
                std::ptr::null_mut(),
            )
        };
        if r != 0 {
            return Err(std::io::Error::last_os_error());
        }
        Ok(())
    }

    /// Stops the timer.
    pub fn disarm(&self) -> std::io::Result<()> {
        let spec = libc::itimerspec {
            it_interval: ts(0),
            it_value: ts(0),
        };
        // SAFETY: `spec` is valid; the old value pointer may be null.
        let r = unsafe {
            libc::timerfd_settime(self.fd.native_handle(), 0, &spec, std::ptr::null_mut())
        };
        if r != 0 {
            return Err(std::io::Error::last_os_error());
        }
        Ok(())
    }

    /// Reads and clears the expiration count (0 when the timer has not fired).
    pub fn read_expirations(&self) -> u64 {
        let mut buf = [0u8; 8];
        // SAFETY: reading 8 bytes into an 8-byte buffer.
        let n = unsafe { libc::read(self.fd.native_handle(), buf.as_mut_ptr().cast(), buf.len()) };
        if n == 8 { u64::from_ne_bytes(buf) } else { 0 }
    }
}

/// A periodic grid from two [`TimerFd`]s that take turns, each firing every second grid
/// point, behind one epoll fd to wait on.
///
/// Why two: the kernel re-arms a periodic timerfd when it is read; when that makes it the
/// CPU's next timer to expire, the kernel reprograms the clock-event device, which in a
/// virtual machine is an exit to the hypervisor (5.4 µs per tick on the reference VM). With
/// two, the timer just read is re-armed behind the other one, already queued for the next
/// grid point, and only the timer interrupt programs the device (0.65 µs per read;
/// `cargo run --release -p microrobot-runtime --example timer_move`).
#[derive(Debug)]
pub struct TickTimer {
    timers: [TimerFd; 2],
    epoll: FileDescriptor,
    /// Next expiration of each timer (ns; `u64::MAX`: disarmed or done).
    next_ns: [Cell<u64>; 2],
    /// Each timer's own period (ns; 0: one-shot).
    interval_ns: Cell<u64>,
}

impl FileDescriptorBased for TickTimer {
    fn file_descriptor(&self) -> &FileDescriptor {
        &self.epoll
    }
}

impl SynchronousMultiplexing for TickTimer {}

impl TickTimer {
    /// Two unarmed timers.
    pub fn new() -> std::io::Result<Self> {
        let timers = [TimerFd::new()?, TimerFd::new()?];
        // SAFETY: plain syscall.
        let raw = unsafe { libc::epoll_create1(libc::EPOLL_CLOEXEC) };
        if raw < 0 {
            return Err(std::io::Error::last_os_error());
        }
        let epoll =
            FileDescriptor::new(raw).ok_or_else(|| std::io::Error::other("invalid epoll fd"))?;
        for t in &timers {
            // SAFETY: the timer owns the fd, open for its lifetime.
            let fd = unsafe { t.fd.native_handle() };
            let mut ev = libc::epoll_event {
                events: libc::EPOLLIN as u32,
                u64: fd as u64,
            };
            // SAFETY: both fds are open; `ev` is valid for the call.
            if unsafe { libc::epoll_ctl(raw, libc::EPOLL_CTL_ADD, fd, &mut ev) } != 0 {
                return Err(std::io::Error::last_os_error());
            }
        }
        Ok(Self {
            timers,
            epoll,
            next_ns: [Cell::new(u64::MAX), Cell::new(u64::MAX)],
            interval_ns: Cell::new(0),
        })
    }

    /// Fires at absolute `first_ns` and every `period_ns` after it (`period_ns` 0: once):
    /// one timer at the even grid points, the other at the odd ones.
    pub fn arm_absolute(&self, first_ns: u64, period_ns: u64) -> std::io::Result<()> {
        let interval = period_ns.saturating_mul(2);
        self.timers[0].arm_absolute(first_ns, interval)?;
        let second = if period_ns == 0 {
            self.timers[1].disarm()?;
            u64::MAX
        } else {
            let at = first_ns.max(1) + period_ns;
            self.timers[1].arm_absolute(at, interval)?;
            at
        };
        self.next_ns[0].set(first_ns.max(1));
        self.next_ns[1].set(second);
        self.interval_ns.set(interval);
        Ok(())
    }

    /// Reads and clears the grid points passed since the last read (0 when none): only
    /// the timers whose next expiration has come are read.
    pub fn read_expirations(&self) -> u64 {
        let now = monotonic_ns();
        let mut n = 0;
        for (t, next) in self.timers.iter().zip(&self.next_ns) {
            if now < next.get() {
                continue;
            }
            let k = t.read_expirations();
            n += k;
            if k > 0 {
                let interval = self.interval_ns.get();
                next.set(if interval == 0 {
                    u64::MAX
                } else {
                    next.get().saturating_add(k.saturating_mul(interval))
                });
            }
        }
        n
    }
}

/// The fixed-rate tick grid of a periodic [`TimerFd`], with the overrun policy and its
/// counters. Pure bookkeeping: [`Ticker::on_expirations`] is fed what the timer read returned.
#[derive(Debug, Clone)]
pub struct Ticker {
    start_ns: u64,
    period_ns: u64,
    policy: OverrunPolicy,
    /// Grid index of the last tick handed out.
    next_index: u64,
    /// Grid points that have expired so far.
    expired: u64,
    /// Ticks that started more than one period late (or never started, with Skip).
    pub deadline_misses: u64,
    /// Ticks dropped by the Skip policy.
    pub skipped_ticks: u64,
}

/// One tick to run: its grid index and ideal time.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Tick {
    /// Grid index (0 = the first tick at `start_ns`).
    pub index: u64,
    /// Ideal time of this tick (CLOCK_MONOTONIC ns).
    pub ideal_ns: u64,
}

impl Ticker {
    /// A grid starting at `start_ns` with `period_ns`.
    pub fn new(start_ns: u64, period_ns: u64, policy: OverrunPolicy) -> Self {
        Self {
            start_ns,
            period_ns: period_ns.max(1),
            policy,
            next_index: 0,
            expired: 0,
            deadline_misses: 0,
            skipped_ticks: 0,
        }
    }

    /// Period of the grid (ns).
    pub fn period_ns(&self) -> u64 {
        self.period_ns
    }

    /// Records `n` new expirations. Afterwards call [`Ticker::next_tick`] until it
    /// returns `None`.
    pub fn on_expirations(&mut self, n: u64) {
        if n == 0 {
            return;
        }
        self.expired += n;
        let pending = self.expired - self.next_index;
        if pending > 1 {
            self.deadline_misses += pending - 1;
            if self.policy == OverrunPolicy::Skip {
                self.skipped_ticks += pending - 1;
                self.next_index = self.expired - 1;
            }
        }
    }

    /// The next tick to run, `None` when caught up.
    pub fn next_tick(&mut self) -> Option<Tick> {
        if self.next_index >= self.expired {
            return None;
        }
        let index = self.next_index;
        self.next_index += 1;
        Some(Tick {
            index,
            ideal_ns: self.start_ns + index * self.period_ns,
        })
    }
}

/// A periodic [`TickTimer`] plus its [`Ticker`]: the planner's clock, the bare chain's
/// source, and the bare timer loop of the floor probe.
#[derive(Debug)]
pub struct PeriodicClock {
    pub timer: TickTimer,
    pub ticker: Ticker,
}

impl PeriodicClock {
    /// Starts a grid one period from now.
    pub fn start(period_ns: u64, policy: OverrunPolicy) -> std::io::Result<Self> {
        let timer = TickTimer::new()?;
        let start = monotonic_ns() + period_ns;
        timer.arm_absolute(start, period_ns)?;
        Ok(Self {
            timer,
            ticker: Ticker::new(start, period_ns, policy),
        })
    }

    /// Reads the timer and updates the grid (call when the timer's fd fired).
    pub fn poll(&mut self) {
        let n = self.timer.read_expirations();
        self.ticker.on_expirations(n);
    }
}

/// Result of the bare timer-loop probe ([`floor_probe`]).
#[derive(Debug, Clone, Default)]
pub struct FloorReport {
    /// Ticks run.
    pub ticks: u64,
    /// Wake-up lateness (actual − ideal) percentiles.
    pub lateness: microrobot_messages::LatencySummary,
    /// Ticks that started more than one period late.
    pub deadline_misses: u64,
    /// Lateness per window between bumps of the `epoch` given to
    /// [`floor_probe_windows`] (one window without one).
    pub windows: Vec<microrobot_messages::LatencySummary>,
}

/// The machine's timer floor: a bare timerfd loop at `period_ns` for `duration_ns`, with
/// the same settings as the pipeline (apply [`crate::rt::apply`] first in the same
/// thread) and the planner's overrun policy. Lateness and misses are defined exactly as
/// for the planner, so the planner's figures compare against it. (With `Skip` the ticks
/// a stall swallowed are not recorded, so no lateness exceeds a period; with `CatchUp`
/// each one is, as the planner records them: the two distributions differ in their tail.)
pub fn floor_probe(
    period_ns: u64,
    duration_ns: u64,
    overrun: OverrunPolicy,
) -> std::io::Result<FloorReport> {
    floor_probe_until(
        period_ns,
        duration_ns,
        overrun,
        &std::sync::atomic::AtomicBool::new(false),
    )
}

/// [`floor_probe`] that also ends within one period (or at most 1 s) once `stop` is set,
/// for runs whose length is not known at the start (`microrobot run --floor-probe`).
pub fn floor_probe_until(
    period_ns: u64,
    duration_ns: u64,
    overrun: OverrunPolicy,
    stop: &std::sync::atomic::AtomicBool,
) -> std::io::Result<FloorReport> {
    floor_probe_windows(period_ns, duration_ns, overrun, stop, None)
}

/// [`floor_probe_until`] that also keeps one lateness histogram per window, a new window
/// starting whenever `epoch` changes. The soak bumps it when it kills the planner: each
/// planner process reports the percentiles of its own lifetime, so the floor's
/// per-window figures are the ones to hold them against.
pub fn floor_probe_windows(
    period_ns: u64,
    duration_ns: u64,
    overrun: OverrunPolicy,
    stop: &std::sync::atomic::AtomicBool,
    epoch: Option<&std::sync::atomic::AtomicU64>,
) -> std::io::Result<FloorReport> {
    use std::sync::atomic::Ordering::Relaxed;
    let mut hist = crate::stats::LatencyHistogram::new();
    let mut window = crate::stats::LatencyHistogram::new();
    let mut windows = Vec::with_capacity(64); // a boundary pushes without allocating, up to 64
    let mut seen_epoch = epoch.map_or(0, |e| e.load(Relaxed));
    let mut clock = PeriodicClock::start(period_ns, overrun)?;
    let end = monotonic_ns() + duration_ns;
    let mut ticks = 0;
    // SAFETY: the fd stays owned by `clock` for the whole loop.
    let fd = unsafe { clock.timer.epoll.native_handle() };
    loop {
        let mut pfd = libc::pollfd {
            fd,
            events: libc::POLLIN,
            revents: 0,
        };
        // SAFETY: one valid pollfd.
        unsafe { libc::poll(&mut pfd, 1, 1000) };
        let now = monotonic_ns();
        clock.poll();
        while let Some(t) = clock.ticker.next_tick() {
            hist.record(now.saturating_sub(t.ideal_ns));
            window.record(now.saturating_sub(t.ideal_ns));
            ticks += 1;
        }
        if let Some(e) = epoch.map(|e| e.load(Relaxed))
            && e != seen_epoch
        {
            seen_epoch = e;
            if !window.is_empty() {
                windows.push(window.summary());
                window.reset();
            }
        }
        if now >= end || stop.load(Relaxed) {
            break;
        }
    }
    if !window.is_empty() {
        windows.push(window.summary());
    }
    Ok(FloorReport {
        ticks,
        lateness: hist.summary(),
        deadline_misses: clock.ticker.deadline_misses,
        windows,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn skip_policy_drops_missed_ticks_and_counts_them() {
        let mut t = Ticker::new(1000, 10, OverrunPolicy::Skip);
        t.on_expirations(1);
        assert_eq!(
            t.next_tick(),
            Some(Tick {
                index: 0,
                ideal_ns: 1000
            })
        );
        assert_eq!(t.next_tick(), None);
        t.on_expirations(4);
        assert_eq!(
            t.next_tick(),
            Some(Tick {
                index: 4,
                ideal_ns: 1040
            })
        );
        assert_eq!(t.next_tick(), None);
        assert_eq!(t.deadline_misses, 3);
        assert_eq!(t.skipped_ticks, 3);
    }

    #[test]
    fn catch_up_policy_runs_every_tick_back_to_back() {
        let mut t = Ticker::new(0, 10, OverrunPolicy::CatchUp);
        t.on_expirations(3);
        let idx: Vec<u64> = std::iter::from_fn(|| t.next_tick())
            .map(|k| k.index)
            .collect();
        assert_eq!(idx, vec![0, 1, 2]);
        assert_eq!(t.deadline_misses, 2);
        assert_eq!(t.skipped_ticks, 0);
    }

    #[test]
    fn timerfd_fires_on_the_absolute_grid() {
        let period = 1_000_000;
        let mut c = PeriodicClock::start(period, OverrunPolicy::Skip).unwrap();
        std::thread::sleep(std::time::Duration::from_millis(5));
        c.poll();
        let mut n = 0;
        while c.ticker.next_tick().is_some() {
            n += 1;
        }
        assert!(n >= 1);
    }

    /// Grid points `first + k·period` at or before `t`.
    fn passed(first: u64, period: u64, t: u64) -> u64 {
        if t < first {
            0
        } else {
            (t - first) / period + 1
        }
    }

    fn readable(t: &TickTimer, timeout_ms: i32) -> bool {
        let mut pfd = libc::pollfd {
            // SAFETY: the timer owns the fd, open for its lifetime.
            fd: unsafe { t.epoll.native_handle() },
            events: libc::POLLIN,
            revents: 0,
        };
        // SAFETY: one valid pollfd.
        unsafe { libc::poll(&mut pfd, 1, timeout_ms) == 1 }
    }

    #[test]
    fn the_two_timers_together_count_every_grid_point_once() {
        let period = 1_000_000;
        let t = TickTimer::new().unwrap();
        let first = monotonic_ns() + period;
        t.arm_absolute(first, period).unwrap();
        assert!(!readable(&t, 0), "readable before the first grid point");
        let mut total = 0;
        // Read at every wake-up for a while, and once after a 4.5-period sleep (a
        // backlog spanning both timers).
        for round in 0..12 {
            if round == 6 {
                std::thread::sleep(std::time::Duration::from_micros(4500));
            } else {
                assert!(readable(&t, 1000), "no wake-up in round {round}");
            }
            let before = monotonic_ns();
            total += t.read_expirations();
            let after = monotonic_ns();
            assert!(
                (passed(first, period, before)..=passed(first, period, after)).contains(&total),
                "round {round}: {total} grid points read, {} passed by the read",
                passed(first, period, before)
            );
        }
        assert!(total >= 12);
    }

    #[test]
    fn a_one_shot_tick_timer_fires_once() {
        let t = TickTimer::new().unwrap();
        t.arm_absolute(monotonic_ns() + 1_000_000, 0).unwrap();
        assert!(readable(&t, 1000));
        assert_eq!(t.read_expirations(), 1);
        assert!(!readable(&t, 5));
        assert_eq!(t.read_expirations(), 0);
    }

    #[test]
    fn the_floor_probe_starts_a_window_at_each_epoch_bump_and_every_tick_is_in_one() {
        use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
        let stop = AtomicBool::new(false);
        let epoch = AtomicU64::new(7);
        let report = std::thread::scope(|s| {
            s.spawn(|| {
                for _ in 0..2 {
                    std::thread::sleep(std::time::Duration::from_millis(30));
                    epoch.fetch_add(1, Ordering::Relaxed);
                }
                std::thread::sleep(std::time::Duration::from_millis(30));
                stop.store(true, Ordering::Relaxed);
            });
            floor_probe_windows(
                1_000_000,
                10_000_000_000,
                OverrunPolicy::CatchUp,
                &stop,
                Some(&epoch),
            )
            .unwrap()
        });
        // Three windows (an empty one, possible only if the probe got no CPU for 30 ms,
        // is not kept); each tick is counted in exactly one of them.
        assert!(
            (2..=3).contains(&report.windows.len()),
            "{:?}",
            report.windows
        );
        let in_windows: u64 = report.windows.iter().map(|w| w.count).sum();
        assert_eq!(in_windows, report.ticks);
        assert_eq!(report.lateness.count, report.ticks);
        // Without an epoch: one window, the whole run.
        let one = floor_probe_windows(
            1_000_000,
            5_000_000,
            OverrunPolicy::CatchUp,
            &AtomicBool::new(false),
            None,
        )
        .unwrap();
        assert_eq!(one.windows.len(), 1);
        assert_eq!(one.windows[0].count, one.ticks);
    }
}
