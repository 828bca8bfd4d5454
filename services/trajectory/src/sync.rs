//! Synchronised soft motion: all joints finish together.
//!
//! Each joint's time-optimal duration is computed; the slowest sets T (or the
//! requested minimum duration if longer). A joint started in motion may be unable to
//! finish at some durations just above its own minimum (its stretch family starts at
//! a *floor*, see [`crate::soft::stretch`]); T is then raised to the smallest duration
//! every joint reaches, as Ruckig's time synchronisation does with blocked intervals.
//! Every other joint is then stretched to T within its limits.

use crate::piecewise::{Kin, Phases, Piecewise};
use crate::soft::stretch::Stretch;
use crate::soft::{Limits1, brake::brake, from_state, rest_to_rest};
use crate::{JointState, KinematicLimits, MAX_JOINTS};

/// Result of planning: per-joint motions, common duration, whether any joint braked.
pub(crate) struct SoftPlan {
    pub joints: [Piecewise; MAX_JOINTS],
    pub duration: f64,
    pub braked: bool,
}

#[derive(Clone, Copy, Default)]
struct JointWork {
    brake: Phases,
    after: Kin,
    opt: Phases,
    t_brake: f64,
    t_opt: f64,
}

pub(crate) fn limits1(l: &KinematicLimits, i: usize) -> Limits1 {
    Limits1 {
        v: l.velocity[i],
        a: l.acceleration[i],
        j: l.jerk[i],
    }
}

/// Plans every joint from `start` to rest at `target_q`, synchronised.
pub(crate) fn plan_soft(
    dof: usize,
    start: &JointState,
    target_q: &crate::JointVector,
    limits: &KinematicLimits,
    min_duration: Option<f64>,
) -> SoftPlan {
    let mut work = [JointWork::default(); MAX_JOINTS];
    let mut braked = false;
    let mut t_sync = min_duration.unwrap_or(0.0);
    for i in 0..dof {
        let lim = limits1(limits, i);
        let k0 = Kin {
            p: start.q[i],
            v: start.qd[i],
            a: start.qdd[i],
        };
        let w = &mut work[i];
        w.brake = brake(k0, &lim);
        braked |= w.brake.n > 0;
        w.t_brake = w.brake.duration();
        w.after = w.brake.integrate(k0);
        let d = target_q[i] - w.after.p;
        w.opt = if w.after.v == 0.0 && w.after.a == 0.0 {
            let mut ph = rest_to_rest::time_optimal(d.abs(), &lim);
            if d < 0.0 {
                for p in &mut ph.p[..ph.n] {
                    p.j = -p.j;
                }
            }
            ph
        } else {
            from_state::time_optimal(w.after.v, w.after.a, d, &lim)
        };
        w.t_opt = w.t_brake + w.opt.duration();
        t_sync = t_sync.max(w.t_opt);
    }
    // Stretch the others; raise T past blocked intervals until every joint reaches it.
    let mut phases = [Phases::default(); MAX_JOINTS];
    let mut stretches: [Option<Stretch>; MAX_JOINTS] = [None; MAX_JOINTS];
    let eps = |t: f64| 1e-12 * t.max(1.0);
    for _ in 0..=dof + 1 {
        let mut raise = t_sync;
        for i in 0..dof {
            let w = &work[i];
            let lim = limits1(limits, i);
            phases[i] = w.brake;
            if t_sync - w.t_opt <= eps(t_sync) {
                phases[i].extend(&w.opt);
                continue;
            }
            let st = *stretches[i].get_or_insert_with(|| {
                Stretch::new(w.after.v, w.after.a, target_q[i] - w.after.p, &lim)
            });
            match st.phases(t_sync - w.t_brake, &lim) {
                Some(ph) => phases[i].extend(&ph),
                None => raise = raise.max(w.t_brake + st.guaranteed()),
            }
        }
        if raise <= t_sync {
            break;
        }
        t_sync = raise;
    }
    let mut joints = [Piecewise::hold(0.0); MAX_JOINTS];
    for i in 0..dof {
        let k0 = Kin {
            p: start.q[i],
            v: start.qd[i],
            a: start.qdd[i],
        };
        let fin = Kin {
            p: target_q[i],
            v: 0.0,
            a: 0.0,
        };
        joints[i] = Piecewise::from_phases(k0, &phases[i], Some(fin));
    }
    SoftPlan {
        joints,
        duration: t_sync,
        braked,
    }
}
