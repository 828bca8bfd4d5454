//! What a status report's own work costs (µs): the percentiles of a latency histogram
//! filled like a control cycle's hop (most values 4–20 µs, a tail to a few ms), the
//! process CPU time and the resident set size, each measured after a 100 ms sleep (the
//! status period: caches and TLB as a service finds them) and warm (back to back).
//! Run: `cargo run --release -p microrobot-runtime --example summary_cost`.

use microrobot_runtime::stats::{LatencyHistogram, RssReader, cpu_time_ms};
use std::hint::black_box;
use std::time::{Duration, Instant};

/// Mean µs of `f` after a sleep of the status period, and its fastest warm call.
fn cost(name: &str, mut f: impl FnMut()) {
    let mut warm = Duration::MAX;
    for _ in 0..200 {
        let t = Instant::now();
        f();
        warm = warm.min(t.elapsed());
    }
    let n = 20;
    let mut cold = Duration::ZERO;
    for _ in 0..n {
        std::thread::sleep(Duration::from_millis(100));
        let t = Instant::now();
        f();
        cold += t.elapsed();
    }
    println!(
        "{name:32} after a sleep {:6.1} µs   warm {:6.1} µs",
        cold.as_secs_f64() * 1e6 / f64::from(n),
        warm.as_secs_f64() * 1e6
    );
}

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
    cost("summary (p50..p99.99, max)", || {
        black_box(h.summary());
    });
    cost("hop_latency (p50..p99.9, max)", || {
        black_box(h.hop_latency());
    });
    cost("cpu_time_ms (getrusage)", || {
        black_box(cpu_time_ms());
    });
    cost("rss_kib (/proc/self/statm)", || {
        black_box(rss.rss_kib());
    });
}
