//! Input watchdog in milliseconds (not in periods): each stage feeds it when a valid
//! input arrives and asks how old its input is. Two thresholds: `stale_ms` (flag and
//! hold) and `fault_ms` (the actuator latches its safe state). Pure logic on
//! CLOCK_MONOTONIC ns, so it is unit-tested without clocks.

/// How old the input is, judged against the two thresholds.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Freshness {
    /// Not armed yet: no valid input has arrived since start (or since a reset).
    Waiting,
    /// Younger than `stale_ms`.
    Fresh,
    /// At least `stale_ms` old.
    Stale,
    /// At least `fault_ms` old.
    Fault,
}

/// Age of the last valid input against `stale_ms` / `fault_ms`.
#[derive(Debug, Clone, Copy)]
pub struct Watchdog {
    stale_ns: u64,
    fault_ns: u64,
    last_ns: Option<u64>,
}

impl Watchdog {
    /// Thresholds in ms (as configured).
    pub fn new(stale_ms: f64, fault_ms: f64) -> Self {
        Self {
            stale_ns: crate::config::ms_to_ns(stale_ms),
            fault_ns: crate::config::ms_to_ns(fault_ms),
            last_ns: None,
        }
    }

    /// A valid input arrived at `now_ns`.
    #[inline]
    pub fn feed(&mut self, now_ns: u64) {
        self.last_ns = Some(now_ns);
    }

    /// Time that does not count (`ns` spent in a blocking call the owner made itself):
    /// the last input's age at the end of it is its age at the start.
    pub fn pause(&mut self, ns: u64) {
        if let Some(t) = &mut self.last_ns {
            *t = t.saturating_add(ns);
        }
    }

    /// Forget the last input (back to [`Freshness::Waiting`]).
    pub fn disarm(&mut self) {
        self.last_ns = None;
    }

    /// Whether any input arrived since start or the last [`Watchdog::disarm`].
    pub fn armed(&self) -> bool {
        self.last_ns.is_some()
    }

    /// Age of the last input at `now_ns` (`None` when waiting).
    pub fn age_ns(&self, now_ns: u64) -> Option<u64> {
        self.last_ns.map(|t| now_ns.saturating_sub(t))
    }

    /// Classifies the input's age at `now_ns`.
    #[inline]
    pub fn check(&self, now_ns: u64) -> Freshness {
        match self.age_ns(now_ns) {
            None => Freshness::Waiting,
            Some(a) if a >= self.fault_ns => Freshness::Fault,
            Some(a) if a >= self.stale_ns => Freshness::Stale,
            Some(_) => Freshness::Fresh,
        }
    }

    /// The stale threshold in ns.
    pub fn stale_ns(&self) -> u64 {
        self.stale_ns
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const MS: u64 = 1_000_000;

    #[test]
    fn waits_until_first_input_then_ages_through_stale_to_fault() {
        let mut w = Watchdog::new(50.0, 200.0);
        assert_eq!(w.check(1_000 * MS), Freshness::Waiting);
        w.feed(1_000 * MS);
        assert_eq!(w.check(1_000 * MS), Freshness::Fresh);
        assert_eq!(w.check(1_049 * MS), Freshness::Fresh);
        assert_eq!(w.check(1_050 * MS), Freshness::Stale);
        assert_eq!(w.check(1_199 * MS), Freshness::Stale);
        assert_eq!(w.check(1_200 * MS), Freshness::Fault);
    }

    #[test]
    fn feeding_again_makes_it_fresh_and_disarm_forgets() {
        let mut w = Watchdog::new(50.0, 200.0);
        w.feed(0);
        assert_eq!(w.check(300 * MS), Freshness::Fault);
        w.feed(300 * MS);
        assert_eq!(w.check(301 * MS), Freshness::Fresh);
        w.disarm();
        assert_eq!(w.check(900 * MS), Freshness::Waiting);
    }

    #[test]
    fn an_18_ms_host_stall_does_not_go_stale_with_the_defaults() {
        let mut w = Watchdog::new(50.0, 200.0);
        w.feed(0);
        assert_eq!(w.check(18 * MS + MS), Freshness::Fresh);
    }

    #[test]
    fn a_clock_read_before_the_feed_is_not_negative_age() {
        let mut w = Watchdog::new(50.0, 200.0);
        w.feed(10 * MS);
        assert_eq!(w.age_ns(5 * MS), Some(0));
    }
}
