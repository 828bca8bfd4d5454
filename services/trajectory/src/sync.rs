//! Synchronised soft motion: all joints finish together.
//!
//! Each joint's time-optimal duration is computed; the slowest sets T (or the
//! requested minimum duration if longer). A joint started in motion may be unable to
//! finish at some durations above its own minimum (blocked intervals of its stretch
//! family, computed exactly by [`crate::soft::stretch::Stretch::next_reachable`]); T
//! is then raised to the smallest duration every joint reaches, as Ruckig's time
//! synchronisation does with its blocked intervals. Every other joint is stretched to
//! T within its limits.

use crate::piecewise::{Kin, Phases, Piecewise};
use crate::soft::stretch::Stretch;
use crate::soft::{Limits1, brake::brake, from_state, rest_to_rest};
use crate::{KinematicLimits, MAX_JOINTS, MotionState};

#[derive(Clone, Copy, Default)]
struct JointWork {
    /// State after the brake pre-phase (the start itself when none).
    after: Kin,
    t_brake: f64,
    /// Time-optimal duration including the brake.
    t_opt: f64,
    /// Peak velocity of the optimal motion, anchoring its stretch.
    anchor: Option<f64>,
    /// Brake point of `after`, relative to it.
    pb: f64,
    /// The solved optimum (its phases are written only if the joint is not
    /// stretched); `None` when `after` is at rest (closed form).
    opt: Option<from_state::Optimal>,
}

/// Every joint starts at rest: closed forms only (no brake, no blocked intervals,
/// no root search). The same phases as the general path.
fn plan_rest(
    dof: usize,
    q0: &crate::JointVector,
    target_q: &crate::JointVector,
    limits: &KinematicLimits,
    min_duration: Option<f64>,
    joints: &mut [Piecewise; MAX_JOINTS],
) -> f64 {
    let mut t_opt = [0.0; MAX_JOINTS];
    let mut t_sync = min_duration.unwrap_or(0.0);
    for i in 0..dof {
        let d = (target_q[i] - q0[i]).abs();
        t_opt[i] = rest_to_rest::time_optimal_duration(d, &limits1(limits, i));
        t_sync = t_sync.max(t_opt[i]);
    }
    let eps = 1e-12 * t_sync.max(1.0);
    let mut plans = [Phases::default(); MAX_JOINTS];
    let mut starts = [Kin::default(); MAX_JOINTS];
    let mut fins = [Kin::default(); MAX_JOINTS];
    for i in 0..dof {
        let lim = limits1(limits, i);
        let d = target_q[i] - q0[i];
        let mut ph = if t_sync - t_opt[i] <= eps {
            rest_to_rest::time_optimal(d.abs(), &lim)
        } else {
            rest_to_rest::stretched(d.abs(), t_sync, &lim)
        };
        if d < 0.0 {
            for p in &mut ph.p[..ph.n] {
                p.j = -p.j;
            }
        }
        plans[i] = ph;
        starts[i] = Kin {
            p: q0[i],
            v: 0.0,
            a: 0.0,
        };
        fins[i] = Kin {
            p: target_q[i],
            v: 0.0,
            a: 0.0,
        };
    }
    Piecewise::set_phases_many(
        &mut joints[..dof],
        &starts[..dof],
        &plans[..dof],
        &fins[..dof],
    );
    t_sync
}

pub(crate) fn limits1(l: &KinematicLimits, i: usize) -> Limits1 {
    Limits1 {
        v: l.velocity[i],
        a: l.acceleration[i],
        j: l.jerk[i],
    }
}

/// Plans every joint from `start` to rest at `target_q`, synchronised, writing the
/// motions into `joints` in place. Returns the common duration, whether any joint
/// braked, and whether every joint started at rest (each motion is then monotone,
/// between its validated start and target: no position check needed).
pub(crate) fn plan_soft(
    dof: usize,
    start: &MotionState,
    target_q: &crate::JointVector,
    limits: &KinematicLimits,
    min_duration: Option<f64>,
    joints: &mut [Piecewise; MAX_JOINTS],
) -> (f64, bool, bool) {
    if (0..dof).all(|i| start.qd[i] == 0.0 && start.qdd[i] == 0.0) {
        return (
            plan_rest(dof, &start.q, target_q, limits, min_duration, joints),
            false,
            true,
        );
    }
    let mut work = [JointWork::default(); MAX_JOINTS];
    // Each joint's phases; written to `joints` once T is settled.
    let mut plans = [Phases::default(); MAX_JOINTS];
    let mut braked = false;
    let mut t_sync = min_duration.unwrap_or(0.0);
    let k0 = |i: usize| Kin {
        p: start.q[i],
        v: start.qd[i],
        a: start.qdd[i],
    };
    let fin = |i: usize| Kin {
        p: target_q[i],
        v: 0.0,
        a: 0.0,
    };
    for i in 0..dof {
        let lim = limits1(limits, i);
        let ph = brake(k0(i), &lim);
        braked |= ph.n > 0;
        let t_brake = ph.duration();
        let after = ph.integrate(k0(i));
        let d = target_q[i] - after.p;
        work[i] = if after.v == 0.0 && after.a == 0.0 {
            JointWork {
                after,
                t_brake,
                t_opt: t_brake + rest_to_rest::time_optimal_duration(d.abs(), &lim),
                anchor: None,
                pb: 0.0,
                opt: None,
            }
        } else {
            let o = from_state::optimal(after.v, after.a, d, &lim);
            JointWork {
                after,
                t_brake,
                t_opt: t_brake + o.duration,
                anchor: o.anchor,
                pb: o.pb,
                opt: Some(o),
            }
        };
        t_sync = t_sync.max(work[i].t_opt);
    }
    // Stretch the others. A joint that cannot take T (a blocked interval) names the
    // next duration it reaches; T moves to the largest such and the round repeats, so
    // the final T is the smallest duration ≥ the slowest minimum that every joint
    // reaches. Each raise lands on an interval end of some joint (at most 3 each), so
    // this settles within a few rounds; the round limit is a guard against round-off
    // ping-pong, after which T moves past every joint's "stop, then move" floor.
    let mut stretches: [Option<Stretch>; MAX_JOINTS] = [None; MAX_JOINTS];
    let mut stretched = [false; MAX_JOINTS];
    let eps = |t: f64| 1e-12 * t.max(1.0);
    for round in 0..4 * MAX_JOINTS + 2 {
        let mut raise = t_sync;
        let mut blocked = false;
        for i in 0..dof {
            let w = work[i];
            stretched[i] = false;
            if t_sync - w.t_opt <= eps(t_sync) {
                continue;
            }
            let lim = limits1(limits, i);
            let st = *stretches[i].get_or_insert_with(|| {
                Stretch::prepared(
                    w.after.v,
                    w.after.a,
                    target_q[i] - w.after.p,
                    &lim,
                    w.anchor,
                    w.pb,
                )
            });
            match st.phases(t_sync - w.t_brake, &lim) {
                Some(main) => {
                    let mut ph = brake(k0(i), &lim);
                    ph.extend(&main);
                    plans[i] = ph;
                    stretched[i] = true;
                }
                None => {
                    blocked = true;
                    let next = w.t_brake + st.next_reachable(t_sync - w.t_brake);
                    let next = if next > t_sync {
                        next
                    } else {
                        w.t_brake + st.guaranteed()
                    };
                    raise = raise.max(next);
                }
            }
        }
        if !blocked {
            break;
        }
        t_sync = raise;
        if round + 1 == 4 * MAX_JOINTS {
            // Guard: past every joint's floor, "stop, then move" reaches T.
            for i in 0..dof {
                let w = work[i];
                let st = Stretch::prepared(
                    w.after.v,
                    w.after.a,
                    target_q[i] - w.after.p,
                    &limits1(limits, i),
                    w.anchor,
                    w.pb,
                );
                t_sync = t_sync.max(w.t_brake + st.guaranteed());
            }
        }
    }
    // The joints that set T move time-optimally: their phases are written now.
    for i in 0..dof {
        if stretched[i] {
            continue;
        }
        let lim = limits1(limits, i);
        let mut ph = brake(k0(i), &lim);
        let w = &work[i];
        let opt = match &w.opt {
            Some(o) => o.phases(&lim),
            None => {
                let d = target_q[i] - w.after.p;
                let mut r = rest_to_rest::time_optimal(d.abs(), &lim);
                if d < 0.0 {
                    for p in &mut r.p[..r.n] {
                        p.j = -p.j;
                    }
                }
                r
            }
        };
        ph.extend(&opt);
        plans[i] = ph;
    }
    let starts: [Kin; MAX_JOINTS] = std::array::from_fn(k0);
    let fins: [Kin; MAX_JOINTS] = std::array::from_fn(fin);
    Piecewise::set_phases_many(
        &mut joints[..dof],
        &starts[..dof],
        &plans[..dof],
        &fins[..dof],
    );
    (t_sync, braked, false)
}
