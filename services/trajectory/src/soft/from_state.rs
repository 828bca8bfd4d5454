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
use super::{Kin, Limits1, Phases, solve_known, stop_velocity};

/// The push duration after which the stop velocity reaches vmax (positive frame).
pub fn tau_max(v0: f64, a0: f64, lim: &Limits1) -> f64 {
    let (vm, am, jm) = (lim.v, lim.a, lim.j);
    let s0 = stop_velocity(v0, a0, jm);
    if s0 >= vm {
        return 0.0;
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
    let pb = brake_point(v0, a0, lim);
    let sg = if d >= pb { 1.0 } else { -1.0 };
    let (mut ph, peak) = positive(sg * v0, sg * a0, sg * d, sg * pb, lim);
    for p in &mut ph.p[..ph.n] {
        p.j *= sg;
    }
    (ph, peak)
}

/// Positive-frame solution (d ≥ brake point `pb`, which is the end of τ = 0).
fn positive(v0: f64, a0: f64, d: f64, pb: f64, lim: &Limits1) -> (Phases, Option<f64>) {
    let tmax = tau_max(v0, a0, lim);
    let p_max = push_then_stop_end(v0, a0, tmax, lim);
    if d >= p_max {
        // Reach vmax, cruise, stop.
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
        (ph, Some(lim.v))
    } else {
        let tau = solve_known(
            |t| push_then_stop_end(v0, a0, t, lim) - d,
            (0.0, pb - d),
            (tmax, p_max - d),
            1e-15 * (1.0 + d.abs()),
        );
        let k = push(a0, tau, lim).integrate(Kin {
            p: 0.0,
            v: v0,
            a: a0,
        });
        let peak = (k.a >= 0.0).then(|| k.v + k.a * k.a / (2.0 * lim.j));
        (push_then_stop(v0, a0, tau, lim).0, peak)
    }
}
