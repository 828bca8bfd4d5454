//! What a status report's own work costs: the percentiles of a latency histogram filled
//! like a control cycle's hop (most values 4–20 µs, a tail to a few ms), the process CPU
//! time and the resident set size, each back to back and after a 100 ms sleep (the status
//! period: caches and TLB as a service finds them).
//! Run: `cargo run --release -p microrobot-runtime --example summary_cost`.

use std::hint::black_box;
use std::time::Duration;

use microrobot_runtime::stats::{LatencyHistogram, RssReader, cpu_time_ms};

mod common;
use common::time_warm_and_after_sleep;

/// Calls timed each way (20 sleeps of 100 ms: 2 s per line).
const CALLS: usize = 20;

fn main() {
    let mut h = LatencyHistogram::new();
    let mut x: u64 = 0x9E37_79B9_7F4A_7C15;
    for i in 0..4_000_000u64 {
        x ^= x << 13;
        x ^= x >> 7;
        x ^= x << 17;
        let v = match i % 10_000 {
            0 => 2_000_000 + x % 3_000_000,
            1..=20 => 30_000 + x % 100_000,
            _ => 4_000 + x % 16_000,
        };
        h.record(v);
    }
    let rss = RssReader::new();
    let sleep = Duration::from_millis(100);
    time_warm_and_after_sleep(
        "latency summary (p50 … p99.99, max)",
        sleep,
        CALLS,
        || {
            black_box(h.summary());
        },
    );
    time_warm_and_after_sleep("hop summary (p50 … p99.9, max)", sleep, CALLS, || {
        black_box(h.hop_latency());
    });
    time_warm_and_after_sleep("cpu_time_ms (getrusage)", sleep, CALLS, || {
        black_box(cpu_time_ms());
    });
    time_warm_and_after_sleep("rss_kib (/proc/self/statm)", sleep, CALLS, || {
        black_box(rss.rss_kib());
    });
}
