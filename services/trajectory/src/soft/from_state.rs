//! Time-optimal soft motion from a moving state (v0, a0), already inside the limits
//! (|a0| ≤ amax, |v0 + a0|a0|/(2 jmax)| ≤ vmax), to rest at displacement `d`.
//!
//! The fastest stop (velocity change to 0) ends at the *brake point* p_b. A target
//! beyond p_b is reached by pushing towards it first: jerk +jmax for τ seconds
//! (holding +amax once reached), then the fastest stop. The end position grows
//! monotonically with τ, so τ is a bracketed root; once the push makes the stop
//! velocity reach vmax the profile cruises at vmax instead. A target before p_b is
//! the mirror image. Seen as jerk signs this is Ruckig's UDDU (or, mirrored, its DUUD)
//! family with the VEL/ACC0/ACC1 variants, for rest targets.

use super::velocity::{ramp, velocity_change};
use super::{Kin, Limits1, Phases, model_root_increasing, stop_velocity};

/// The push duration after which the stop velocity reaches vmax (positive frame).
pub fn tau_max(v0: f64, a0: f64, lim: &Limits1) -> f64 {
    let (vm, am, jm) = (lim.v, lim.a, lim.j);
    let s0 = stop_velocity(v0, a0, jm);
    if s0 >= vm {
        // At the velocity limit already (e.g. right after a brake pre-phase, with
        // v > vmax and a < 0): pushing while a < 0 leaves the stop velocity where it
        // is, so the push may still last until a = 0 — the start of the cruise.
        return (-a0 / jm).max(0.0);
    }
    let a0p = a0.max(0.0);
    let s_a = s0 + (am * am - a0p * a0p) / jm;
    if s_a >= vm {
        let ap = ((vm - s0) * jm + a0p * a0p).sqrt();
        ((ap - a0) / jm).max(0.0)
    } else {
        ((am - a0) / jm).max(0.0) + (vm - s_a) / am
    }
}

/// Push phases of length τ from acceleration a0 (positive frame).
#[inline]
fn push(a0: f64, tau: f64, lim: &Limits1) -> Phases {
    let t_a = ((lim.a - a0) / lim.j).max(0.0);
    let mut ph = Phases::default();
    ph.push(tau.min(t_a), lim.j);
    ph.push((tau - t_a).max(0.0), 0.0);
    ph
}

/// End position of "push τ, then stop" (positive frame), without building phases.
#[inline]
fn push_then_stop_end(v0: f64, a0: f64, tau: f64, lim: &Limits1) -> f64 {
    let t_a = ((lim.a - a0) / lim.j).max(0.0);
    let k = Kin {
        p: 0.0,
        v: v0,
        a: a0,
    }
    .advance(tau.min(t_a), lim.j)
    .advance((tau - t_a).max(0.0), 0.0);
    ramp(k.v, k.a, 0.0, lim).integrate(k).p
}

/// Push τ then stop: the whole profile (positive frame).
pub fn push_then_stop(v0: f64, a0: f64, tau: f64, lim: &Limits1) -> (Phases, f64) {
    let start = Kin {
        p: 0.0,
        v: v0,
        a: a0,
    };
    let mut ph = push(a0, tau, lim);
    let k = ph.integrate(start);
    let stop = ramp(k.v, k.a, 0.0, lim);
    let end = stop.integrate(k);
    stop.push_to(&mut ph);
    (ph, end.p)
}

/// Position where the fastest stop from (v0, a0) ends, relative to the start.
#[inline]
pub fn brake_point(v0: f64, a0: f64, lim: &Limits1) -> f64 {
    ramp(v0, a0, 0.0, lim)
        .integrate(Kin {
            p: 0.0,
            v: v0,
            a: a0,
        })
        .p
}

/// Time-optimal phases (in the original frame) from (v0, a0) to rest at `d`.
pub fn time_optimal(v0: f64, a0: f64, d: f64, lim: &Limits1) -> Phases {
    time_optimal_peak(v0, a0, d, lim).0
}

/// [`time_optimal`], plus the peak velocity (in the frame where the motion goes
/// towards +) at which its acceleration crosses zero, when it does: the anchor of
/// the stretch family ([`super::stretch::Stretch::with_anchor`]).
pub fn time_optimal_peak(v0: f64, a0: f64, d: f64, lim: &Limits1) -> (Phases, Option<f64>) {
    let o = optimal(v0, a0, d, lim);
    (o.phases(lim), o.anchor)
}

/// The time-optimal motion from (v0, a0) to rest at `d`, solved but not yet written
/// as phases: synchronisation needs every joint's duration but the phases of the
/// slowest joint only (the others are stretched).
#[derive(Debug, Clone, Copy)]
pub(crate) struct Optimal {
    /// Duration (s).
    pub duration: f64,
    /// Peak velocity anchoring the stretch family (see [`time_optimal_peak`]).
    pub anchor: Option<f64>,
    /// Brake point of (v0, a0), relative to the start (original frame).
    pub pb: f64,
    /// +1 when the motion goes towards + (d ≥ pb), else −1; v0, a0, d in that frame.
    sg: f64,
    v0: f64,
    a0: f64,
    d: f64,
    /// Push duration, or `None` for the profile that cruises at vmax.
    tau: Option<f64>,
}

/// Solves the time-optimal motion (see [`Optimal`]).
pub(crate) fn optimal(v0: f64, a0: f64, d: f64, lim: &Limits1) -> Optimal {
    let pb = brake_point(v0, a0, lim);
    let sg = if d >= pb { 1.0 } else { -1.0 };
    let (v0, a0, d, pbs) = (sg * v0, sg * a0, sg * d, sg * pb);
    let start = Kin {
        p: 0.0,
        v: v0,
        a: a0,
    };
    let tmax = tau_max(v0, a0, lim);
    let p_max = push_then_stop_end(v0, a0, tmax, lim);
    let (duration, anchor, tau) = if d >= p_max {
        // Reach vmax, cruise, stop.
        let r1 = ramp(v0, a0, lim.v, lim);
        let k = r1.integrate(start);
        let r2 = ramp(lim.v, 0.0, 0.0, lim);
        let end = r2.integrate(Kin { a: 0.0, ..k });
        let cruise = ((d - end.p) / lim.v).max(0.0);
        (r1.duration() + cruise + r2.duration(), Some(lim.v), None)
    } else {
        let tau = push_duration(v0, a0, d, pbs, tmax, p_max, lim);
        let k = push(a0, tau, lim).integrate(start);
        let peak = (k.a >= 0.0).then(|| k.v + k.a * k.a / (2.0 * lim.j));
        (tau + ramp(k.v, k.a, 0.0, lim).duration(), peak, Some(tau))
    };
    Optimal {
        duration,
        anchor,
        pb,
        sg,
        v0,
        a0,
        d,
        tau,
    }
}

impl Optimal {
    /// The motion's phases (original frame).
    pub(crate) fn phases(&self, lim: &Limits1) -> Phases {
        let (v0, a0, d) = (self.v0, self.a0, self.d);
        let mut ph = match self.tau {
            None => {
                let start = Kin {
                    p: 0.0,
                    v: v0,
                    a: a0,
                };
                let mut ph = velocity_change(v0, a0, lim.v, lim);
                let k = ph.integrate(start);
                let stop = velocity_change(lim.v, 0.0, 0.0, lim);
                let end = stop.integrate(Kin { a: 0.0, ..k });
                ph.push((d - end.p) / lim.v, 0.0);
                ph.extend(&stop);
                ph
            }
            Some(tau) => push_then_stop(v0, a0, tau, lim).0,
        };
        for p in &mut ph.p[..ph.n] {
            p.j *= self.sg;
        }
        ph
    }
}

/// Push duration at which the stop velocity of the pushed state reaches 0 (positive
/// frame), 0 when it starts there or above. Before it the fastest stop accelerates
/// first, so the end position stays at the brake point: the root search starts here.
/// The stop velocity after a push to acceleration a₁ ≥ 0 is s₀ + (a₁² − max(a₀, 0)²)/J
/// (it does not move while a₁ < 0), and grows by amax per second of hold.
fn tau_zero(v0: f64, a0: f64, lim: &Limits1) -> f64 {
    let (am, jm) = (lim.a, lim.j);
    let s0 = stop_velocity(v0, a0, jm);
    if s0 >= 0.0 {
        return 0.0;
    }
    let a0p = a0.max(0.0);
    let s_a = s0 + (am * am - a0p * a0p) / jm;
    if s_a >= 0.0 {
        ((a0p * a0p - s0 * jm).sqrt() - a0) / jm
    } else {
        ((am - a0) / jm).max(0.0) - s_a / am
    }
    .max(0.0)
}

/// End position of "push τ, then stop" (positive frame) and its exact first two
/// derivatives d/dτ. With the pushed state (v, a) the stop distance S(v, a) has, for
/// a stop decelerating to the peak w = √(J v + a²/2) (no amax phase):
/// S_v = (a + 3w/2)/J, S_a = (J v + a² + 3aw/2)/J², S_vv = 3/(4w),
/// S_va = (1 + 3a/(4w))/J, S_aa = (2a + 3w/2 + 3a²/(4w))/J²; with an amax phase
/// (q = 2Jv + a²): S_v = (A² + 2Aa + q)/(2AJ), S_a = (A + a)(Aa + q)/(2AJ²),
/// S_vv = 1/A, S_va = (A + a)/(AJ), S_aa = (Aa + q + (A + a)(A + 2a))/(2AJ²).
/// The push moves (p, v, a) at rates (v, a, J) while ramping, (v, A, 0) while holding.
#[inline]
fn end_and_slope(v0: f64, a0: f64, tau: f64, lim: &Limits1) -> (f64, f64, f64) {
    let (am, jm) = (lim.a, lim.j);
    let t_a = ((am - a0) / jm).max(0.0);
    let k = Kin {
        p: 0.0,
        v: v0,
        a: a0,
    }
    .advance(tau.min(t_a), jm)
    .advance((tau - t_a).max(0.0), 0.0);
    let r = ramp(k.v, k.a, 0.0, lim);
    let e = r.integrate(k).p;
    if r.j > 0.0 {
        // The stop starts by accelerating: still on the flat stretch before tau_zero.
        return (e, 0.0, 0.0);
    }
    let (v, a) = (k.v, k.a);
    let w2 = jm * v + 0.5 * a * a;
    let (s_v, s_a, s_vv, s_va, s_aa) = if w2 <= am * am {
        let w = w2.max(0.0).sqrt();
        let iw = 1.0 / w;
        (
            (a + 1.5 * w) / jm,
            (jm * v + a * a + 1.5 * a * w) / (jm * jm),
            0.75 * iw,
            (1.0 + 0.75 * a * iw) / jm,
            (2.0 * a + 1.5 * w + 0.75 * a * a * iw) / (jm * jm),
        )
    } else {
        let q = 2.0 * jm * v + a * a;
        (
            (am * am + 2.0 * am * a + q) / (2.0 * am * jm),
            (am + a) * (am * a + q) / (2.0 * am * jm * jm),
            1.0 / am,
            (am + a) / (am * jm),
            (am * a + q + (am + a) * (am + 2.0 * a)) / (2.0 * am * jm * jm),
        )
    };
    if tau > t_a {
        (e, v + s_v * am, am + s_vv * am * am)
    } else {
        (
            e,
            v + s_v * a + s_a * jm,
            a + s_vv * a * a + 2.0 * s_va * a * jm + s_aa * jm * jm + s_v * jm,
        )
    }
}

// The positive frame (d ≥ brake point pb, the end of τ = 0): the end position e(τ)
// of "push τ, then stop" is constant (= pb) up to [`tau_zero`], then strictly
// increasing and smooth except at τ = (amax − a₀)/J where the push starts holding
// amax. Beyond e(tmax) the profile cruises at vmax (closed form). Below it the root
// of e(τ) = d is taken by safeguarded steps to the root of the local quadratic model
// ([`end_and_slope`] gives e, e', e'' exactly) on the smooth piece that holds it, from
// the secant point of that piece — Ruckig's UDDU NONE/ACC0/ACC1 cases (for rest
// targets) as one monotone function instead of three quartics; ACC0_ACC1 (both amax
// holds) in closed form.

/// The push duration τ ∈ [tau_zero, tmax] whose "push, then stop" ends at `d`, given
/// e(0) = pb ≤ d < e(tmax) = p_max.
#[inline]
fn push_duration(v0: f64, a0: f64, d: f64, pb: f64, tmax: f64, p_max: f64, lim: &Limits1) -> f64 {
    let (mut lo, mut flo) = (tau_zero(v0, a0, lim).min(tmax), pb - d);
    let (mut hi, mut fhi) = (tmax, p_max - d);
    if flo >= 0.0 {
        return lo;
    }
    let (am, jm) = (lim.a, lim.j);
    let t_a = ((am - a0) / jm).max(0.0);
    if t_a < hi {
        // Holding +amax. Once the pushed velocity v₁ reaches c = A²/(2J) the stop holds
        // −amax too (Ruckig's ACC0_ACC1) and the end position is quadratic in v₁:
        // e − d = Q(v₁) = v₁²/A + 2A v₁/J + K, K = p_a − (v_a² + c²)/(2A) + 5A³/(6J²) − d,
        // (p_a, v_a) the state when the hold starts. Q increases for v₁ > 0, so its
        // root is e's root whenever it falls in that piece [t_c, tmax]; tried first.
        let ka = Kin {
            p: 0.0,
            v: v0,
            a: a0,
        }
        .advance(t_a, jm);
        let c = am * am / (2.0 * jm);
        let t_c = t_a + ((c - ka.v) / am).max(0.0);
        if t_c < hi {
            let k = ka.p - (ka.v * ka.v + c * c) / (2.0 * am)
                + 5.0 * am * am * am / (6.0 * jm * jm)
                - d;
            let b = am * am / jm;
            let v1 = (b * b - am * k).sqrt() - b;
            let tau = t_a + (v1 - ka.v) / am;
            if tau >= t_c.max(lo) {
                return tau.min(hi);
            }
            // Below t_c: e(t_c) − d = Q(v(t_c)) > 0 bounds the root from above.
            let vc = ka.v.max(c);
            let f_c = vc * vc / am + 2.0 * am * vc / jm + k;
            if t_c > lo && f_c > 0.0 {
                (hi, fhi) = (t_c, f_c);
            }
        }
    }
    // Keep to the smooth piece: below or above the start of the amax hold.
    if t_a > lo && t_a < hi {
        let f_a = push_then_stop_end(v0, a0, t_a, lim) - d;
        if f_a >= 0.0 {
            (hi, fhi) = (t_a, f_a);
        } else {
            (lo, flo) = (t_a, f_a);
        }
    }
    let x0 = (lo * fhi - hi * flo) / (fhi - flo);
    model_root_increasing(
        |t| {
            let (e, de, dde) = end_and_slope(v0, a0, t, lim);
            (e - d, de, dde)
        },
        lo,
        hi,
        x0,
        1e-15 * (1.0 + d.abs()),
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::soft::solve_known;
    use crate::soft::test_cases::{Lcg, random_moving_start};

    /// The old numeric search, kept as the oracle: Illinois regula falsi on e(τ) = d.
    fn tau_by_bracketing(v0: f64, a0: f64, d: f64, lim: &Limits1) -> f64 {
        let pb = brake_point(v0, a0, lim);
        let tmax = tau_max(v0, a0, lim);
        let p_max = push_then_stop_end(v0, a0, tmax, lim);
        solve_known(
            |t| push_then_stop_end(v0, a0, t, lim) - d,
            (0.0, pb - d),
            (tmax, p_max - d),
            1e-15 * (1.0 + d.abs()),
        )
    }

    /// Random inside-the-limits start (positive frame) and a target in [pb, p_max).
    fn case(r: &mut Lcg) -> (f64, f64, f64, Limits1) {
        let (v0, a0, lim) = random_moving_start(r);
        let pb = brake_point(v0, a0, &lim);
        let tmax = tau_max(v0, a0, &lim);
        let p_max = push_then_stop_end(v0, a0, tmax, &lim);
        // Targets spread over [pb, p_max), denser near both ends.
        let u = r.next();
        let u = match (r.next() * 4.0) as u32 {
            0 => u * 1e-6,
            1 => 1.0 - u * 1e-6,
            _ => u,
        };
        (v0, a0, pb + u * (p_max - pb), lim)
    }

    #[test]
    fn slope_and_curvature_are_the_derivatives_of_the_end_position() {
        let mut r = Lcg(7);
        for _ in 0..2000 {
            let (v0, a0, _, lim) = case(&mut r);
            let (lo, hi) = (tau_zero(v0, a0, &lim), tau_max(v0, a0, &lim));
            let t = lo + r.next() * (hi - lo);
            let h = 1e-6 * (1.0 + t);
            let (_, de, dde) = end_and_slope(v0, a0, t, &lim);
            let num = (push_then_stop_end(v0, a0, t + h, &lim)
                - push_then_stop_end(v0, a0, t - h, &lim))
                / (2.0 * h);
            let num2 = (end_and_slope(v0, a0, t + h, &lim).1
                - end_and_slope(v0, a0, t - h, &lim).1)
                / (2.0 * h);
            // Central differences straddle the kink at the start of the amax hold.
            let t_a = (lim.a - a0) / lim.j;
            if (t - t_a).abs() > 2.0 * h && t - h > lo {
                assert!(
                    (de - num).abs() <= 1e-5 * (1.0 + num.abs()),
                    "v0 {v0} a0 {a0} {lim:?} t {t}: {de} vs {num}"
                );
                // The curvature jumps where the stop starts holding amax: skip there.
                let k = push(a0, t, &lim).integrate(Kin {
                    p: 0.0,
                    v: v0,
                    a: a0,
                });
                let w2 = lim.j * k.v + 0.5 * k.a * k.a;
                if (w2.sqrt() - lim.a).abs() > 1e-3 * lim.a {
                    assert!(
                        (dde - num2).abs() <= 1e-4 * (1.0 + num2.abs()),
                        "v0 {v0} a0 {a0} {lim:?} t {t}: e'' {dde} vs {num2}"
                    );
                }
            }
        }
    }

    #[test]
    fn tau_zero_is_where_the_end_starts_moving() {
        let mut r = Lcg(11);
        for _ in 0..2000 {
            let (v0, a0, _, lim) = case(&mut r);
            let tz = tau_zero(v0, a0, &lim);
            let pb = brake_point(v0, a0, &lim);
            let at = push_then_stop_end(v0, a0, tz, &lim);
            assert!((at - pb).abs() <= 1e-12 * (1.0 + pb.abs()), "{at} vs {pb}");
            let tmax = tau_max(v0, a0, &lim);
            if tmax > tz {
                let after = push_then_stop_end(v0, a0, tz + 1e-3 * (tmax - tz), &lim);
                assert!(after > pb, "end does not move after tau_zero");
            }
        }
    }

    /// Newton from the secant point lands on the same push duration as the bracketed
    /// search (to round-off), and the resulting profile ends on the target.
    #[test]
    fn newton_push_duration_matches_bracketing_oracle() {
        let mut r = Lcg(3);
        for n in 0..20_000 {
            let (v0, a0, d, lim) = case(&mut r);
            let pb = brake_point(v0, a0, &lim);
            let tmax = tau_max(v0, a0, &lim);
            let p_max = push_then_stop_end(v0, a0, tmax, &lim);
            if d >= p_max {
                continue;
            }
            let got = push_duration(v0, a0, d, pb, tmax, p_max, &lim);
            let end = push_then_stop_end(v0, a0, got, &lim);
            assert!(
                (end - d).abs() <= 1e-12 * (1.0 + d.abs()),
                "case {n}: end {end} vs {d}"
            );
            let want = tau_by_bracketing(v0, a0, d, &lim);
            let e_want = push_then_stop_end(v0, a0, want, &lim);
            // Equal durations, except where e(τ) is flat (τ below tau_zero) there.
            if (e_want - pb).abs() > 1e-12 * (1.0 + pb.abs()) {
                assert!(
                    (got - want).abs() <= 1e-9 * (1.0 + want),
                    "case {n}: τ {got} vs oracle {want} (v0 {v0} a0 {a0} d {d} {lim:?})"
                );
            }
        }
    }
}
