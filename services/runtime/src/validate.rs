//! Validation of bus payloads at every stage: finite values, the robot's joint count,
//! increasing sequence numbers per publisher, fresh timestamps, joint limits. A refused
//! message is counted and dropped; the stage holds its last good output.

use microrobot_messages::{
    JointSetpoint, JointState, MAX_JOINTS, RefusalReason, TorqueCommand, all_finite,
};

/// Why an input message was refused.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Refusal {
    /// NaN or infinity in an active joint.
    NonFinite,
    /// `dof` differs from the robot's joint count.
    WrongDof,
    /// Sequence number not above the last one of the same publisher (duplicate or reordered).
    OutOfOrder,
    /// Timestamp older than `stale_ms`, or in the future.
    Stale,
    /// Outside the joint limits.
    OutOfLimits,
    /// From a second publisher while the stream's publisher is still live.
    SecondPublisher,
    /// From a process outside the pipeline ([`crate::provenance`]).
    Outsider,
}

impl Refusal {
    /// The wire code reported in `ServiceStatus::last_input_refusal`.
    pub fn reason(self) -> RefusalReason {
        match self {
            Self::NonFinite => RefusalReason::NonFinite,
            Self::WrongDof => RefusalReason::WrongDof,
            Self::OutOfOrder => RefusalReason::OutOfOrder,
            Self::Stale => RefusalReason::Stale,
            Self::OutOfLimits => RefusalReason::OutOfLimits,
            Self::SecondPublisher => RefusalReason::SecondPublisher,
            Self::Outsider => RefusalReason::Outsider,
        }
    }
}

/// The one publisher a stream follows (messages/README.md, "One publisher per stream").
///
/// A message from another publisher is refused ([`Refusal::SecondPublisher`]) while
/// the current one is live, i.e. its last accepted message is younger than the
/// takeover time, so a stray or rogue second publisher cannot interleave its messages
/// with the stream's. Once the current publisher has been silent that long (it died,
/// or was killed and the supervisor restarts it), the next one takes the stream over.
/// Used by [`SeqTracker`] for the bus streams and by the teleop master stream.
#[derive(Debug, Clone, Copy)]
pub struct StreamOwner {
    publisher: Option<u128>,
    last_accepted_ns: u64,
    takeover_ns: u64,
    /// Times another publisher took the stream over (restarts seen).
    pub changes: u64,
}

impl StreamOwner {
    /// An owner that another publisher may replace after `takeover_ns` of silence.
    pub fn new(takeover_ns: u64) -> Self {
        Self {
            publisher: None,
            last_accepted_ns: 0,
            takeover_ns,
            changes: 0,
        }
    }

    /// Whether a message from `publisher` at `now_ns` may be taken: `Ok(false)` from
    /// the current publisher, `Ok(true)` from a new one (the first, or one taking over
    /// a silent stream), [`Refusal::SecondPublisher`] while another one is live.
    /// Nothing changes until [`StreamOwner::accepted`].
    #[inline]
    pub fn admits(&self, publisher: u128, now_ns: u64) -> Result<bool, Refusal> {
        match self.publisher {
            Some(p) if p == publisher => Ok(false),
            Some(_) if now_ns.saturating_sub(self.last_accepted_ns) < self.takeover_ns => {
                Err(Refusal::SecondPublisher)
            }
            _ => Ok(true),
        }
    }

    /// A message from `publisher` (admitted) was accepted at `now_ns`.
    #[inline]
    pub fn accepted(&mut self, publisher: u128, now_ns: u64) {
        if self.publisher.is_some_and(|p| p != publisher) {
            self.changes += 1;
        }
        self.publisher = Some(publisher);
        self.last_accepted_ns = now_ns;
    }
}

/// Per-stream sequence tracking: refuses duplicates and reordering, counts gaps as lost
/// messages, and follows one publisher at a time ([`StreamOwner`]; the takeover time is
/// the stage's `stale_ms`). A publisher taking over starts its sequence afresh.
#[derive(Debug, Clone, Copy)]
pub struct SeqTracker {
    owner: StreamOwner,
    last: Option<u64>,
    /// Messages missing between accepted ones (gaps).
    pub lost: u64,
}

impl SeqTracker {
    /// A tracker whose stream another publisher may take over after `takeover_ns` of
    /// silence from the current one.
    pub fn new(takeover_ns: u64) -> Self {
        Self {
            owner: StreamOwner::new(takeover_ns),
            last: None,
            lost: 0,
        }
    }

    /// Checks `seq` from `publisher` (iceoryx2's unique publisher id), received at
    /// `now_ns`; on success it becomes the last accepted one.
    #[inline]
    pub fn accept(&mut self, publisher: u128, seq: u64, now_ns: u64) -> Result<(), Refusal> {
        let new_publisher = self.owner.admits(publisher, now_ns)?;
        if !new_publisher {
            match self.last {
                Some(l) if seq <= l => return Err(Refusal::OutOfOrder),
                Some(l) => self.lost += seq - l - 1,
                None => {}
            }
        }
        self.last = Some(seq);
        self.owner.accepted(publisher, now_ns);
        Ok(())
    }

    /// Whether a message from `publisher` would come from a publisher other than the
    /// one the stream follows (the first, a takeover or an intruder): the stage then
    /// checks where it comes from ([`crate::provenance`]) before it is taken.
    #[inline]
    pub fn is_new_publisher(&self, publisher: u128) -> bool {
        self.owner.publisher != Some(publisher)
    }

    /// Whether a message from `publisher` at `now_ns` would take the stream over
    /// (`Ok(true)`: the first publisher, or a new one after the owner's silence),
    /// [`Refusal::SecondPublisher`] while another one is live; changes nothing. A stage
    /// checks where a taking-over publisher comes from ([`crate::provenance`]) first.
    #[inline]
    pub fn takes_over(&self, publisher: u128, now_ns: u64) -> Result<bool, Refusal> {
        self.owner.admits(publisher, now_ns)
    }

    /// [`Self::accept`], where a message that would take the stream over (the first
    /// publisher, or a new one after the owner's silence) is taken only if
    /// `from_pipeline()` says the pipeline's supervisor started its process
    /// ([`crate::provenance`]); another's is [`Refusal::Outsider`]. `from_pipeline` is
    /// asked only on a takeover, so the steady stream pays nothing for it.
    #[inline]
    pub fn accept_from(
        &mut self,
        publisher: u128,
        seq: u64,
        now_ns: u64,
        from_pipeline: impl FnOnce() -> bool,
    ) -> Result<(), Refusal> {
        if self.takes_over(publisher, now_ns)? && !from_pipeline() {
            return Err(Refusal::Outsider);
        }
        self.accept(publisher, seq, now_ns)
    }

    /// Times another publisher took the stream over (restarts seen).
    pub fn publisher_changes(&self) -> u64 {
        self.owner.changes
    }

    /// Last accepted sequence number.
    pub fn last(&self) -> Option<u64> {
        self.last
    }
}

/// A stamp is fresh when it is at most `stale_ns` old and not more than 1 ms in the future.
#[inline]
pub fn check_fresh(stamp_ns: u64, now_ns: u64, stale_ns: u64) -> Result<(), Refusal> {
    if stamp_ns > now_ns.saturating_add(1_000_000) || now_ns.saturating_sub(stamp_ns) > stale_ns {
        Err(Refusal::Stale)
    } else {
        Ok(())
    }
}

fn dof_ok(msg_dof: u32, dof: usize) -> Result<(), Refusal> {
    if msg_dof as usize != dof || dof > MAX_JOINTS {
        Err(Refusal::WrongDof)
    } else {
        Ok(())
    }
}

fn finite(arrays: &[&[f64; MAX_JOINTS]], dof: u32) -> Result<(), Refusal> {
    if arrays.iter().all(|a| all_finite(a, dof)) {
        Ok(())
    } else {
        Err(Refusal::NonFinite)
    }
}

/// Joint bounds a setpoint must respect (SI), with a small tolerance.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct JointBounds {
    pub q_min: [f64; MAX_JOINTS],
    pub q_max: [f64; MAX_JOINTS],
    pub qd_max: [f64; MAX_JOINTS],
}

impl JointBounds {
    /// Tolerance on positions (rad or m) and, relative, on velocities.
    pub const TOL_Q: f64 = 1e-6;
    pub const TOL_QD_REL: f64 = 0.05;

    /// Whether the first `dof` joints of `q`, `qd` are within bounds.
    pub fn contains(&self, q: &[f64; MAX_JOINTS], qd: &[f64; MAX_JOINTS], dof: usize) -> bool {
        (0..dof.min(MAX_JOINTS)).all(|i| {
            q[i] >= self.q_min[i] - Self::TOL_Q
                && q[i] <= self.q_max[i] + Self::TOL_Q
                && qd[i].abs() <= self.qd_max[i] * (1.0 + Self::TOL_QD_REL) + Self::TOL_Q
        })
    }
}

/// Checks a setpoint's shape, values and limits (not its sequence or age).
pub fn check_setpoint(m: &JointSetpoint, dof: usize, bounds: &JointBounds) -> Result<(), Refusal> {
    dof_ok(m.dof, dof)?;
    finite(&[&m.q, &m.qd, &m.qdd, &m.jerk], m.dof)?;
    if !bounds.contains(&m.q, &m.qd, dof) {
        return Err(Refusal::OutOfLimits);
    }
    Ok(())
}

/// Checks a torque command's shape and values (the actuator saturates, it does not refuse, large torques).
pub fn check_torque(m: &TorqueCommand, dof: usize) -> Result<(), Refusal> {
    dof_ok(m.dof, dof)?;
    finite(&[&m.tau, &m.q_desired], m.dof)
}

/// Checks a measured state's shape and values.
pub fn check_state(m: &JointState, dof: usize) -> Result<(), Refusal> {
    dof_ok(m.dof, dof)?;
    finite(&[&m.q, &m.qd, &m.tau_applied], m.dof)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sequence_gaps_are_lost_and_duplicates_refused() {
        let mut t = SeqTracker::new(50);
        assert_eq!(t.accept(7, 1, 0), Ok(()));
        assert_eq!(t.accept(7, 2, 1), Ok(()));
        assert_eq!(t.accept(7, 5, 2), Ok(()));
        assert_eq!(t.lost, 2);
        assert_eq!(t.accept(7, 5, 3), Err(Refusal::OutOfOrder));
        assert_eq!(t.accept(7, 3, 4), Err(Refusal::OutOfOrder));
        assert_eq!(t.last(), Some(5));
    }

    #[test]
    fn a_second_publisher_is_refused_while_the_first_is_live_and_takes_over_after_it_fell_silent() {
        let mut t = SeqTracker::new(50);
        t.accept(1, 100, 1_000).unwrap();
        // Live: the first one's last message is younger than the takeover time.
        assert_eq!(t.accept(2, 0, 1_049), Err(Refusal::SecondPublisher));
        t.accept(1, 101, 1_049).unwrap();
        assert_eq!(t.accept(2, 1, 1_098), Err(Refusal::SecondPublisher));
        assert_eq!(t.publisher_changes(), 0);
        assert_eq!(t.last(), Some(101));
        // Silent for the takeover time: the next publisher takes over, sequence afresh.
        assert_eq!(t.accept(2, 7, 1_099), Ok(()));
        assert_eq!(t.publisher_changes(), 1);
        assert_eq!(t.accept(2, 8, 1_100), Ok(()));
        assert_eq!(t.lost, 0);
        // And now the old one is the second publisher.
        assert_eq!(t.accept(1, 102, 1_101), Err(Refusal::SecondPublisher));
    }

    #[test]
    fn provenance_is_asked_only_on_a_takeover_and_an_outsider_changes_nothing() {
        let mut t = SeqTracker::new(50);
        let asked = std::cell::Cell::new(0);
        let from = |ok: bool| {
            let asked = &asked;
            move || {
                asked.set(asked.get() + 1);
                ok
            }
        };
        // The first publisher takes the stream: asked once.
        assert_eq!(t.accept_from(1, 10, 1_000, from(true)), Ok(()));
        assert_eq!(asked.get(), 1);
        // The steady stream is not asked.
        assert_eq!(t.accept_from(1, 11, 1_010, from(false)), Ok(()));
        assert_eq!(asked.get(), 1);
        // A second publisher while the owner is live: refused before provenance.
        assert_eq!(
            t.accept_from(2, 0, 1_020, from(true)),
            Err(Refusal::SecondPublisher)
        );
        assert_eq!(asked.get(), 1);
        // After the owner's silence an outsider is refused and the stream stays the
        // owner's: its next message is in sequence, nothing counted lost.
        assert_eq!(
            t.accept_from(3, 0, 1_100, from(false)),
            Err(Refusal::Outsider)
        );
        assert_eq!(asked.get(), 2);
        assert_eq!(t.publisher_changes(), 0);
        assert_eq!(t.accept_from(1, 12, 1_101, from(false)), Ok(()));
        assert_eq!((t.last(), t.lost), (Some(12), 0));
        // A restarted pipeline process takes over after the silence.
        assert_eq!(t.accept_from(4, 0, 1_200, from(true)), Ok(()));
        assert_eq!(t.publisher_changes(), 1);
    }

    #[test]
    fn stale_and_future_stamps_are_refused() {
        let ms = 1_000_000;
        assert_eq!(check_fresh(100 * ms, 149 * ms, 50 * ms), Ok(()));
        assert_eq!(
            check_fresh(100 * ms, 151 * ms, 50 * ms),
            Err(Refusal::Stale)
        );
        assert_eq!(
            check_fresh(200 * ms, 100 * ms, 50 * ms),
            Err(Refusal::Stale)
        );
    }

    fn bounds() -> JointBounds {
        JointBounds {
            q_min: [-1.0; MAX_JOINTS],
            q_max: [1.0; MAX_JOINTS],
            qd_max: [2.0; MAX_JOINTS],
        }
    }

    #[test]
    fn setpoints_with_nan_wrong_dof_or_out_of_limits_are_refused() {
        let mut m = JointSetpoint {
            dof: 6,
            ..Default::default()
        };
        assert_eq!(check_setpoint(&m, 6, &bounds()), Ok(()));
        assert_eq!(check_setpoint(&m, 5, &bounds()), Err(Refusal::WrongDof));
        m.qdd[5] = f64::NAN;
        assert_eq!(check_setpoint(&m, 6, &bounds()), Err(Refusal::NonFinite));
        m.qdd[5] = 0.0;
        m.jerk[7] = f64::NAN; // inactive joint: ignored
        assert_eq!(check_setpoint(&m, 6, &bounds()), Ok(()));
        m.q[0] = 1.1;
        assert_eq!(check_setpoint(&m, 6, &bounds()), Err(Refusal::OutOfLimits));
        m.q[0] = 0.0;
        m.qd[2] = -2.2;
        assert_eq!(check_setpoint(&m, 6, &bounds()), Err(Refusal::OutOfLimits));
    }

    #[test]
    fn torque_and_state_with_infinity_are_refused() {
        let mut t = TorqueCommand {
            dof: 3,
            ..Default::default()
        };
        assert_eq!(check_torque(&t, 3), Ok(()));
        t.tau[1] = f64::INFINITY;
        assert_eq!(check_torque(&t, 3), Err(Refusal::NonFinite));
        let mut s = JointState {
            dof: 9,
            ..Default::default()
        };
        assert_eq!(check_state(&s, 9), Err(Refusal::WrongDof));
        s.dof = 2;
        s.qd[0] = f64::NAN;
        assert_eq!(check_state(&s, 2), Err(Refusal::NonFinite));
    }
}
