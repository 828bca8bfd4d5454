//! What the runtime's cost examples share: one way to time a call warm and as a service
//! finds its caches after a sleep.

use std::time::Duration;

use microrobot_messages::monotonic_ns;

/// Times `f` `calls` times back to back, then `calls` times each after a `sleep`, and
/// prints p50, p90 and mean of each (µs; every call timed with two clock reads).
pub fn time_warm_and_after_sleep(name: &str, sleep: Duration, calls: usize, mut f: impl FnMut()) {
    println!("{name}:");
    for (when, pause) in [("back to back", Duration::ZERO), ("after a sleep", sleep)] {
        let mut ns = Vec::with_capacity(calls);
        for _ in 0..calls {
            if !pause.is_zero() {
                std::thread::sleep(pause);
            }
            let t0 = monotonic_ns();
            f();
            ns.push(monotonic_ns() - t0);
        }
        ns.sort_unstable();
        let us = |v: u64| v as f64 / 1e3;
        let mean = ns.iter().sum::<u64>() as f64 / ns.len().max(1) as f64 / 1e3;
        println!(
            "  {when:<14} p50 {:7.2} µs, p90 {:7.2} µs, mean {mean:7.2} µs",
            us(ns[ns.len() / 2]),
            us(ns[ns.len() * 9 / 10]),
        );
    }
}
