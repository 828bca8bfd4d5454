//! The grid of a periodic step that normally runs as its message arrives, ahead of its
//! time (the actuator's plant step on its torque command), with a periodic
//! [`crate::TimerFd`] behind it that runs the steps whose message did not come.
//!
//! Why the timer lags: moving a timer that is the CPU's next to expire makes the kernel
//! reprogram the clock-event device, which in a virtual machine is an exit to the
//! hypervisor (about 6 µs per move on the reference VM, against under 1 µs for a timer
//! that is not the next; `cargo run --release -p microrobot-runtime --example
//! timer_move`). A step due half a period after the
//! planner's tick is always the next to expire when its message arrives just after that
//! tick. So the timer is kept `lead` grid points past the pending step (at least one),
//! where the planner's next tick comes first, and it is moved only once every `lead`
//! steps. A missing message is then noticed up to `lead` periods late; the steps that
//! fell due meanwhile run back to back at once ([`ArrivalTicker::next_due`]), and when
//! messages stay away the timer's ticks run each step on time. With `lead` 0 the timer
//! stays at the pending step's own time and is moved at every step: for a step that must
//! run by its time whatever it costs (a bus cycle).

use crate::timer::Tick;

/// See the module documentation. Pure bookkeeping: the caller owns the timer, arms it
/// where [`ArrivalTicker::new`] and [`ArrivalTicker::take_early`] say, and tells
/// [`ArrivalTicker::on_expirations`] what its reads returned.
#[derive(Debug, Clone)]
pub struct ArrivalTicker {
    start_ns: u64,
    period_ns: u64,
    /// Next grid index to run.
    next_index: u64,
    /// Grid index of the timer's next expiration (it is periodic from there).
    timer_index: u64,
    lead: u64,
    /// Steps dropped because they fell due longer ago than the caller's `max_age_ns`.
    pub dropped_ticks: u64,
}

impl ArrivalTicker {
    /// A grid `start_ns + n·period_ns`, with its timer armed to fire first at
    /// `start_ns` (grid point 0) and every period after, moved `lead` grid points past
    /// the pending step by [`ArrivalTicker::take_early`] (0: onto it).
    pub fn new(start_ns: u64, period_ns: u64, lead: u64) -> Self {
        Self {
            start_ns,
            period_ns: period_ns.max(1),
            next_index: 0,
            timer_index: 0,
            lead,
            dropped_ticks: 0,
        }
    }

    /// The lead for a `period_ns` grid: as many periods as fit in `max_lag_ns` (how
    /// late a missing message may be noticed), at least one.
    pub fn lead_for(period_ns: u64, max_lag_ns: u64) -> u64 {
        (max_lag_ns / period_ns.max(1)).clamp(1, 64)
    }

    /// Period of the grid (ns).
    pub fn period_ns(&self) -> u64 {
        self.period_ns
    }

    fn ideal_ns(&self, index: u64) -> u64 {
        self.start_ns + index * self.period_ns
    }

    /// The timer fired `n` times (what its read returned).
    pub fn on_expirations(&mut self, n: u64) {
        self.timer_index += n;
    }

    /// The next step whose grid time has come (`ideal ≤ now_ns`), oldest first; `None`
    /// when caught up. Steps that fell due more than `max_age_ns` before `now_ns` are
    /// dropped, not replayed (counted in `dropped_ticks`).
    pub fn next_due(&mut self, now_ns: u64, max_age_ns: u64) -> Option<Tick> {
        if now_ns < self.ideal_ns(self.next_index) {
            return None;
        }
        // Newest grid point at or before now.
        let newest = (now_ns - self.start_ns) / self.period_ns;
        let oldest_kept = now_ns
            .saturating_sub(max_age_ns)
            .saturating_sub(self.start_ns)
            .div_ceil(self.period_ns);
        if self.next_index < oldest_kept {
            let first = oldest_kept.min(newest + 1);
            self.dropped_ticks += first - self.next_index;
            self.next_index = first;
            if first > newest {
                return None;
            }
        }
        let index = self.next_index;
        self.next_index += 1;
        Some(Tick {
            index,
            ideal_ns: self.ideal_ns(index),
        })
    }

    /// Drops every step whose grid time has come by `now_ns` (the periods a blocking
    /// call spent are not replayed).
    pub fn skip_due(&mut self, now_ns: u64) {
        if now_ns < self.ideal_ns(self.next_index) {
            return;
        }
        let first_ahead = (now_ns - self.start_ns) / self.period_ns + 1;
        self.dropped_ticks += first_ahead - self.next_index;
        self.next_index = first_ahead;
    }

    /// On a message's arrival at `now_ns`: the next step, run now ahead of its time,
    /// when it is due within one period (`now_ns` in `(ideal − period, ideal)`) and no
    /// step is due (run [`ArrivalTicker::next_due`] first). When the timer would then
    /// fire at or before the next pending step's own time, `rearm(first_ns, period_ns)`
    /// moves it `lead` grid points past that step; when that fails, nothing is taken
    /// and the timer runs the step.
    pub fn take_early(
        &mut self,
        now_ns: u64,
        rearm: impl FnOnce(u64, u64) -> bool,
    ) -> Option<Tick> {
        let index = self.next_index;
        let ideal_ns = self.ideal_ns(index);
        if now_ns >= ideal_ns || ideal_ns - now_ns > self.period_ns {
            return None;
        }
        let next = index + 1;
        if self.timer_index <= next {
            let to = next + self.lead;
            if !rearm(self.ideal_ns(to), self.period_ns) {
                return None;
            }
            self.timer_index = to;
        }
        self.next_index = next;
        Some(Tick { index, ideal_ns })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Grid 1000 + 100·n.
    fn grid(lead: u64) -> ArrivalTicker {
        ArrivalTicker::new(1000, 100, lead)
    }

    #[test]
    fn steps_taken_on_arrival_move_the_timer_once_every_lead_steps_and_never_onto_the_pending_step()
    {
        let mut t = grid(3);
        let mut armed = Vec::new();
        for k in 0..9u64 {
            let now = 1000 + k * 100 - 40;
            assert_eq!(t.next_due(now, u64::MAX), None);
            let tick = t.take_early(now, |f, p| {
                armed.push((k, f, p));
                true
            });
            assert_eq!(tick.map(|t| t.index), Some(k));
            // The timer never fires before the step after the pending one is due.
            assert!(t.timer_index > t.next_index, "after step {k}: {t:?}");
        }
        // Moved at steps 0, 3 and 6, each time 3 grid points past the pending step.
        assert_eq!(armed, vec![(0, 1400, 100), (3, 1700, 100), (6, 2000, 100)]);
    }

    #[test]
    fn with_no_lead_the_timer_is_moved_onto_each_pending_step_and_fires_on_time() {
        let mut t = grid(0);
        let mut armed = Vec::new();
        for k in 0..3u64 {
            let now = 1000 + k * 100 - 40;
            let tick = t.take_early(now, |f, _| {
                armed.push(f);
                true
            });
            assert_eq!(tick.map(|t| t.index), Some(k));
        }
        assert_eq!(armed, vec![1100, 1200, 1300]);
        // Step 3's message is missing: the timer fires at its time and it runs then.
        t.on_expirations(1);
        assert_eq!(t.next_due(1300, u64::MAX).map(|t| t.index), Some(3));
        assert_eq!(t.next_due(1300, u64::MAX), None);
    }

    #[test]
    fn a_step_is_taken_early_only_within_its_own_period_and_only_once() {
        let mut t = grid(1);
        // More than a period ahead, at or after its time, or the timer refused.
        assert_eq!(t.take_early(899, |_, _| true), None);
        assert_eq!(t.take_early(1000, |_, _| true), None);
        assert_eq!(t.take_early(950, |_, _| false), None);
        assert_eq!(t.take_early(950, |_, _| true).map(|t| t.index), Some(0));
        // The same period's second message finds step 1 more than a period ahead.
        assert_eq!(t.take_early(990, |_, _| true), None);
    }

    #[test]
    fn a_missing_message_s_step_runs_late_when_the_next_one_arrives_then_that_one_early() {
        let mut t = grid(2);
        assert_eq!(t.take_early(960, |_, _| true).map(|t| t.index), Some(0));
        // Step 1's message never comes; step 2's arrives at 1160, after step 1's time.
        assert_eq!(t.take_early(1160, |_, _| true), None);
        assert_eq!(t.next_due(1160, u64::MAX).map(|t| t.index), Some(1));
        assert_eq!(t.next_due(1160, u64::MAX), None);
        assert_eq!(t.take_early(1160, |_, _| true).map(|t| t.index), Some(2));
        assert_eq!(t.dropped_ticks, 0);
    }

    #[test]
    fn when_messages_stop_the_timer_runs_the_missed_steps_then_each_on_time() {
        let mut t = grid(2);
        let mut armed_at = 0;
        t.take_early(960, |f, _| {
            armed_at = f;
            true
        });
        // Timer moved to grid point 3 (1300): it fires there, steps 1..=3 are due.
        assert_eq!(armed_at, 1300);
        t.on_expirations(1);
        let due: Vec<u64> = std::iter::from_fn(|| t.next_due(1300, u64::MAX))
            .map(|t| t.index)
            .collect();
        assert_eq!(due, vec![1, 2, 3]);
        // Then periodic: each firing runs its own step.
        for k in 4..8 {
            t.on_expirations(1);
            let now = 1000 + k * 100;
            assert_eq!(t.next_due(now, u64::MAX).map(|t| t.index), Some(k));
            assert_eq!(t.next_due(now, u64::MAX), None);
        }
        // A message again: its step runs early, and the timer (due at step 8's own
        // time) is moved past it.
        let mut moved = None;
        let tick = t.take_early(1760, |f, _| {
            moved = Some(f);
            true
        });
        assert_eq!(tick.map(|t| t.index), Some(8));
        assert_eq!(moved, Some(2100));
    }

    #[test]
    fn steps_older_than_the_age_limit_are_dropped_not_replayed() {
        let mut t = grid(1);
        // At 2050 steps 0..=10 are due; only those at most 250 ns old (8, 9, 10) run.
        let due: Vec<u64> = std::iter::from_fn(|| t.next_due(2050, 250))
            .map(|t| t.index)
            .collect();
        assert_eq!(due, vec![8, 9, 10]);
        assert_eq!(t.dropped_ticks, 8);
        // Everything too old: all dropped, nothing run.
        let mut t = grid(1);
        assert_eq!(t.next_due(5050, 10), None);
        assert_eq!(t.dropped_ticks, 41);
        assert_eq!(t.next_due(5060, 10), None);
        assert_eq!(t.next_due(5100, 10).map(|t| t.index), Some(41));
    }

    #[test]
    fn skipping_drops_every_due_step() {
        let mut t = grid(1);
        t.skip_due(1250);
        assert_eq!(t.dropped_ticks, 3);
        assert_eq!(t.next_due(1250, u64::MAX), None);
        assert_eq!(t.take_early(1260, |_, _| true).map(|t| t.index), Some(3));
    }

    #[test]
    fn the_lead_is_the_periods_in_the_allowed_lag_at_least_one() {
        assert_eq!(ArrivalTicker::lead_for(250_000, 1_000_000), 4);
        assert_eq!(ArrivalTicker::lead_for(1_000_000, 1_000_000), 1);
        assert_eq!(ArrivalTicker::lead_for(2_000_000, 1_000_000), 1);
        assert_eq!(ArrivalTicker::lead_for(1, u64::MAX), 64);
    }
}
