//! The durations a stretched soft motion can take: Ruckig's blocked intervals, exact.
//!
//! The stretch family ([`super::stretch`], positive frame): velocity change
//! (v0, a0) → (vp, 0), cruise at vp, ramp vp → 0. With the zero-cruise distance
//! D(vp) = D1 + D2 and ramp time T12(vp) ([`zero_cruise`]), the member of peak velocity
//! vp exists iff D(vp) ≤ d, and takes T(vp) = T12 + (d − D)/vp. Each ramp satisfies
//! dD/dvp − vp·dT12/dvp = a_peak/(2J), so dT/dvp = −(d − D)/vp² − (a1 + a2)/(2J·vp) < 0:
//! T decreases on every interval of members. D(0) = p_b ≤ d (the brake point); D
//! rises, falls to a local minimum at the stop velocity m, then rises (above m both
//! ramps lengthen with vp; below m it is unimodal, checked by a unit test). So the
//! members form at most two intervals of peak velocity, [0, r1] and [r2, r3], with
//! D = d at r1, r2 and r3 (or r3 = vmax), and the family reaches the durations
//! [T(r3), T(r2)] ∪ [T(r1), ∞) (T(0) = ∞). "Stop, then a rest-to-rest move" reaches
//! every duration from G = T_stop + T_r2r(d − p_b) on. Whatever neither covers is
//! blocked: synchronisation moves T to the next reachable duration.

use super::velocity::{ramp, ramp_from_rest};
use super::{Kin, Limits1, newton_increasing, solve, stop_velocity};

/// Zero-cruise distance D(vp), its slope D'(vp) = vp·(T1' + T2') + (a1 + a2)/(2J), and
/// the ramps' duration T12(vp), for the family from (v, a) (positive frame).
#[inline]
pub(crate) fn zero_cruise(v: f64, a: f64, vp: f64, lim: &Limits1) -> (f64, f64, f64) {
    let r1 = ramp(v, a, vp, lim);
    let k = r1.integrate(Kin { p: 0.0, v, a });
    let (t1, t2, d2) = ramp_from_rest(vp, lim);
    let s1 = r1.j.signum();
    let dt1 = if r1.t[1] > 0.0 {
        s1 / lim.a
    } else {
        s1 / (r1.t[2] * lim.j)
    };
    // vp·T2' = vp/A with an amax hold, else vp/(J·t1) = t1 (finite at vp = 0).
    let vdt2 = if t2 > 0.0 { vp / lim.a } else { t1 };
    (
        k.p + d2,
        vp * dt1 + vdt2 + 0.5 * (r1.t[2] + t1),
        r1.duration() + 2.0 * t1 + t2,
    )
}

/// The reachable durations of one joint's stretch family plus "stop, then move".
#[derive(Debug, Clone, Copy)]
pub(crate) struct Reach {
    /// Peak-velocity intervals of the members, [lo, hi], in increasing vp.
    vp: [(f64, f64); 2],
    /// Their durations [T(hi), T(lo)] (T(0) = ∞).
    t: [(f64, f64); 2],
    n: usize,
    /// Every duration from here on is reachable (stop, then move).
    guaranteed: f64,
}

impl Reach {
    /// The intervals for the family from (v, a) to rest at d ≥ p_b (positive frame),
    /// given G (`guaranteed`).
    pub(crate) fn new(v: f64, a: f64, d: f64, lim: &Limits1, guaranteed: f64) -> Self {
        let dist = |vp: f64| zero_cruise(v, a, vp, lim);
        let ftol = 1e-14 * (1.0 + d.abs());
        // Root of D = d where D − d increases on [lo, hi] (or decreases: `up` false).
        let root = |lo: f64, hi: f64, up: bool| {
            let s = if up { 1.0 } else { -1.0 };
            newton_increasing(
                |vp| {
                    // D' is +∞ at m from above when a0 < 0: bisect there instead.
                    let (x, dx, _) = dist(vp);
                    (s * (x - d), if dx.is_finite() { s * dx } else { f64::NAN })
                },
                lo,
                hi,
                0.5 * (lo + hi),
                ftol,
            )
        };
        let vmax = lim.v;
        let m = stop_velocity(v, a, lim.j).clamp(0.0, vmax);
        // The top of D's hump on [0, m] (m itself when D rises all the way).
        let peak = if m > 0.0 && dist(m * (1.0 - 1e-12)).1 < 0.0 {
            solve(|vp| dist(vp).1, 0.0, m * (1.0 - 1e-12))
        } else {
            m
        };
        let upper = |lo: f64| {
            if dist(vmax).0 <= d {
                vmax
            } else {
                root(lo, vmax, true)
            }
        };
        let mut vp = [(0.0, 0.0); 2];
        let mut n = 0;
        if dist(peak).0 <= d {
            vp[0] = (0.0, upper(m));
            n = 1;
        } else {
            let r1 = root(0.0, peak, true);
            if r1 > 0.0 {
                vp[n] = (0.0, r1);
                n += 1;
            }
            if dist(m).0 <= d {
                let r2 = if peak < m { root(peak, m, false) } else { m };
                vp[n] = (r2, upper(m));
                n += 1;
            }
        }
        let duration = |x: f64| {
            if x <= 0.0 {
                return f64::INFINITY;
            }
            let (dd, _, t12) = dist(x);
            t12 + (d - dd).max(0.0) / x
        };
        let mut t = [(0.0, 0.0); 2];
        for k in 0..n {
            t[k] = (duration(vp[k].1), duration(vp[k].0));
        }
        Self {
            vp,
            t,
            n,
            guaranteed,
        }
    }

    /// The peak-velocity interval whose durations contain `t` (round-off tolerant),
    /// the faster (upper) one first.
    pub(crate) fn interval_of(&self, t: f64) -> Option<(f64, f64)> {
        let tol = 1e-12 * t.max(1.0);
        (0..self.n)
            .rev()
            .find(|&k| t >= self.t[k].0 - tol && t <= self.t[k].1 + tol)
            .map(|k| self.vp[k])
    }

    /// The smallest reachable duration ≥ `t`.
    pub(crate) fn next(&self, t: f64) -> f64 {
        let tol = 1e-12 * t.max(1.0);
        if t >= self.guaranteed - tol || self.interval_of(t).is_some() {
            return t;
        }
        (0..self.n)
            .map(|k| self.t[k].0)
            .filter(|&lo| lo > t)
            .fold(self.guaranteed, f64::min)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::soft::from_state::brake_point;
    use crate::soft::test_cases::{Lcg, random_moving_start};

    /// D is unimodal below the stop velocity and increasing above it, the shape the
    /// interval construction relies on (dense grid, random starts and limits).
    #[test]
    fn zero_cruise_distance_rises_falls_then_rises() {
        let mut r = Lcg(77);
        for n in 0..3000 {
            let (v, a, lim) = random_moving_start(&mut r);
            let m = stop_velocity(v, a, lim.j).clamp(0.0, lim.v);
            let xs: Vec<f64> = (0..=2000).map(|k| lim.v * k as f64 / 2000.0).collect();
            let ds: Vec<f64> = xs.iter().map(|&x| zero_cruise(v, a, x, &lim).0).collect();
            // Direction changes of D along the grid (ignoring round-off wiggles).
            let tol = 1e-13 * (1.0 + ds.iter().fold(0.0f64, |s, x| s.max(x.abs())));
            let mut dirs = Vec::new();
            for w in ds.windows(2) {
                let dd = w[1] - w[0];
                let s = if dd > tol {
                    1
                } else if dd < -tol {
                    -1
                } else {
                    continue;
                };
                if dirs.last() != Some(&s) {
                    dirs.push(s);
                }
            }
            assert!(
                dirs.len() <= 3 && dirs.first().is_none_or(|&s| s == 1),
                "case {n}: D changes direction {dirs:?} (m = {m})"
            );
            if dirs.len() == 3 {
                assert_eq!(dirs, [1, -1, 1], "case {n}");
            }
            for (k, &x) in xs.iter().enumerate().skip(1) {
                if x > m * (1.0 + 1e-9) && xs[k - 1] >= m {
                    assert!(ds[k] >= ds[k - 1] - tol, "case {n}: D falls above m at {x}");
                }
            }
        }
    }

    /// The intervals agree with a dense scan of the family: every sampled member's
    /// duration lies in the reachable set, and the interval ends are members with zero
    /// cruise (or vmax / 0).
    #[test]
    fn intervals_match_a_dense_scan() {
        let mut r = Lcg(3);
        let mut two = 0;
        for n in 0..3000 {
            let (v0, a0, lim) = random_moving_start(&mut r);
            let pb = brake_point(v0, a0, &lim);
            let d = pb + 3.0 * r.next() * r.next() * r.next();
            let reach = Reach::new(v0, a0, d, &lim, f64::INFINITY);
            two += usize::from(reach.n == 2);
            for k in 0..=4000 {
                let x = lim.v * k as f64 / 4000.0;
                let (dd, _, t12) = zero_cruise(v0, a0, x, &lim);
                let member = x > 0.0 && dd <= d;
                let inside = (0..reach.n).any(|i| x >= reach.vp[i].0 && x <= reach.vp[i].1);
                let margin = (0..reach.n)
                    .flat_map(|i| [reach.vp[i].0, reach.vp[i].1])
                    .fold(f64::INFINITY, |s, e| s.min((x - e).abs()));
                if margin > 1e-9 * lim.v {
                    assert_eq!(member, inside, "case {n}: vp {x} member {member}");
                }
                if member {
                    let t = t12 + (d - dd) / x;
                    assert!(
                        reach.interval_of(t).is_some(),
                        "case {n}: T({x}) = {t} not reachable: {reach:?}"
                    );
                }
            }
            for i in 0..reach.n {
                for e in [reach.vp[i].0, reach.vp[i].1] {
                    if e > 0.0 && e < lim.v {
                        let dd = zero_cruise(v0, a0, e, &lim).0;
                        assert!(
                            (dd - d).abs() <= 1e-10 * (1.0 + d.abs()),
                            "case {n}: D({e}) {dd} vs {d}"
                        );
                    }
                }
            }
        }
        assert!(two > 20, "only {two} cases with a blocked interval");
    }
}
