//! Soft motion stretched to a given duration T (for synchronisation and the seed's
//! 5/10/20/60 s comparisons), within the same limits.
//!
//! Family: velocity change (v0, a0) → (vp, 0), cruise at vp, symmetric ramp vp → 0.
//! For a given T the cruise takes what the ramps leave, and vp solves the distance
//! equation D1(vp) + vp·Tc + D2(vp) = d, a bracketed root. From rest, and whenever
//! the optimal motion's acceleration crosses zero at its velocity peak, the family's
//! fastest member *is* the time-optimal motion. Where the family has no member of
//! the requested duration, "stop, then a rest-to-rest move" covers every duration from
//! [`Stretch::guaranteed`] on; durations in between are reported as blocked (`None`),
//! and synchronisation moves on to a duration every joint reaches, as Ruckig's time
//! synchronisation does with its blocked intervals.

use super::from_state::brake_point;
use super::velocity::{ramp, ramp_from_rest, velocity_change};
use super::{Kin, Limits1, Phases, newton_increasing, rest_to_rest, solve_tol, stop_velocity};

/// Prepared stretch problem for one joint (positive frame).
#[derive(Debug, Clone, Copy)]
pub struct Stretch {
    sg: f64,
    v0: f64,
    a0: f64,
    d: f64,
    /// Upper anchor of the peak-velocity search (vmax, or the zero-cruise vp).
    vp_hi: f64,
    /// Duration of the fastest stop, and of the fastest rest-to-rest move from the
    /// stop point to the target: the fallback "stop, then move" needs their sum.
    t_stop: f64,
    t_r2r: f64,
    rest: bool,
}

impl Stretch {
    /// Prepares stretching the motion (v0, a0) → rest at displacement `d`.
    pub fn new(v0: f64, a0: f64, d: f64, lim: &Limits1) -> Self {
        Self::with_anchor(v0, a0, d, lim, None)
    }

    /// [`Stretch::new`] given the optimal motion's peak velocity (from
    /// [`super::from_state::time_optimal_peak`]), which saves a root search.
    pub fn with_anchor(v0: f64, a0: f64, d: f64, lim: &Limits1, anchor: Option<f64>) -> Self {
        if v0 == 0.0 && a0 == 0.0 {
            let t_r2r = rest_to_rest::time_optimal_duration(d.abs(), lim);
            return Self {
                sg: if d >= 0.0 { 1.0 } else { -1.0 },
                v0,
                a0,
                d: d.abs(),
                vp_hi: lim.v,
                t_stop: 0.0,
                t_r2r,
                rest: true,
            };
        }
        let pb = brake_point(v0, a0, lim);
        let sg = if d >= pb { 1.0 } else { -1.0 };
        let (v, a, dd) = (sg * v0, sg * a0, sg * d);
        let dist = |vp: f64| {
            let r1 = ramp(v, a, vp, lim);
            let k = r1.integrate(Kin { p: 0.0, v, a });
            let (_, _, d2) = ramp_from_rest(vp, lim);
            k.p + d2
        };
        let vp_hi = if let Some(vp) = anchor {
            vp.clamp(0.0, lim.v)
        } else if dd >= dist(lim.v) {
            lim.v
        } else {
            solve_tol(|vp| dist(vp) - dd, 0.0, lim.v, 1e-14 * (1.0 + dd.abs()))
        };
        Self {
            sg,
            v0: v,
            a0: a,
            d: dd,
            vp_hi,
            t_stop: ramp(v, a, 0.0, lim).duration(),
            t_r2r: rest_to_rest::time_optimal_duration((d - pb).abs(), lim),
            rest: false,
        }
    }

    /// A duration from which on every longer one is reachable (stop, then a
    /// rest-to-rest move); shorter ones down to the minimum usually are too.
    pub fn guaranteed(&self) -> f64 {
        self.t_stop + self.t_r2r
    }

    /// Phases (original frame) finishing at exactly `t`, or `None` when this family
    /// has no member of that duration (t below the minimum, or in a blocked interval).
    ///
    /// Search: f(vp) = D1 + D2 + vp·Tc − d on peak velocities where the cruise Tc ≥ 0,
    /// from the upper anchor down: first between the stop velocity and the anchor
    /// (where Tc is monotone), then on a 16-point grid; last resort "stop, then move".
    pub fn phases(&self, t: f64, lim: &Limits1) -> Option<Phases> {
        let mut ph = if self.rest {
            if t < self.t_r2r * (1.0 - 1e-12) {
                return None;
            }
            rest_to_rest::stretched(self.d, t, lim)
        } else {
            self.search(t, lim)
                .or_else(|| self.stop_then_move(t, lim))?
        };
        for p in &mut ph.p[..ph.n] {
            p.j *= self.sg;
        }
        Some(ph)
    }

    /// f(vp), its derivative and validity (cruise ≥ 0).
    ///
    /// f(vp) = D1 + D2 + vp·Tc − d with Tc = t − T1 − T2. Each ramp satisfies
    /// dD/dvp − vp·dT/dvp = a_peak/(2J) (a_peak its peak |acceleration|, with or
    /// without an amax phase, either direction), so f'(vp) = Tc + (a1 + a2)/(2J) > 0:
    /// f increases wherever the cruise is non-negative.
    #[inline]
    fn f(&self, vp: f64, t: f64, lim: &Limits1) -> (f64, f64, bool) {
        let (v, a) = (self.v0, self.a0);
        let r1 = ramp(v, a, vp, lim);
        let k = r1.integrate(Kin { p: 0.0, v, a });
        let (t1, t2, d2) = ramp_from_rest(vp, lim);
        let tc = t - r1.duration() - 2.0 * t1 - t2;
        // Round-off at the family's fastest member must not look infeasible.
        let tc = if tc > -1e-12 * t.max(1.0) {
            tc.max(0.0)
        } else {
            tc
        };
        // a1/(2J) = t[2]/2 (the ramp's last phase takes its peak to 0), a2/(2J) = t1/2.
        let df = tc + 0.5 * (r1.t[2] + t1);
        (k.p + d2 + vp * tc - self.d, df, tc >= 0.0)
    }

    fn search(&self, t: f64, lim: &Limits1) -> Option<Phases> {
        let u = self.vp_hi;
        let (fu, _, ok_u) = self.f(u, t, lim);
        let mut bracket = None;
        if ok_u && fu >= 0.0 {
            let m = stop_velocity(self.v0, self.a0, lim.j).clamp(0.0, u);
            let (fm, _, ok_m) = self.f(m, t, lim);
            if ok_m && fm <= 0.0 {
                bracket = Some(((m, fm), (u, fu)));
            }
        }
        if bracket.is_none() {
            const N: usize = 16;
            let mut prev: Option<(f64, f64)> = ok_u.then_some((u, fu));
            for k in (0..N).rev() {
                let x = u * k as f64 / N as f64;
                let (fx, _, ok) = self.f(x, t, lim);
                if !ok {
                    prev = None;
                    continue;
                }
                if let Some((xp, fp)) = prev
                    && fp >= 0.0
                    && fx <= 0.0
                {
                    bracket = Some(((x, fx), (xp, fp)));
                    break;
                }
                prev = Some((x, fx));
            }
        }
        let ((lo, flo), (hi, fhi)) = bracket?;
        // f increases on the valid part of the bracket; an invalid point (negative
        // cruise) counts as below the root, and its NaN slope makes Newton bisect.
        let vp = newton_increasing(
            |vp| {
                let (fx, df, ok) = self.f(vp, t, lim);
                if ok {
                    (fx, df)
                } else {
                    (-1.0 - self.d.abs(), f64::NAN)
                }
            },
            lo,
            hi,
            if fhi > flo {
                (lo * fhi - hi * flo) / (fhi - flo)
            } else {
                hi
            },
            1e-14 * (1.0 + self.d.abs()),
        );
        let (fx, _, ok) = self.f(vp, t, lim);
        if !ok || fx.abs() > 1e-9 * (1.0 + self.d.abs()) {
            return None;
        }
        let mut ph = velocity_change(self.v0, self.a0, vp, lim);
        let (t1, t2, _) = ramp_from_rest(vp, lim);
        ph.push((t - ph.duration() - 2.0 * t1 - t2).max(0.0), 0.0);
        ph.push(t1, -lim.j);
        ph.push(t2, 0.0);
        ph.push(t1, lim.j);
        Some(ph)
    }

    /// Fastest stop, then a rest-to-rest move taking the remaining time.
    fn stop_then_move(&self, t: f64, lim: &Limits1) -> Option<Phases> {
        if t < self.guaranteed() * (1.0 - 1e-12) {
            return None;
        }
        let stop = velocity_change(self.v0, self.a0, 0.0, lim);
        let pb = stop
            .integrate(Kin {
                p: 0.0,
                v: self.v0,
                a: self.a0,
            })
            .p;
        let mut ph = stop;
        let mv = rest_to_rest::stretched(
            (self.d - pb).abs(),
            (t - stop.duration()).max(self.t_r2r),
            lim,
        );
        let s = if self.d >= pb { 1.0 } else { -1.0 };
        for p in &mv.p[..mv.n] {
            ph.push(p.t, s * p.j);
        }
        Some(ph)
    }
}
