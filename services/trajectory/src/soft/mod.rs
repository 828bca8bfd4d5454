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
//!   motion back under vmax, as Ruckig does.
//! * [`stretch`]: the same motion finishing exactly at a longer duration T: ramp to a
//!   lower peak velocity vp, cruise, ramp down; vp solves the distance equation.

pub mod brake;
pub mod from_state;
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
    lo: (f64, f64),
    hi: (f64, f64),
    ftol: f64,
) -> f64 {
    let mut s = Illinois::new(lo, hi, ftol);
    loop {
        if let Some(x) = s.result {
            return x;
        }
        let x = s.propose();
        s.accept(x, f(x));
    }
}

/// Several independent [`solve_known`] searches in lockstep: each round proposes a
/// point for every unfinished search, then evaluates them one after another. The
/// evaluations do not depend on each other, so the CPU overlaps their long serial
/// chains (one search alone is latency-bound). Results are bit-identical to
/// [`solve_known`]; `f(k, x)` evaluates search `k` at `x`.
pub(crate) fn solve_many(searches: &mut [Illinois], mut f: impl FnMut(usize, f64) -> f64) {
    const CAP: usize = crate::MAX_JOINTS;
    let m = searches.len().min(CAP);
    let searches = &mut searches[..m];
    loop {
        let mut xs = [f64::NAN; CAP];
        let mut any = false;
        for (k, s) in searches.iter_mut().enumerate() {
            if s.result.is_none() {
                xs[k] = s.propose();
                any = true;
            }
        }
        if !any {
            return;
        }
        let mut fs = [0.0; CAP];
        for k in 0..m {
            if !xs[k].is_nan() {
                fs[k] = f(k, xs[k]);
            }
        }
        for (k, s) in searches.iter_mut().enumerate() {
            if !xs[k].is_nan() {
                s.accept(xs[k], fs[k]);
            }
        }
    }
}

/// State of one bracketed root search (Illinois variant of regula falsi with a
/// bisection whenever three steps failed to halve the bracket — flat stretches and
/// kinks of piecewise profiles). Converges to machine precision, to |f| ≤ `ftol`, or
/// stops after 200 steps; `result` is then set.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Illinois {
    lo: f64,
    flo: f64,
    hi: f64,
    fhi: f64,
    side: i8,
    width: f64,
    it: u32,
    ftol: f64,
    /// The root, once the search has finished.
    pub result: Option<f64>,
}

impl Illinois {
    /// A search on [lo.0, hi.0] given f there (lo.1, hi.1).
    pub fn new((lo, flo): (f64, f64), (hi, fhi): (f64, f64), ftol: f64) -> Self {
        let result = if flo == 0.0 {
            Some(lo)
        } else if fhi == 0.0 {
            Some(hi)
        } else if flo.signum() == fhi.signum() {
            Some(if flo.abs() < fhi.abs() { lo } else { hi })
        } else {
            None
        };
        Self {
            lo,
            flo,
            hi,
            fhi,
            side: 0,
            width: hi - lo,
            it: 0,
            ftol,
            result,
        }
    }

    /// A finished search with result `x` (nothing left to solve).
    pub fn done(x: f64) -> Self {
        let mut s = Self::new((x, 0.0), (x, 0.0), 0.0);
        s.result = Some(x);
        s
    }

    /// The next point to evaluate.
    #[inline]
    pub fn propose(&mut self) -> f64 {
        let (lo, hi) = (self.lo, self.hi);
        let bisect = self.it % 3 == 2;
        let mut x = if bisect && hi - lo > 0.5 * self.width {
            0.5 * (lo + hi)
        } else {
            (lo * self.fhi - hi * self.flo) / (self.fhi - self.flo)
        };
        if bisect {
            self.width = hi - lo;
        }
        if !(x > lo && x < hi) {
            x = 0.5 * (lo + hi);
        }
        x
    }

    /// Takes f(x) for the point `x` from [`Illinois::propose`].
    #[inline]
    pub fn accept(&mut self, x: f64, fx: f64) {
        self.it += 1;
        if fx.abs() <= self.ftol {
            self.result = Some(x);
            return;
        }
        if fx.signum() == self.flo.signum() {
            self.lo = x;
            self.flo = fx;
            if self.side == -1 {
                self.fhi *= 0.5;
            }
            self.side = -1;
        } else {
            self.hi = x;
            self.fhi = fx;
            if self.side == 1 {
                self.flo *= 0.5;
            }
            self.side = 1;
        }
        let (lo, hi) = (self.lo, self.hi);
        if hi - lo <= 4.0 * f64::EPSILON * hi.abs().max(lo.abs()).max(f64::MIN_POSITIVE)
            || self.it >= 200
        {
            self.result = Some(if self.flo.abs() < self.fhi.abs() {
                lo
            } else {
                hi
            });
        }
    }
}
