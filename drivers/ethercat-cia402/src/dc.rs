//! Distributed clocks: the SyncManager parameter objects 0x1C32 (SM2, outputs) and
//! 0x1C33 (SM3, inputs) of ETG.1020 / ETG.6010 (CiA 402 drive profile for EtherCAT),
//! as the master writes them and the emulator serves them.

/// SM output parameter (SM2, the RxPDO the master writes), ETG.1020 clause 5 / ETG.6010.
pub const SM_OUTPUT_PARAMETER: u16 = 0x1C32;
/// SM input parameter (SM3, the TxPDO the master reads).
pub const SM_INPUT_PARAMETER: u16 = 0x1C33;

/// Subindices of 0x1C32 / 0x1C33.
pub mod sub {
    /// Sync mode (u16, [`super::sync_mode`]); writable in PRE-OP.
    pub const SYNC_MODE: u8 = 0x01;
    /// Cycle time (u32, ns).
    pub const CYCLE_TIME: u8 = 0x02;
    /// Shift time (u32, ns): SYNC0 to outputs valid / inputs latched.
    pub const SHIFT_TIME: u8 = 0x03;
    /// Sync modes supported (u16, bit field, see [`super::sync_mode_supported`]).
    pub const SYNC_MODES_SUPPORTED: u8 = 0x04;
    /// Minimum cycle time (u32, ns).
    pub const MIN_CYCLE_TIME: u8 = 0x05;
    /// Calc and copy time (u32, ns).
    pub const CALC_AND_COPY_TIME: u8 = 0x06;
    /// SM-event missed counter (u16).
    pub const SM_EVENT_MISSED: u8 = 0x0B;
    /// Cycle time too small counter (u16).
    pub const CYCLE_TIME_TOO_SMALL: u8 = 0x0C;
    /// Sync error (BOOL, one byte).
    pub const SYNC_ERROR: u8 = 0x20;
}

/// Values of 0x1C32:01 / 0x1C33:01 (ETG.1020 table "sync mode").
pub mod sync_mode {
    /// Free run: the application runs on its own timer.
    pub const FREE_RUN: u16 = 0;
    /// Synchronous with the SM2 (outputs) event: the frame's arrival.
    pub const SM_SYNCHRONOUS: u16 = 1;
    /// Synchronous with the distributed clocks' SYNC0 event.
    pub const DC_SYNC0: u16 = 2;
    /// Synchronous with SYNC1.
    pub const DC_SYNC1: u16 = 3;
}

/// Whether 0x1C32:04 `supported` (ETG.1020: bit 0 free run, bit 1 synchronous with
/// the SM event, bits 2-3 DC type: 01 SYNC0, 10 SYNC1, 11 subordinated) allows sync
/// mode `mode`.
pub const fn sync_mode_supported(supported: u16, mode: u16) -> bool {
    let dc = (supported >> 2) & 0x3;
    match mode {
        sync_mode::FREE_RUN => supported & 0x1 != 0,
        sync_mode::SM_SYNCHRONOUS => supported & 0x2 != 0,
        sync_mode::DC_SYNC0 => dc == 0b01 || dc == 0b11,
        sync_mode::DC_SYNC1 => dc == 0b10 || dc == 0b11,
        _ => false,
    }
}

/// Most exchanges one correction window holds.
const WINDOW: usize = 128;
/// How long one correction window lasts (its exchange count is this over the period,
/// 8 to [`WINDOW`]).
const WINDOW_NS: u64 = 100_000_000;

/// The phase of the cyclic exchange against SYNC0, measured on every exchange and kept
/// at a margin.
///
/// The margin is how early the outputs reach the drives before SYNC0 latches them
/// (ETG.1020 DC synchronous mode: outputs written after SYNC0 miss it, an SM-event
/// missed). It is read from the DC system time the reference clock puts into each
/// exchange's frame as the frame passes it (ethercrab's `CycleInfo::dc_system_time`),
/// against the SYNC0 grid (`sync0_phase_ns + k·period` in DC system time; ethercrab
/// rounds the SYNC0 start to whole periods, so its phase is 0).
///
/// The exchange's place in the period is the pipeline's (the actuator steps on the
/// host's monotonic clock), so the SYNC0 grid is moved to it, not the other way round:
/// every window (~100 ms) the median margin error is taken and the DC system time is
/// to be advanced by it ([`PhaseLock::on_exchange`] returns the shift; the master
/// adds it to the reference clock's system time offset, see `master::Bus`). An error beyond the lock
/// window (period / 8) is taken at once (acquisition: the first window of a run, or a
/// pipeline that restarted its timer); a smaller one by at most period / 50 per window
/// (200 ppm at any period), which follows the reference clock's drift against the host
/// (a crystal's, tens of ppm) without a step. ethercrab 0.7.1 keeps the SubDevices on
/// the reference clock (FRMW in `tx_rx_dc`) but offers nothing that keeps the
/// reference clock on the host, nor a SYNC0 shift on the SubDevices (its
/// `sync0_shift` only enters `next_cycle_wait`, for a master that times itself on DC):
/// hence this by hand.
#[derive(Debug, Clone)]
pub struct PhaseLock {
    period_ns: u64,
    sync0_phase_ns: u64,
    target_ns: u64,
    errors: [i64; WINDOW],
    n: usize,
    interval: usize,
    locked: bool,
    stats: PhaseStats,
}

/// Buckets of the margin histogram (each period / `MARGIN_BUCKETS` wide).
pub const MARGIN_BUCKETS: usize = 50;

/// What [`PhaseLock`] measured (ns).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PhaseStats {
    /// Exchanges measured.
    pub samples: u64,
    /// The wanted margin: SYNC0 this long after the frame reaches the drives.
    pub target_margin_ns: u64,
    /// Margin of the last exchange.
    pub last_margin_ns: u64,
    /// Median margin of the last full window.
    pub window_median_margin_ns: u64,
    /// Smallest margin since the last acquisition (`u64::MAX` before any).
    pub min_margin_ns: u64,
    /// Largest margin since the last acquisition.
    pub max_margin_ns: u64,
    /// Exchanges while locked that reached the drives after the SYNC0 they were meant
    /// for (more than halfway from the target to the next SYNC0 after it): outputs a
    /// drive took a cycle late.
    pub late: u64,
    /// Shifts of the DC system time asked for, and their sum.
    pub corrections: u64,
    /// Of them, acquisitions (an error beyond the lock window, taken at once).
    pub acquisitions: u64,
    /// Sum of all shifts (ns, positive: DC system time advanced, SYNC0 earlier).
    pub shifted_ns: i64,
    /// The shift of the last acquisition.
    pub last_acquisition_ns: i64,
    /// Margins since the last acquisition: bucket `i` counts margins in
    /// `[i, i + 1) · period / MARGIN_BUCKETS`.
    pub margin_histogram: [u64; MARGIN_BUCKETS],
    /// The period (ns).
    pub period_ns: u64,
}

impl Default for PhaseStats {
    fn default() -> PhaseStats {
        PhaseStats {
            samples: 0,
            target_margin_ns: 0,
            last_margin_ns: 0,
            window_median_margin_ns: 0,
            min_margin_ns: u64::MAX,
            max_margin_ns: 0,
            late: 0,
            corrections: 0,
            acquisitions: 0,
            shifted_ns: 0,
            last_acquisition_ns: 0,
            margin_histogram: [0; MARGIN_BUCKETS],
            period_ns: 0,
        }
    }
}

impl PhaseStats {
    /// The margin under which fraction `q` (0..=1) of the margins since the last
    /// acquisition lie, to a bucket's width (the bucket's upper edge); `None` without
    /// any.
    pub fn margin_quantile_ns(&self, q: f64) -> Option<u64> {
        let n: u64 = self.margin_histogram.iter().sum();
        if n == 0 {
            return None;
        }
        let want = ((q.clamp(0.0, 1.0) * n as f64).ceil() as u64).max(1);
        let mut seen = 0;
        for (i, c) in self.margin_histogram.iter().enumerate() {
            seen += c;
            if seen >= want {
                return Some((i as u64 + 1) * self.period_ns / MARGIN_BUCKETS as u64);
            }
        }
        Some(self.period_ns)
    }
}

impl PhaseLock {
    /// SYNC0 every `period_ns` at `sync0_phase_ns` (mod period) in DC system time, to
    /// fall `target_margin_ns` after each exchange's arrival (clamped into the period).
    pub fn new(period_ns: u64, sync0_phase_ns: u64, target_margin_ns: u64) -> PhaseLock {
        let period_ns = period_ns.max(1);
        let target_ns = target_margin_ns.clamp(1, period_ns.saturating_sub(1).max(1));
        PhaseLock {
            period_ns,
            sync0_phase_ns: sync0_phase_ns % period_ns,
            target_ns,
            errors: [0; WINDOW],
            n: 0,
            interval: usize::try_from(WINDOW_NS / period_ns)
                .unwrap_or(WINDOW)
                .clamp(8, WINDOW),
            locked: false,
            stats: PhaseStats {
                target_margin_ns: target_ns,
                period_ns,
                ..PhaseStats::default()
            },
        }
    }

    /// Time from DC system time `dc_ns` to the next SYNC0 (0 = at it), in [0, period).
    pub fn margin_ns(&self, dc_ns: u64) -> u64 {
        let p = self.period_ns;
        (self.sync0_phase_ns + p - dc_ns % p) % p
    }

    /// `margin - target`, wrapped into [-period/2, period/2).
    fn error_ns(&self, margin_ns: u64) -> i64 {
        let p = self.period_ns;
        let e = ((margin_ns + p - self.target_ns) % p) as i64;
        if e >= (p / 2) as i64 { e - p as i64 } else { e }
    }

    /// One exchange whose frame passed the reference clock at DC system time `dc_ns`.
    /// Returns, once per window, the shift (ns) to advance the DC system time by
    /// (positive: SYNC0 comes earlier against the host). No allocation, no lock.
    pub fn on_exchange(&mut self, dc_ns: u64) -> Option<i64> {
        let m = self.margin_ns(dc_ns);
        let e = self.error_ns(m);
        let st = &mut self.stats;
        st.samples += 1;
        st.last_margin_ns = m;
        if self.locked {
            st.min_margin_ns = st.min_margin_ns.min(m);
            st.max_margin_ns = st.max_margin_ns.max(m);
            let b = (m * MARGIN_BUCKETS as u64 / self.period_ns) as usize;
            if let Some(c) = st.margin_histogram.get_mut(b.min(MARGIN_BUCKETS - 1)) {
                *c += 1;
            }
            if m > self.target_ns + (self.period_ns - self.target_ns) / 2 {
                st.late += 1;
            }
        }
        self.errors[self.n] = e;
        self.n += 1;
        if self.n < self.interval {
            return None;
        }
        let w = &mut self.errors[..self.n];
        let mid = w.len() / 2;
        let (_, median, _) = w.select_nth_unstable(mid);
        let median = *median;
        self.n = 0;
        st.window_median_margin_ns =
            (self.target_ns as i64 + median).rem_euclid(self.period_ns as i64) as u64;
        let p = self.period_ns as i64;
        let shift = if median.abs() > p / 8 {
            st.acquisitions += 1;
            st.last_acquisition_ns = median;
            // The extremes and the histogram are those of the phase from here on.
            st.min_margin_ns = u64::MAX;
            st.max_margin_ns = 0;
            st.margin_histogram = [0; MARGIN_BUCKETS];
            median
        } else {
            median.clamp(-(p / 50).max(1), (p / 50).max(1))
        };
        self.locked = true;
        if shift == 0 {
            return None;
        }
        st.corrections += 1;
        st.shifted_ns += shift;
        Some(shift)
    }

    /// What was measured so far.
    pub fn stats(&self) -> PhaseStats {
        self.stats
    }

    /// Whether a window has been taken (the phase was set at least once).
    pub fn locked(&self) -> bool {
        self.locked
    }

    /// The period (ns).
    pub fn period_ns(&self) -> u64 {
        self.period_ns
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn margin_is_the_time_to_the_next_sync0() {
        let p = PhaseLock::new(1_000_000, 0, 500_000);
        assert_eq!(p.margin_ns(10_000_000), 0, "at SYNC0");
        assert_eq!(p.margin_ns(10_000_001), 999_999);
        assert_eq!(p.margin_ns(10_700_000), 300_000);
        let p = PhaseLock::new(1_000_000, 250_000, 500_000);
        assert_eq!(p.margin_ns(10_000_000), 250_000);
        assert_eq!(p.error_ns(500_000), 0);
        assert_eq!(p.error_ns(100_000), -400_000);
        assert_eq!(p.error_ns(950_000), 450_000);
        assert_eq!(p.error_ns(0), -500_000, "wrapped");
    }

    /// Exchanges every period at host time `t`, DC = host + `offset`; the shifts
    /// returned are applied to the offset as the master applies them.
    fn run(lock: &mut PhaseLock, offset: &mut i64, t0: u64, n: u64, drift_ppm: i64) -> u64 {
        let p = lock.period_ns();
        let mut t = t0;
        for _ in 0..n {
            let dc = (t as i64 + *offset + (t - t0) as i64 * drift_ppm / 1_000_000) as u64;
            if let Some(s) = lock.on_exchange(dc) {
                *offset += s;
            }
            t += p;
        }
        t
    }

    #[test]
    fn the_first_window_acquires_the_phase_and_drift_is_followed() {
        let period = 1_000_000;
        let mut lock = PhaseLock::new(period, 0, 300_000);
        // Exchanges 0.9 ms after SYNC0: a margin of 0.1 ms.
        let mut offset = -100_000i64;
        let t = run(&mut lock, &mut offset, 1_000_000_000, 100, 0);
        let st = lock.stats();
        assert_eq!(st.acquisitions, 1);
        assert_eq!(
            st.last_acquisition_ns, -200_000,
            "DC back 0.2 ms: SYNC0 later"
        );
        assert_eq!(lock.margin_ns((t as i64 + offset) as u64), 300_000);
        // 150 ppm of drift for 5 s: followed within one window's slew, no acquisition.
        let t = run(&mut lock, &mut offset, t, 5000, 150);
        let st = lock.stats();
        assert_eq!(st.acquisitions, 1, "{st:?}");
        assert_eq!(st.late, 0);
        // Within about a window's drift (15 µs) of the target, the median lagging.
        let err = st.last_margin_ns as i64 - 300_000;
        assert!(err.abs() <= 40_000, "{st:?}");
        assert!(
            st.min_margin_ns >= 260_000 && st.max_margin_ns <= 340_000,
            "{st:?}"
        );
        // 20 µs buckets: the median within a bucket or two of the target.
        let p50 = st.margin_quantile_ns(0.5).expect("samples");
        assert!((280_000..=320_000).contains(&p50), "{p50}");
        assert!(st.margin_quantile_ns(0.0).expect("samples") >= 260_000);
        let _ = t;
    }

    #[test]
    fn the_window_median_is_a_margin_in_the_period() {
        // Target 0.1 ms, exchanges 0.9 ms before SYNC0: the error wraps to -0.2 ms.
        let mut lock = PhaseLock::new(1_000_000, 0, 100_000);
        let mut shift = None;
        for k in 0..100u64 {
            shift = lock.on_exchange(k * 1_000_000 + 100_000);
        }
        assert_eq!(lock.stats().window_median_margin_ns, 900_000);
        assert_eq!(shift, Some(-200_000), "DC back 0.2 ms: SYNC0 later");
    }

    #[test]
    fn an_exchange_past_its_sync0_counts_as_late() {
        let mut lock = PhaseLock::new(1_000_000, 0, 500_000);
        let mut offset = -500_000i64;
        let t = run(&mut lock, &mut offset, 0, 100, 0);
        assert!(lock.locked());
        // 0.6 ms late: 0.1 ms after the SYNC0 it was meant for.
        let dc = (t as i64 + offset + 600_000) as u64;
        lock.on_exchange(dc);
        assert_eq!(lock.stats().late, 1);
        assert_eq!(lock.stats().last_margin_ns, 900_000);
    }

    #[test]
    fn supported_modes_follow_the_bit_field() {
        // Free run, SM-synchronous, DC SYNC0.
        let s = 0x0007;
        assert!(sync_mode_supported(s, sync_mode::FREE_RUN));
        assert!(sync_mode_supported(s, sync_mode::SM_SYNCHRONOUS));
        assert!(sync_mode_supported(s, sync_mode::DC_SYNC0));
        assert!(!sync_mode_supported(s, sync_mode::DC_SYNC1));
        assert!(!sync_mode_supported(s, 7));
        // No DC at all.
        assert!(!sync_mode_supported(0x0003, sync_mode::DC_SYNC0));
    }
}
