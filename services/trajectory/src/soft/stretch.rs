//! Soft motion stretched to a given duration T (for synchronisation and the seed's
//! 5/10/20/60 s comparisons), within the same limits.
//!
//! Family: velocity change (v0, a0) → (vp, 0), cruise at vp, symmetric ramp vp → 0.
//! For a given T the cruise takes what the ramps leave, and vp solves the distance
//! equation D1(vp) + vp·Tc + D2(vp) = d, a bracketed root. From rest, and whenever
//! the optimal motion's acceleration crosses zero at its velocity peak, the family's
//! fastest member *is* the time-optimal motion. "Stop, then a rest-to-rest move"
//! covers every duration from [`Stretch::guaranteed`] on. Durations neither reaches
//! (blocked intervals, exact: `super::reach`) are tried with the profiles without a
//! cruise of `super::free`; what those miss too is reported as `None`, and
//! [`Stretch::next_reachable`] names the end of the blocked interval, where
//! synchronisation moves on to, as Ruckig's time synchronisation does.

use super::free;
use super::from_state::brake_point;
use super::reach::{Reach, zero_cruise};
use super::velocity::{ramp, ramp_from_rest, velocity_change};
use super::{Kin, Limits1, Phases, newton_increasing, rest_to_rest, stop_velocity};

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
        // Zero-cruise distance D(vp) = D1 + D2 and its slope (see [`zero_cruise`]).
        let dist = |vp: f64| {
            let (x, dx, _) = zero_cruise(v, a, vp, lim);
            (x, dx)
        };
        let vp_hi = if let Some(vp) = anchor {
            vp.clamp(0.0, lim.v)
        } else if dd >= dist(lim.v).0 {
            lim.v
        } else {
            // D increases above the stop velocity m: the largest root lies there when
            // D(m) ≤ d; otherwise take a root below m (D may rise and fall there).
            let m = stop_velocity(v, a, lim.j).clamp(0.0, lim.v);
            let (lo, hi) = if dist(m).0 <= dd {
                (m, lim.v)
            } else {
                (0.0, m)
            };
            newton_increasing(
                |vp| {
                    let (x, dx) = dist(vp);
                    (x - dd, dx)
                },
                lo,
                hi,
                0.5 * (lo + hi),
                1e-14 * (1.0 + dd.abs()),
            )
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

    /// The smallest duration ≥ `t` that the stretch family reaches: `t` itself unless
    /// it lies in a blocked interval, else that interval's end (see `super::reach`).
    /// [`Stretch::phases`] may reach more (through `free`); synchronisation asks
    /// this only where `phases` found nothing, and raises T to it.
    pub fn next_reachable(&self, t: f64) -> f64 {
        if self.rest {
            return t.max(self.t_r2r);
        }
        self.reach().next(t)
    }

    /// The exact reachable durations (computed on demand: a few root searches).
    fn reach(&self) -> Reach {
        Reach::new(self.v0, self.a0, self.d, &self.lim, self.guaranteed())
    }

    /// Phases (original frame) finishing at exactly `t`, or `None` when no profile
    /// does (t below the minimum, or in a blocked interval that `free` — profiles
    /// without a cruise — cannot take either).
    ///
    /// Search: f(vp) = D1 + D2 + vp·Tc − d on peak velocities where the cruise Tc ≥ 0,
    /// from the upper anchor down between the stop velocity and the anchor (where Tc
    /// is monotone); when that finds nothing, on the exact member interval whose
    /// durations hold t (`super::reach`); last resort "stop, then move".
    pub fn phases(&self, t: f64, lim: &Limits1) -> Option<Phases> {
        let mut ph = if self.rest {
            if t < self.t_r2r * (1.0 - 1e-12) {
                return None;
            }
            rest_to_rest::stretched(self.d, t, lim)
        } else {
            self.search(t, lim)
                .or_else(|| self.stop_then_move(t, lim))
                .or_else(|| free::phases(self.v0, self.a0, self.d, t, lim))?
        };
        for p in &mut ph.p[..ph.n] {
            p.j *= self.sg;
        }
        Some(ph)
    }

    /// f(vp), its first two derivatives and validity (cruise ≥ 0).
    ///
    /// f(vp) = D1 + D2 + vp·Tc − d with Tc = t − T1 − T2. Each ramp satisfies
    /// dD/dvp − vp·dT/dvp = a_peak/(2J) (a_peak its peak |acceleration|, with or
    /// without an amax phase, either direction), so f'(vp) = Tc + (a1 + a2)/(2J) > 0:
    /// f increases wherever the cruise is non-negative. Differentiating once more,
    /// each ramp adds −(dT/dvp − da_peak/dvp/(2J)): −s/A with an amax phase, else
    /// −3s/(4 a_peak) (s = ±1, the sign of its velocity change). Where both ramps hold
    /// amax, f is exactly quadratic (linear when the first ramp slows down).
    #[inline]
    fn eval(&self, vp: f64, t: f64, lim: &Limits1) -> Eval {
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
        let s1 = r1.j.signum();
        let k1 = if r1.t[1] > 0.0 {
            1.0 / lim.a
        } else {
            0.75 / (r1.t[2] * lim.j)
        };
        let k2 = if t2 > 0.0 {
            1.0 / lim.a
        } else {
            0.75 / (t1 * lim.j)
        };
        Eval {
            x: vp,
            f: k.p + d2 + vp * tc - self.d,
            df,
            ddf: -(s1 * k1 + k2),
            ok: tc >= 0.0,
        }
    }

    /// Root of f on [lo, top.x], given f(top.x) ≥ 0, by safeguarded steps to the root
    /// of the local quadratic model (exact where both ramps hold amax, cubically
    /// convergent elsewhere; Newton where the model has no real root). f(lo) is only
    /// evaluated when a step falls below lo. Invalid points (negative cruise) count
    /// as below the root.
    fn descend(&self, lo0: f64, top: Eval, t: f64, lim: &Limits1) -> Descent {
        let ftol = 1e-14 * (1.0 + self.d.abs());
        let tiny = 4.0 * f64::EPSILON * top.x.abs().max(f64::MIN_POSITIVE);
        let (mut lo, mut hi, mut lo_checked) = (lo0, top.x, false);
        let mut e = top;
        for _ in 0..100 {
            if e.ok && e.f.abs() <= ftol {
                return Descent::Root(e.x);
            }
            if !e.ok || e.f < 0.0 {
                (lo, lo_checked) = (e.x, true);
            } else {
                hi = e.x;
            }
            let mut xn = if e.ok { e.x + model_step(&e) } else { f64::NAN };
            if !(xn >= lo && xn <= hi) {
                if !lo_checked {
                    let el = self.eval(lo0, t, lim);
                    if el.ok && el.f > ftol {
                        return Descent::LowPositive(el);
                    }
                    if el.ok && el.f.abs() <= ftol {
                        return Descent::Root(lo0);
                    }
                    lo_checked = true;
                }
                xn = 0.5 * (lo + hi);
            }
            if (xn - e.x).abs() <= tiny || hi - lo <= tiny {
                let en = self.eval(xn, t, lim);
                return if en.ok && en.f.abs() <= 1e-9 * (1.0 + self.d.abs()) {
                    Descent::Root(xn)
                } else {
                    Descent::Fail
                };
            }
            e = self.eval(xn, t, lim);
        }
        Descent::Fail
    }

    fn search(&self, t: f64, lim: &Limits1) -> Option<Phases> {
        let vp = self.peak_velocity(t, lim)?;
        let mut ph = velocity_change(self.v0, self.a0, vp, lim);
        let (t1, t2, _) = ramp_from_rest(vp, lim);
        ph.push((t - ph.duration() - 2.0 * t1 - t2).max(0.0), 0.0);
        ph.push(t1, -lim.j);
        ph.push(t2, 0.0);
        ph.push(t1, lim.j);
        Some(ph)
    }

    /// The cruise velocity of the family member of duration `t`, if there is one.
    fn peak_velocity(&self, t: f64, lim: &Limits1) -> Option<f64> {
        let u = self.vp_hi;
        let top = self.eval(u, t, lim);
        let mut vp = None;
        if top.ok && top.f >= 0.0 {
            // Above the stop velocity m, T1 + T2 grows with vp, so [m, u] is all valid
            // and f increases on it. When f(m) > 0 the root lies below m, on the valid
            // stretch that ends at m (the first ramp then slows down to vp).
            let m = stop_velocity(self.v0, self.a0, lim.j).clamp(0.0, u);
            vp = match self.descend(m, top, t, lim) {
                Descent::Root(x) => Some(x),
                Descent::LowPositive(em) if m > 0.0 => match self.descend(0.0, em, t, lim) {
                    Descent::Root(x) => Some(x),
                    _ => None,
                },
                _ => None,
            };
        }
        if vp.is_none() {
            vp = self.interval_search(t, lim);
        }
        vp
    }

    /// Fallback: the root of f on the exact member interval [l, u] whose durations
    /// hold `t` (f increases there, f(l) ≤ 0 ≤ f(u)).
    fn interval_search(&self, t: f64, lim: &Limits1) -> Option<f64> {
        let (l, u) = self.reach().interval_of(t)?;
        match self.descend(l, self.eval(u, t, lim), t, lim) {
            Descent::Root(x) => Some(x),
            _ => None,
        }
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

/// f and its derivatives at one peak velocity (see [`Stretch::eval`]).
#[derive(Debug, Clone, Copy)]
struct Eval {
    x: f64,
    f: f64,
    df: f64,
    ddf: f64,
    /// Cruise ≥ 0: the point belongs to the family.
    ok: bool,
}

/// How a descent ended.
enum Descent {
    Root(f64),
    /// f(lo) > 0: the root, if any, lies below lo.
    LowPositive(Eval),
    Fail,
}

/// Scans a 16-point grid from `u` (where f = `fu`, valid if `ok_u`) down to 0 for the
/// first sign change (f ≥ 0 above, ≤ 0 below) between two neighbouring valid points;
/// `g(x)` returns f(x) and whether x is valid. Returns the bracket ((lo, f(lo)),
/// (hi, f(hi))). The old fallback search, kept for the tests' bracketing oracle (the
/// exact member intervals of `super::reach` replaced it).
#[cfg(test)]
fn grid_bracket(
    u: f64,
    (fu, ok_u): (f64, bool),
    mut g: impl FnMut(f64) -> (f64, bool),
) -> Option<((f64, f64), (f64, f64))> {
    const N: usize = 16;
    let mut prev = ok_u.then_some((u, fu));
    for k in (0..N).rev() {
        let x = u * k as f64 / N as f64;
        let (fx, ok) = g(x);
        if !ok {
            prev = None;
            continue;
        }
        if let Some((xp, fp)) = prev
            && fp >= 0.0
            && fx <= 0.0
        {
            return Some(((x, fx), (xp, fp)));
        }
        prev = Some((x, fx));
    }
    None
}

/// Step to the root of f + f'·δ + f''·δ²/2 nearest δ = 0 (the stable form of the
/// quadratic formula); a Newton step when that has no real root.
#[inline]
fn model_step(e: &Eval) -> f64 {
    let disc = e.df * e.df - 2.0 * e.f * e.ddf;
    let q = e.df + disc.sqrt();
    let step = -2.0 * e.f / q;
    // An infinite curvature (a ramp whose peak acceleration is 0 here) gives no step.
    if e.ddf.is_finite() && disc >= 0.0 && step.is_finite() {
        step
    } else {
        -e.f / e.df
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::soft::test_cases::{Lcg, random_moving_start};
    use crate::soft::{from_state, solve_known};

    /// Random start inside the limits (no brake needed) and target.
    fn case(r: &mut Lcg) -> (f64, f64, f64, Limits1) {
        let (v0, a0, lim) = random_moving_start(r);
        let d = (2.0 * r.next() - 1.0) * 3.0;
        (v0, a0, d, lim)
    }

    /// The old search, kept as the oracle: from the anchor down, bracket [m, u] or a
    /// 16-point grid, then Illinois regula falsi.
    fn vp_by_bracketing(st: &Stretch, t: f64, lim: &Limits1) -> Option<f64> {
        let g = |vp: f64| {
            let e = st.eval(vp, t, lim);
            (e.f, e.ok)
        };
        let u = st.vp_hi;
        let (fu, ok_u) = g(u);
        let mut bracket = None;
        if ok_u && fu >= 0.0 {
            let m = stop_velocity(st.v0, st.a0, lim.j).clamp(0.0, u);
            let (fm, ok_m) = g(m);
            if ok_m && fm <= 0.0 {
                bracket = Some(((m, fm), (u, fu)));
            }
        }
        if bracket.is_none() {
            bracket = grid_bracket(u, (fu, ok_u), g);
        }
        let (lo, hi) = bracket?;
        let vp = solve_known(
            |vp| {
                let (fx, ok) = g(vp);
                if ok { fx } else { -1.0 - st.d.abs() }
            },
            lo,
            hi,
            1e-14 * (1.0 + st.d.abs()),
        );
        let (fx, ok) = g(vp);
        (ok && fx.abs() <= 1e-9 * (1.0 + st.d.abs())).then_some(vp)
    }

    /// Without an anchor, the top of the search is a zero-cruise member: D(vp_hi) = d
    /// (or vmax when even that falls short), and no larger root exists above the
    /// stop velocity.
    #[test]
    fn unanchored_top_is_a_zero_cruise_member() {
        let mut r = Lcg(21);
        for n in 0..4000 {
            let (v0, a0, d, lim) = case(&mut r);
            let st = Stretch::new(v0, a0, d, &lim);
            if st.rest {
                continue;
            }
            let dist = |vp: f64| {
                let r1 = ramp(st.v0, st.a0, vp, &lim);
                let k = r1.integrate(Kin {
                    p: 0.0,
                    v: st.v0,
                    a: st.a0,
                });
                k.p + ramp_from_rest(vp, &lim).2
            };
            if st.vp_hi < lim.v {
                let got = dist(st.vp_hi);
                assert!(
                    (got - st.d).abs() <= 1e-10 * (1.0 + st.d.abs()),
                    "case {n}: D(vp_hi) {got} vs {}",
                    st.d
                );
                // Above the stop velocity D increases: nothing above vp_hi reaches d.
                let m = stop_velocity(st.v0, st.a0, lim.j).clamp(0.0, lim.v);
                if st.vp_hi >= m {
                    assert!(dist(0.5 * (st.vp_hi + lim.v)) >= st.d);
                }
            } else {
                assert!(dist(lim.v) <= st.d * (1.0 + 1e-12) + 1e-12);
            }
        }
    }

    /// f' and f'' of `eval` are the derivatives of f (central differences away from
    /// the kinks where a ramp changes direction or starts holding amax).
    #[test]
    fn eval_derivatives_match_differences() {
        let mut r = Lcg(5);
        let mut checked = 0;
        for _ in 0..3000 {
            let (v0, a0, d, lim) = case(&mut r);
            let st = Stretch::new(v0, a0, d, &lim);
            let t = 10.0 * r.next() + 1.0;
            let x = 0.05 * lim.v + 0.9 * lim.v * r.next();
            let h = 1e-5 * lim.v;
            let (e, ep, em) = (
                st.eval(x, t, &lim),
                st.eval(x + h, t, &lim),
                st.eval(x - h, t, &lim),
            );
            let smooth = (ep.ddf - em.ddf).abs() <= 1e-3 * (1.0 + e.ddf.abs())
                && (ep.df - em.df - 2.0 * h * e.ddf).abs() <= 1e-3 * (1.0 + e.df.abs()) * h;
            if !(e.ok && ep.ok && em.ok && smooth) {
                continue;
            }
            checked += 1;
            let d1 = (ep.f - em.f) / (2.0 * h);
            assert!(
                (d1 - e.df).abs() <= 1e-6 * (1.0 + e.df.abs()),
                "f' {} vs {d1}",
                e.df
            );
            let d2 = (ep.df - em.df) / (2.0 * h);
            assert!(
                (d2 - e.ddf).abs() <= 1e-4 * (1.0 + e.ddf.abs()),
                "f'' {} vs {d2}",
                e.ddf
            );
        }
        assert!(checked > 1000, "only {checked} smooth points");
    }

    /// The model-step descent finds the same peak velocity as the old bracketed
    /// search wherever that finds one, and every root it reports lands the motion on
    /// the target at exactly t.
    #[test]
    fn descent_matches_bracketing_oracle() {
        let mut r = Lcg(9);
        let (mut both, mut only_new) = (0, 0);
        for n in 0..4000 {
            let (v0, a0, d, lim) = case(&mut r);
            let st = Stretch::new(v0, a0, d, &lim);
            let t_opt = from_state::time_optimal(v0, a0, d, &lim).duration();
            let t = t_opt * (1.0 + [1e-9, 1e-3, 0.05, 0.3, 1.0, 3.0][n % 6] * r.next());
            let old = vp_by_bracketing(&st, t, &lim);
            let new = st.peak_velocity(t, &lim);
            if let Some(ph) = st.search(t, &lim) {
                let end = ph.integrate(Kin {
                    p: 0.0,
                    v: st.v0,
                    a: st.a0,
                });
                assert!(
                    (end.p - st.d).abs() <= 1e-8 * (1.0 + st.d.abs()),
                    "case {n}: misses"
                );
                assert!((ph.duration() - t).abs() <= 1e-9 * t, "case {n}: not at t");
            }
            match (old, new) {
                (Some(_), None) => panic!("case {n}: the oracle finds a root, the descent none"),
                (Some(a), Some(b)) => {
                    both += 1;
                    assert!(
                        (a - b).abs() <= 1e-7 * (1.0 + a),
                        "case {n}: vp {b} vs oracle {a}"
                    );
                }
                (None, Some(_)) => only_new += 1,
                (None, None) => {}
            }
        }
        assert!(
            both > 3000,
            "{both} cases compared ({only_new} found by the descent only)"
        );
    }
}
