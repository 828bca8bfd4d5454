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
    /// Brake point (positive frame): where the fastest stop ends.
    pb: f64,
    /// From rest: the time-optimal duration (nothing shorter is reachable).
    t_r2r: f64,
    rest: bool,
    lim: Limits1,
}

impl Stretch {
    /// Prepares stretching the motion (v0, a0) → rest at displacement `d`.
    pub fn new(v0: f64, a0: f64, d: f64, lim: &Limits1) -> Self {
        Self::with_anchor(v0, a0, d, lim, None)
    }

    /// [`Stretch::new`] given the optimal motion's peak velocity (from
    /// [`super::from_state::time_optimal_peak`]), which saves a root search.
    pub fn with_anchor(v0: f64, a0: f64, d: f64, lim: &Limits1, anchor: Option<f64>) -> Self {
        let pb = if v0 == 0.0 && a0 == 0.0 {
            0.0
        } else {
            brake_point(v0, a0, lim)
        };
        Self::prepared(v0, a0, d, lim, anchor, pb)
    }

    /// [`Stretch::with_anchor`] given the brake point `pb` of (v0, a0) as well.
    pub(crate) fn prepared(
        v0: f64,
        a0: f64,
        d: f64,
        lim: &Limits1,
        anchor: Option<f64>,
        pb: f64,
    ) -> Self {
        if v0 == 0.0 && a0 == 0.0 {
            let t_r2r = rest_to_rest::time_optimal_duration(d.abs(), lim);
            return Self {
                sg: if d >= 0.0 { 1.0 } else { -1.0 },
                v0,
                a0,
                d: d.abs(),
                vp_hi: lim.v,
                pb: 0.0,
                t_r2r,
                rest: true,
                lim: *lim,
            };
        }
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
            pb: sg * pb,
            t_r2r: 0.0,
            rest: false,
            lim: *lim,
        }
    }

    /// A duration from which on every longer one is reachable (stop, then a
    /// rest-to-rest move); shorter ones down to the minimum usually are too.
    /// (Computed on demand: only synchronisation past a blocked duration needs it.)
    pub fn guaranteed(&self) -> f64 {
        if self.rest {
            return self.t_r2r;
        }
        let lim = &self.lim;
        ramp(self.v0, self.a0, 0.0, lim).duration()
            + rest_to_rest::time_optimal_duration((self.d - self.pb).abs(), lim)
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
        let (fu, dfu, ok_u) = self.f(u, t, lim);
        let mut vp = None;
        if ok_u && fu >= 0.0 {
            // Above the stop velocity T1 + T2 grows with vp, so [m, u] is all valid
            // and f increases on it: Newton from the top, f(m) only looked at when a
            // step falls below m.
            let m = stop_velocity(self.v0, self.a0, lim.j).clamp(0.0, u);
            vp = self.newton_from_top(m, (u, fu, dfu), t, lim);
        }
        if vp.is_none() {
            vp = self.grid_search(u, (fu, ok_u), t, lim);
        }
        let vp = vp?;
        let mut ph = velocity_change(self.v0, self.a0, vp, lim);
        let (t1, t2, _) = ramp_from_rest(vp, lim);
        ph.push((t - ph.duration() - 2.0 * t1 - t2).max(0.0), 0.0);
        ph.push(t1, -lim.j);
        ph.push(t2, 0.0);
        ph.push(t1, lim.j);
        Some(ph)
    }

    /// Root of f on [m, u] by safeguarded Newton steps from u (f(u) ≥ 0 given, with
    /// its slope); `None` when f(m) > 0 (the root, if any, lies below m).
    fn newton_from_top(
        &self,
        m: f64,
        (u, fu, dfu): (f64, f64, f64),
        t: f64,
        lim: &Limits1,
    ) -> Option<f64> {
        let ftol = 1e-14 * (1.0 + self.d.abs());
        let tiny = 4.0 * f64::EPSILON * u.abs().max(f64::MIN_POSITIVE);
        let (mut lo, mut hi, mut lo_checked) = (m, u, false);
        let (mut x, mut fx, mut dfx) = (u, fu, dfu);
        for _ in 0..100 {
            if fx.abs() <= ftol {
                return Some(x);
            }
            if fx < 0.0 {
                (lo, lo_checked) = (x, true);
            } else {
                hi = x;
            }
            let mut xn = x - fx / dfx;
            if !(xn >= lo && xn <= hi) {
                if !lo_checked {
                    let (fm, _, ok_m) = self.f(m, t, lim);
                    if !ok_m || fm > 0.0 {
                        return None;
                    }
                    lo_checked = true;
                }
                xn = 0.5 * (lo + hi);
            }
            if (xn - x).abs() <= tiny || hi - lo <= tiny {
                let (f_end, _, ok) = self.f(xn, t, lim);
                return (ok && f_end.abs() <= 1e-9 * (1.0 + self.d.abs())).then_some(xn);
            }
            let (f2, df2, ok) = self.f(xn, t, lim);
            (x, fx, dfx) = if ok {
                (xn, f2, df2)
            } else {
                (xn, -1.0 - self.d.abs(), f64::NAN)
            };
        }
        None
    }

    /// Fallback: a 16-point grid from u down to 0 for a sign change between two valid
    /// points, then safeguarded Newton inside it.
    fn grid_search(&self, u: f64, (fu, ok_u): (f64, bool), t: f64, lim: &Limits1) -> Option<f64> {
        const N: usize = 16;
        let mut bracket = None;
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
        (ok && fx.abs() <= 1e-9 * (1.0 + self.d.abs())).then_some(vp)
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
            (t - stop.duration()).max(rest_to_rest::time_optimal_duration(
                (self.d - pb).abs(),
                lim,
            )),
            lim,
        );
        let s = if self.d >= pb { 1.0 } else { -1.0 };
        for p in &mv.p[..mv.n] {
            ph.push(p.t, s * p.j);
        }
        Some(ph)
    }
}
