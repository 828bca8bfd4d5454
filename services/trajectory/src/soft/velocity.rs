//! The time-optimal jerk-limited velocity change (v0, a0) → (vf, 0), the building block
//! of every soft-motion profile.

use super::{Limits1, Phases, stop_velocity};

/// Phases of the fastest change from (v0, a0) to velocity `vf` at zero acceleration
/// with |a| ≤ amax, |jerk| ≤ jmax: jerk ±jmax up to a peak acceleration, an optional
/// hold at ±amax, jerk ∓jmax back to zero. Expects |a0| ≤ amax.
#[inline]
pub fn velocity_change(v0: f64, a0: f64, vf: f64, lim: &Limits1) -> Phases {
    let (jm, am) = (lim.j, lim.a);
    let up = vf >= stop_velocity(v0, a0, jm);
    let sg = if up { 1.0 } else { -1.0 };
    let (a0m, dv) = (sg * a0, sg * (vf - v0));
    let ap = (jm * dv + 0.5 * a0m * a0m).max(0.0).sqrt();
    let mut ph = Phases::default();
    if ap <= am {
        ph.push(((ap - a0m) / jm).max(0.0), sg * jm);
        ph.push(ap / jm, -sg * jm);
    } else {
        let dv_ramps = (am * am - a0m * a0m) / (2.0 * jm) + am * am / (2.0 * jm);
        ph.push(((am - a0m) / jm).max(0.0), sg * jm);
        ph.push(((dv - dv_ramps) / am).max(0.0), 0.0);
        ph.push(am / jm, -sg * jm);
    }
    ph
}

/// Duration and displacement of the rest-to-rest-shaped ramp 0 → vp ≥ 0 (or vp → 0):
/// symmetric, so the displacement is vp·T/2.
#[inline]
pub fn ramp_from_rest(vp: f64, lim: &Limits1) -> (f64, f64, f64) {
    let (t1, t2) = if vp * lim.j <= lim.a * lim.a {
        ((vp / lim.j).sqrt(), 0.0)
    } else {
        (lim.a / lim.j, vp / lim.a - lim.a / lim.j)
    };
    (t1, t2, vp * (2.0 * t1 + t2) * 0.5)
}
