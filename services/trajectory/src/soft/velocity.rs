//! The time-optimal jerk-limited velocity change (v0, a0) → (vf, 0), the building block
//! of every soft-motion profile.

use super::{Kin, Limits1, Phases, stop_velocity};

/// A velocity change as three phases: jerk `j` for `t[0]`, 0 for `t[1]`, −`j` for `t[2]`.
/// Plain scalars, so root searches evaluate it without building phase lists.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Ramp {
    /// Phase durations.
    pub t: [f64; 3],
    /// Jerk of the first phase (±jmax).
    pub j: f64,
}

impl Ramp {
    /// State after the ramp.
    #[inline]
    pub fn integrate(&self, k: Kin) -> Kin {
        k.advance(self.t[0], self.j)
            .advance(self.t[1], 0.0)
            .advance(self.t[2], -self.j)
    }
    /// Total duration.
    #[inline]
    pub fn duration(&self) -> f64 {
        self.t[0] + self.t[1] + self.t[2]
    }
    /// Appends the ramp's phases.
    #[inline]
    pub fn push_to(&self, ph: &mut Phases) {
        ph.push(self.t[0], self.j);
        ph.push(self.t[1], 0.0);
        ph.push(self.t[2], -self.j);
    }
}

/// The fastest change from (v0, a0) to velocity `vf` at zero acceleration with
/// |a| ≤ amax, |jerk| ≤ jmax: jerk ±jmax up to a peak acceleration, an optional hold
/// at ±amax, jerk ∓jmax back to zero. Expects |a0| ≤ amax.
#[inline]
pub fn ramp(v0: f64, a0: f64, vf: f64, lim: &Limits1) -> Ramp {
    let (jm, am) = (lim.j, lim.a);
    let sg = if vf >= stop_velocity(v0, a0, jm) {
        1.0
    } else {
        -1.0
    };
    let (a0m, dv) = (sg * a0, sg * (vf - v0));
    let ap = (jm * dv + 0.5 * a0m * a0m).max(0.0).sqrt();
    let ij = 1.0 / jm;
    let t = if ap <= am {
        [((ap - a0m) * ij).max(0.0), 0.0, ap * ij]
    } else {
        let dv_ramps = (am * am - 0.5 * a0m * a0m) * ij;
        [
            ((am - a0m) * ij).max(0.0),
            ((dv - dv_ramps) / am).max(0.0),
            am * ij,
        ]
    };
    Ramp { t, j: sg * jm }
}

/// [`ramp`] as a phase list.
#[inline]
pub fn velocity_change(v0: f64, a0: f64, vf: f64, lim: &Limits1) -> Phases {
    let mut ph = Phases::default();
    ramp(v0, a0, vf, lim).push_to(&mut ph);
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
