//! Counters that cost nothing per cycle: a latency histogram created up front
//! (hdrhistogram, 16 ns .. 60 s, 3 significant digits, never resized) with the exact sum
//! of its samples, and process CPU time and resident memory read at the status rate
//! without allocating.

use hdrhistogram::Histogram;
use microrobot_messages::{HopLatency, LatencySummary};

/// The histogram's lowest discernible value (ns): its resolution below 2048 × this.
const LOWEST_NS: u64 = 16;

/// A fixed-range latency histogram in ns, and the exact sum of what it recorded (the
/// histogram's own mean is bucketed; the sum keeps the means of consecutive hops
/// adding up exactly). Recording never allocates.
#[derive(Debug, Clone)]
pub struct LatencyHistogram {
    hist: Histogram<u64>,
    sum_ns: u64,
}

impl Default for LatencyHistogram {
    fn default() -> Self {
        Self::new()
    }
}

impl LatencyHistogram {
    /// 16 ns .. 60 s at 3 significant digits: 16 ns steps up to 32.8 µs, 0.1 % above
    /// (values outside are clamped). The 16 ns floor keeps the counts that a summary
    /// scans to a control cycle's latencies (tens of µs) 2.3× shorter than a 1 ns floor
    /// would (2.6 k instead of 6 k buckets), below the 0.1 µs that reports print.
    pub fn new() -> Self {
        let mut hist = match Histogram::new_with_bounds(LOWEST_NS, 60_000_000_000, 3) {
            Ok(h) => h,
            Err(_) => Histogram::new(3).unwrap_or_else(|_| unreachable_hist()),
        };
        hist.auto(false);
        Self { hist, sum_ns: 0 }
    }

    /// Records one value (ns), clamped into the histogram's range (the sum takes the
    /// value itself).
    #[inline]
    pub fn record(&mut self, ns: u64) {
        self.hist.saturating_record(ns.max(1));
        self.sum_ns = self.sum_ns.saturating_add(ns);
    }

    /// The exact sum of the values recorded (ns).
    pub fn sum_ns(&self) -> u64 {
        self.sum_ns
    }

    /// Number of values recorded.
    pub fn len(&self) -> u64 {
        self.hist.len()
    }

    /// True when nothing was recorded.
    pub fn is_empty(&self) -> bool {
        self.hist.is_empty()
    }

    /// Forgets every sample and keeps the buckets (no allocation).
    pub fn reset(&mut self) {
        self.hist.reset();
        self.sum_ns = 0;
    }

    /// Every non-empty bucket as `(value_ns, count)`, ascending: the histogram to draw
    /// (allocates; for reports, not for a control cycle).
    pub fn buckets(&self) -> Vec<(u64, u64)> {
        self.hist
            .iter_recorded()
            .map(|v| (v.value_iterated_to(), v.count_at_value()))
            .collect()
    }

    /// The values at `quantiles` (ascending) in one pass over the counts, each exactly
    /// what `value_at_quantile` gives; the pass stops at the last one, so a caller asks
    /// only for what it keeps.
    fn values_at<const N: usize>(&self, quantiles: [f64; N]) -> [u64; N] {
        let mut out = [0; N];
        for (o, v) in out.iter_mut().zip(self.hist.value_at_quantiles(quantiles)) {
            *o = v;
        }
        out
    }

    /// Percentiles for the status message (zeros when empty).
    pub fn summary(&self) -> LatencySummary {
        if self.hist.is_empty() {
            return LatencySummary::default();
        }
        let [p50_ns, p99_ns, p999_ns, p9999_ns] = self.values_at([0.50, 0.99, 0.999, 0.9999]);
        LatencySummary {
            count: self.hist.len(),
            p50_ns,
            p99_ns,
            p999_ns,
            p9999_ns,
            max_ns: self.hist.max(),
        }
    }

    /// Count, exact sum and percentiles, as a status carries one hop (zeros when empty;
    /// no p99.99, so the pass over the counts stops at the p99.9).
    pub fn hop_latency(&self) -> HopLatency {
        if self.hist.is_empty() {
            return HopLatency::default();
        }
        let [p50_ns, p99_ns, p999_ns] = self.values_at([0.50, 0.99, 0.999]);
        HopLatency {
            count: self.hist.len(),
            sum_ns: self.sum_ns,
            p50_ns,
            p99_ns,
            p999_ns,
            max_ns: self.hist.max(),
        }
    }
}

#[cold]
fn unreachable_hist() -> Histogram<u64> {
    // Histogram::new(3) only fails for sigfig > 5.
    Histogram::new(2).unwrap_or_else(|_| std::process::abort())
}

/// Process CPU time (ns, user + system, microsecond resolution) from `getrusage`.
pub fn cpu_time_ns() -> u64 {
    // SAFETY: an all-zero rusage is valid; getrusage fills it.
    let mut ru: libc::rusage = unsafe { std::mem::zeroed() };
    // SAFETY: `ru` is a valid, writable rusage.
    if unsafe { libc::getrusage(libc::RUSAGE_SELF, &mut ru) } != 0 {
        return 0;
    }
    let ns = |t: libc::timeval| t.tv_sec as u64 * 1_000_000_000 + t.tv_usec as u64 * 1000;
    ns(ru.ru_utime) + ns(ru.ru_stime)
}

/// Process CPU time (ms, user + system), as the status message carries it.
pub fn cpu_time_ms() -> u32 {
    (cpu_time_ns() / 1_000_000).min(u32::MAX as u64) as u32
}

/// Reads the resident set size from `/proc/self/statm` through a kept-open fd into a
/// stack buffer (no allocation per read).
#[derive(Debug)]
pub struct RssReader {
    fd: i32,
    page_kib: u64,
}

impl RssReader {
    /// Opens `/proc/self/statm` (reads return 0 when that fails).
    pub fn new() -> Self {
        // SAFETY: NUL-terminated path literal.
        let fd = unsafe {
            libc::open(
                c"/proc/self/statm".as_ptr(),
                libc::O_RDONLY | libc::O_CLOEXEC,
            )
        };
        // SAFETY: sysconf has no preconditions.
        let page = unsafe { libc::sysconf(libc::_SC_PAGESIZE) }.max(4096) as u64;
        Self {
            fd,
            page_kib: page / 1024,
        }
    }

    /// Current RSS in KiB (0 when unavailable).
    pub fn rss_kib(&self) -> u64 {
        if self.fd < 0 {
            return 0;
        }
        let mut buf = [0u8; 128];
        // SAFETY: reading into a stack buffer of the given length.
        let n = unsafe { libc::pread(self.fd, buf.as_mut_ptr().cast(), buf.len(), 0) };
        if n <= 0 {
            return 0;
        }
        parse_statm_resident(&buf[..n as usize]) * self.page_kib
    }
}

impl Default for RssReader {
    fn default() -> Self {
        Self::new()
    }
}

impl Drop for RssReader {
    fn drop(&mut self) {
        if self.fd >= 0 {
            // SAFETY: we own this fd.
            unsafe { libc::close(self.fd) };
        }
    }
}

/// Second field of statm ("size resident shared ..."), in pages.
fn parse_statm_resident(b: &[u8]) -> u64 {
    let mut field = 0;
    let mut val = 0u64;
    for &c in b {
        if c == b' ' {
            if field == 1 {
                return val;
            }
            field += 1;
            val = 0;
        } else if c.is_ascii_digit() {
            val = val * 10 + (c - b'0') as u64;
        }
    }
    if field == 1 { val } else { 0 }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reset_forgets_every_sample_and_keeps_recording() {
        let mut h = LatencyHistogram::new();
        h.record(5_000);
        h.record(7_000);
        assert_eq!(h.sum_ns(), 12_000);
        h.reset();
        assert!(h.is_empty());
        assert_eq!(h.summary().count, 0);
        assert_eq!(h.hop_latency(), HopLatency::default());
        h.record(3_000);
        assert_eq!(h.summary().count, 1);
        assert!(h.summary().max_ns >= 3_000 && h.summary().max_ns < 3_010);
    }

    #[test]
    fn cpu_time_grows_with_work_and_ms_follows_ns() {
        let a = cpu_time_ns();
        let mut x = 0u64;
        for i in 0..20_000_000u64 {
            x = x.wrapping_mul(6364136223846793005).wrapping_add(i);
        }
        std::hint::black_box(x);
        let b = cpu_time_ns();
        assert!(b > a, "{a} -> {b}");
        // Process CPU time: the other test threads add to it meanwhile, so the
        // millisecond reading is bracketed by two nanosecond readings.
        let ms = u64::from(cpu_time_ms());
        let c = cpu_time_ns();
        assert!(
            b / 1_000_000 <= ms && ms <= c / 1_000_000,
            "{b} ns <= {ms} ms <= {c} ns"
        );
    }

    #[test]
    fn one_pass_summary_is_each_quantile_on_its_own() {
        let mut h = LatencyHistogram::new();
        let mut samples = Vec::new();
        let mut raw_sum = 0u64;
        let mut x: u64 = 12345;
        for i in 0..50_000u64 {
            x = x
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            // A body of 5..45 µs, one sample in 100 near 100 µs, a few tiny and huge.
            let v = match i % 1000 {
                0 => x >> 60,
                1 => 2_000_000_000 + (x >> 30),
                _ if i % 100 == 0 => 90_000 + (x >> 44),
                _ => 5_000 + (x >> 40) % 40_000,
            };
            h.record(v);
            raw_sum += v;
            samples.push(v.max(1));
        }
        let s = h.summary();
        let one = |q| h.hist.value_at_quantile(q);
        assert_eq!(
            [s.p50_ns, s.p99_ns, s.p999_ns, s.p9999_ns],
            [one(0.5), one(0.99), one(0.999), one(0.9999)]
        );
        let hop = h.hop_latency();
        assert_eq!(
            [hop.p50_ns, hop.p99_ns, hop.p999_ns, hop.max_ns, hop.count],
            [one(0.5), one(0.99), one(0.999), s.max_ns, s.count]
        );
        assert_eq!(hop.sum_ns, raw_sum);
        // Below 32.8 µs the histogram steps by 16 ns: the median reported is the true
        // one rounded up to its step's top; above, within 0.1 %.
        samples.sort_unstable();
        let exact = |q: f64| samples[((q * samples.len() as f64).ceil() as usize).max(1) - 1];
        let m = exact(0.5);
        assert!(
            m < 32_768 && s.p50_ns >= m && s.p50_ns < m + 16,
            "{} vs {m}",
            s.p50_ns
        );
        let t = exact(0.99);
        assert!(
            s.p99_ns >= t && s.p99_ns as f64 <= t as f64 * 1.001,
            "{} vs {t}",
            s.p99_ns
        );
    }

    #[test]
    fn histogram_summary_has_ordered_percentiles() {
        let mut h = LatencyHistogram::new();
        for v in 1..=10_000u64 {
            h.record(v * 1000);
        }
        let s = h.summary();
        assert_eq!(s.count, 10_000);
        assert!(s.p50_ns <= s.p99_ns && s.p99_ns <= s.p999_ns && s.p999_ns <= s.max_ns);
        assert!((s.p50_ns as f64 - 5.0e6).abs() < 1.0e4);
        h.record(u64::MAX);
        assert!(h.summary().max_ns >= 60_000_000_000 / 2);
    }

    #[test]
    fn statm_parse_and_live_rss() {
        assert_eq!(parse_statm_resident(b"1000 250 30 1 0 2 0\n"), 250);
        assert!(RssReader::new().rss_kib() > 0);
        let _ = cpu_time_ms();
    }
}
