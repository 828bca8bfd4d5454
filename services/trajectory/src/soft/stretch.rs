//! Soft motion stretched to a given duration T (for synchronisation and the seed's
//! 5/10/20/60 s comparisons), within the same limits.
//!
//! Family: velocity change (v0, a0) → (vp, 0), cruise at vp, symmetric ramp vp → 0.
//! For a given T the cruise takes what the ramps leave, and vp solves the distance
//! equation D1(vp) + vp·Tc + D2(vp) = d — a bracketed root between vp = 0 (stop,
//! wait, nothing more) and the family's fastest member. From rest, and whenever the
//! optimal motion's acceleration crosses zero at its velocity peak, that fastest
//! member *is* the time-optimal motion; otherwise (a start that is decelerating
//! towards a target just beyond the brake point) the family starts a little later
//! and durations in between are reported as blocked, like Ruckig's blocked intervals.

use super::from_state::brake_point;
use super::velocity::{ramp_from_rest, velocity_change};
use super::{Kin, Limits1, Phases, rest_to_rest, solve};

/// Prepared stretch problem for one joint (positive frame).
#[derive(Debug, Clone, Copy)]
pub struct Stretch {
    sg: f64,
    v0: f64,
    a0: f64,
    d: f64,
    vp_hi: f64,
    floor: f64,
    rest: bool,
}

impl Stretch {
    /// Prepares stretching the motion (v0, a0) → rest at displacement `d`.
    pub fn new(v0: f64, a0: f64, d: f64, lim: &Limits1) -> Self {
        if v0 == 0.0 && a0 == 0.0 {
            let floor = rest_to_rest::time_optimal(d.abs(), lim).duration();
            return Self {
                sg: if d >= 0.0 { 1.0 } else { -1.0 },
                v0,
                a0,
                d: d.abs(),
                vp_hi: lim.v,
                floor,
                rest: true,
            };
        }
        let sg = if d >= brake_point(v0, a0, lim) {
            1.0
        } else {
            -1.0
        };
        let (v, a, dd) = (sg * v0, sg * a0, sg * d);
        let dist = |vp: f64| {
            let r1 = velocity_change(v, a, vp, lim);
            let k = r1.integrate(Kin { p: 0.0, v, a });
            let (t1, t2, d2) = ramp_from_rest(vp, lim);
            (k.p + d2, r1.duration() + 2.0 * t1 + t2)
        };
        let (d_v, t_v) = dist(lim.v);
        let (vp_hi, floor) = if dd >= d_v {
            (lim.v, t_v + (dd - d_v) / lim.v)
        } else {
            let vz = solve(|vp| dist(vp).0 - dd, 0.0, lim.v);
            (vz, dist(vz).1)
        };
        Self {
            sg,
            v0: v,
            a0: a,
            d: dd,
            vp_hi,
            floor,
            rest: false,
        }
    }

    /// Shortest duration this family reaches; every T ≥ floor is reachable.
    pub fn floor(&self) -> f64 {
        self.floor
    }

    /// Phases (original frame) finishing at exactly `t` ≥ floor (clamped up to it).
    pub fn phases(&self, t: f64, lim: &Limits1) -> Phases {
        let t = t.max(self.floor);
        let mut ph = if self.rest {
            rest_to_rest::stretched(self.d, t, lim)
        } else {
            let (v, a, dd) = (self.v0, self.a0, self.d);
            let f = |vp: f64| {
                let r1 = velocity_change(v, a, vp, lim);
                let k = r1.integrate(Kin { p: 0.0, v, a });
                let (t1, t2, d2) = ramp_from_rest(vp, lim);
                let tc = t - r1.duration() - 2.0 * t1 - t2;
                if tc < 0.0 {
                    tc - 1.0 - dd.abs()
                } else {
                    k.p + d2 + vp * tc - dd
                }
            };
            let vp = solve(f, 0.0, self.vp_hi);
            let mut ph = velocity_change(v, a, vp, lim);
            let (t1, t2, _) = ramp_from_rest(vp, lim);
            ph.push((t - ph.duration() - 2.0 * t1 - t2).max(0.0), 0.0);
            ph.push(t1, -lim.j);
            ph.push(t2, 0.0);
            ph.push(t1, lim.j);
            ph
        };
        for p in &mut ph.p[..ph.n] {
            p.j *= self.sg;
        }
        ph
    }
}
