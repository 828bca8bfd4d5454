//! Soft motion: time-optimal jerk-limited single-joint profiles (seed section 3.2.4).
//!
//! Every profile here is a list of constant-jerk phases with |jerk| = jmax or 0, built
//! from one primitive, the time-optimal *velocity change* (v0, a0) → (vf, 0)
//! ([`velocity::velocity_change`]):
//!
//! * [`rest_to_rest`]: the seed's closed form (cases 1–3 and vmax < amax²/jmax).
//! * [`from_state`]: from any (q, v, a) to a target at rest. A *push* of τ seconds at
//!   +jmax (holding +amax once reached) followed by the velocity change to rest; τ is
//!   found by bracketed root finding on the end position, or the push reaches vmax and
//!   a cruise phase absorbs the remaining distance. This family contains Ruckig's
//!   UDDU/UDUD profiles for rest targets, including those whose acceleration never
//!   crosses zero in the interior.
//! * [`brake`]: when |v0 + a0|a0|/(2 jmax)| > vmax the velocity limit will be crossed
//!   whatever the jerk, so a brake pre-phase (−jmax, then −amax) first brings the
//!   motion back under vmax, as Ruckig's velocity brake does.
//! * [`stretch`]: the same motion finishing exactly at a longer duration T: ramp to a
//!   lower peak velocity vp, cruise, ramp down; vp solves the distance equation.
//!   `reach` gives the exact set of durations it (or "stop, then move") can take;
//!   `free` reaches most of the rest with profiles without a cruise (Ruckig's step 2).

pub mod brake;
pub(crate) mod free;
pub mod from_state;
mod reach;
pub mod rest_to_rest;
pub mod stretch;
pub mod velocity;

pub use crate::piecewise::{Kin, Phase, Phases};

/// Limits of one joint for soft motion (all > 0, finite).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Limits1 {
    /// vmax (rad/s).
    pub v: f64,
    /// amax (rad/s²).
    pub a: f64,
    /// jmax (rad/s³).
    pub j: f64,
}

/// Stop-velocity: the velocity reached when the acceleration is brought to zero as
/// fast as the jerk limit allows, v + a|a|/(2 jmax).
#[inline]
pub fn stop_velocity(v: f64, a: f64, j: f64) -> f64 {
    v + a * a.abs() / (2.0 * j)
}

/// Root of an increasing function on the bracket [lo, hi] (f(lo) ≤ 0 ≤ f(hi)) by
/// Newton's method from `x0`, with `f` returning the value and the exact derivative.
/// Safeguarded (see [`safeguarded_root`]): quadratic near a simple root, bisection at
/// worst.
#[inline]
pub(crate) fn newton_increasing(
    mut f: impl FnMut(f64) -> (f64, f64),
    lo: f64,
    hi: f64,
    x0: f64,
    ftol: f64,
) -> f64 {
    safeguarded_root(
        |x| {
            let (fx, dfx) = f(x);
            (fx, -fx / dfx)
        },
        lo,
        hi,
        x0,
        ftol,
    )
}

/// [`newton_increasing`] with the second derivative too (`f` returns f, f', f''):
/// each step goes to the root of the local quadratic model nearest x (cubically
/// convergent; exact for a quadratic f), a Newton step where the model has no real
/// root, a bisection where the step would leave the bracket.
#[inline]
pub(crate) fn model_root_increasing(
    mut f: impl FnMut(f64) -> (f64, f64, f64),
    lo: f64,
    hi: f64,
    x0: f64,
    ftol: f64,
) -> f64 {
    safeguarded_root(
        |x| {
            let (fx, dfx, ddfx) = f(x);
            let disc = dfx * dfx - 2.0 * fx * ddfx;
            let step = -2.0 * fx / (dfx + dfx.signum() * disc.sqrt());
            let step = if ddfx.is_finite() && disc >= 0.0 && step.is_finite() {
                step
            } else {
                -fx / dfx
            };
            (fx, step)
        },
        lo,
        hi,
        x0,
        ftol,
    )
}

/// The bracketing loop both root finders share: `f(x)` returns f(x) and the step its
/// local model proposes. Every evaluation shrinks the bracket [lo, hi] (f increasing),
/// a step that would leave it (or a non-finite one) bisects instead. Stops once
/// |f| ≤ `ftol` (the caller's round-off level of f) or a step falls below a few ulps
/// of the bracket's scale.
#[inline(always)]
fn safeguarded_root(
    mut f: impl FnMut(f64) -> (f64, f64),
    mut lo: f64,
    mut hi: f64,
    x0: f64,
    ftol: f64,
) -> f64 {
    let tiny = 4.0 * f64::EPSILON * lo.abs().max(hi.abs()).max(f64::MIN_POSITIVE);
    let mut x = if x0 > lo && x0 < hi {
        x0
    } else {
        0.5 * (lo + hi)
    };
    for _ in 0..100 {
        let (fx, step) = f(x);
        if fx.abs() <= ftol {
            return x;
        }
        if fx < 0.0 {
            lo = x;
        } else {
            hi = x;
        }
        let mut xn = x + step;
        if !(xn >= lo && xn <= hi) {
            xn = 0.5 * (lo + hi);
        }
        if (xn - x).abs() <= tiny || hi - lo <= tiny {
            return xn;
        }
        x = xn;
    }
    x
}

/// Bracketed root of `f` on [lo, hi] (Illinois variant of regula falsi), assuming
/// f(lo) ≤ 0 ≤ f(hi) or the reverse. Returns the best point after convergence to
/// machine precision or 200 iterations.
pub(crate) fn solve(f: impl FnMut(f64) -> f64, lo: f64, hi: f64) -> f64 {
    solve_tol(f, lo, hi, 0.0)
}

/// [`solve`], also stopping once |f| ≤ `ftol`.
pub(crate) fn solve_tol(mut f: impl FnMut(f64) -> f64, lo: f64, hi: f64, ftol: f64) -> f64 {
    let (flo, fhi) = (f(lo), f(hi));
    solve_known(f, (lo, flo), (hi, fhi), ftol)
}

/// [`solve_tol`] given f at both ends of the bracket (saves two evaluations when
/// the caller has them already).
pub(crate) fn solve_known(
    mut f: impl FnMut(f64) -> f64,
    (mut lo, mut flo): (f64, f64),
    (mut hi, mut fhi): (f64, f64),
    ftol: f64,
) -> f64 {
    if flo == 0.0 {
        return lo;
    }
    if fhi == 0.0 {
        return hi;
    }
    if flo.signum() == fhi.signum() {
        return if flo.abs() < fhi.abs() { lo } else { hi };
    }
    let mut side = 0i8;
    let mut width = hi - lo;
    for it in 0..200 {
        // Illinois steps, with a bisection whenever three of them failed to halve
        // the bracket (flat stretches and kinks of piecewise profiles).
        let mut x = if it % 3 == 2 && hi - lo > 0.5 * width {
            0.5 * (lo + hi)
        } else {
            (lo * fhi - hi * flo) / (fhi - flo)
        };
        if it % 3 == 2 {
            width = hi - lo;
        }
        if !(x > lo && x < hi) {
            x = 0.5 * (lo + hi);
        }
        let fx = f(x);
        if fx.abs() <= ftol {
            return x;
        }
        if fx.signum() == flo.signum() {
            lo = x;
            flo = fx;
            if side == -1 {
                fhi *= 0.5;
            }
            side = -1;
        } else {
            hi = x;
            fhi = fx;
            if side == 1 {
                flo *= 0.5;
            }
            side = 1;
        }
        if hi - lo <= 4.0 * f64::EPSILON * hi.abs().max(lo.abs()).max(f64::MIN_POSITIVE) {
            break;
        }
    }
    if flo.abs() < fhi.abs() { lo } else { hi }
}

/// Random cases shared by the solvers' unit tests.
#[cfg(test)]
pub(crate) mod test_cases {
    use super::Limits1;

    /// Deterministic pseudo-random numbers in [0, 1).
    pub(crate) struct Lcg(pub u64);

    impl Lcg {
        pub(crate) fn next(&mut self) -> f64 {
            self.0 = self
                .0
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (self.0 >> 11) as f64 / (1u64 << 53) as f64
        }
    }

    /// Random limits and a moving start (v0, a0) inside them that needs no brake:
    /// |a0| within amax and √(4·jmax·vmax), the stop velocity within ±vmax.
    pub(crate) fn random_moving_start(r: &mut Lcg) -> (f64, f64, Limits1) {
        let lim = Limits1 {
            v: 0.2 + 5.0 * r.next(),
            a: 0.2 + 5.0 * r.next(),
            j: 0.2 + 20.0 * r.next(),
        };
        let a0 = (2.0 * r.next() - 1.0) * lim.a.min(0.99 * (4.0 * lim.j * lim.v).sqrt());
        let s = a0 * a0.abs() / (2.0 * lim.j);
        let (lo, hi) = ((-lim.v).max(-lim.v - s), lim.v.min(lim.v - s));
        let v0 = lo + r.next() * (hi - lo) * 0.999;
        (v0, a0, lim)
    }
}
