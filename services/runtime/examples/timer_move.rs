//! What re-arming a timer costs when it becomes the CPU's next to expire (the kernel then
//! reprograms the clock-event device; in a VM, an exit to the hypervisor), in the two
//! patterns the services have:
//!
//! 1. **Reading a periodic timer** (the planner's clock): a read re-arms it for the next
//!    grid point. One periodic timerfd against a [`TickTimer`] (two taking turns).
//! 2. **Moving a timer on each tick** (the actuator's fallback timer): right after each
//!    tick of the clock above, a second timerfd is moved one period on, from half a period
//!    after the tick (the CPU's next timer) or from one and a half (the clock's next tick
//!    comes first).
//!
//! Run it on the pipeline's CPU with its priority:
//!
//! `chrt -f 80 taskset -c 1 cargo run --release -p microrobot-runtime --example timer_move -- [RATE_HZ] [TICKS]`

use iceoryx2::prelude::FileDescriptorBased;
use microrobot_messages::monotonic_ns;
use microrobot_runtime::{TickTimer, TimerFd};

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().collect();
    let rate_hz: f64 = args.get(1).map_or(Ok(4000.0), |s| s.parse())?;
    let ticks: usize = args.get(2).map_or(Ok(8000), |s| s.parse())?;
    anyhow::ensure!(
        rate_hz > 0.0 && rate_hz <= 20_000.0,
        "RATE_HZ must be in (0, 20000], got {rate_hz}"
    );
    anyhow::ensure!(ticks > 0, "TICKS must be at least 1");
    let p = (1e9 / rate_hz) as u64;
    println!("{ticks} ticks at {rate_hz} Hz, mean / median per call:");

    let single = TimerFd::new()?;
    let start = monotonic_ns() + p;
    single.arm_absolute(start, p)?;
    let read = each_tick(ticks, fd_of(&single), || {
        single.read_expirations();
    });
    println!("  read one periodic timerfd:         {read}");

    let pair = TickTimer::new()?;
    let start = monotonic_ns() + p;
    pair.arm_absolute(start, p)?;
    let read = each_tick(ticks, fd_of(&pair), || {
        pair.read_expirations();
    });
    println!("  read a TickTimer (two timerfds):   {read}");

    let moved = TimerFd::new()?;
    for (name, offset) in [
        ("move a timer that is the CPU's next", p / 2),
        ("move a timer that is not the next ", p + p / 2),
    ] {
        let mut cost = Times::default();
        let _ = each_tick(ticks, fd_of(&pair), || {
            pair.read_expirations();
            // The tick just read, on the clock's grid.
            let tick = start + (monotonic_ns() - start) / p * p;
            let t0 = monotonic_ns();
            let _ = moved.arm_absolute(tick + p + offset, p);
            cost.push(monotonic_ns() - t0);
        });
        println!("  {name}: {cost}");
    }
    Ok(())
}

fn fd_of(t: &impl FileDescriptorBased) -> i32 {
    // SAFETY: `t` owns the fd and outlives its use here.
    unsafe { t.file_descriptor().native_handle() }
}

/// Waits for `fd` `ticks` times and times `f` after each wake-up.
fn each_tick(ticks: usize, fd: i32, mut f: impl FnMut()) -> Times {
    let mut times = Times::default();
    for _ in 0..ticks {
        let mut pfd = libc::pollfd {
            fd,
            events: libc::POLLIN,
            revents: 0,
        };
        // SAFETY: one valid pollfd.
        unsafe { libc::poll(&mut pfd, 1, 1000) };
        let t0 = monotonic_ns();
        f();
        times.push(monotonic_ns() - t0);
    }
    times
}

#[derive(Default)]
struct Times(Vec<u64>);

impl Times {
    fn push(&mut self, ns: u64) {
        self.0.push(ns);
    }
}

impl std::fmt::Display for Times {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let mut v = self.0.clone();
        if v.is_empty() {
            return write!(f, "-");
        }
        v.sort_unstable();
        let mean = v.iter().sum::<u64>() as f64 / v.len() as f64;
        write!(
            f,
            "{:.2} / {:.2} µs",
            mean * 1e-3,
            v[v.len() / 2] as f64 * 1e-3
        )
    }
}
