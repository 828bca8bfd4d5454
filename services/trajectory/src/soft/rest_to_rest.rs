//! Rest-to-rest soft motion in closed form (seed section 3.2.4, with the docs/seed-arm.md
//! errata): total time 4Tj + 2Ta + Tv.
//!
//! Seed case 1 (D ≥ Dthr1): vmax and amax reached, cruise Tv > 0. Case 2
//! (Dthr1 > D ≥ Dthr2): amax reached, no cruise, Ta = √(A²/(4J²) + D/A) − 3A/(2J)
//! (here written as the peak velocity). Case 3 (D < Dthr2): neither limit reached,
//! Tj = (D/(2J))^(1/3). When vmax < amax²/jmax the peak acceleration is √(vmax·jmax).

use super::velocity::ramp_from_rest;
use super::{Limits1, Phases, solve};

/// Seed's case number (1, 2, 3) for a distance `d` ≥ 0, with Dthr1, Dthr2.
pub fn seed_case(d: f64, lim: &Limits1) -> (u8, f64, f64) {
    let (_, _, d_v) = ramp_from_rest(lim.v, lim);
    let dthr1 = 2.0 * d_v;
    let dthr2 = 2.0 * lim.a.powi(3) / (lim.j * lim.j);
    let case = if d >= dthr1 {
        1
    } else if d >= dthr2 {
        2
    } else {
        3
    };
    (case, dthr1, dthr2)
}

/// Peak velocity of the zero-cruise profile covering `d` ≥ 0 (unbounded by vmax).
#[inline]
fn peak_velocity(d: f64, lim: &Limits1) -> f64 {
    let (a, j) = (lim.a, lim.j);
    let vp = (0.25 * d * d * j).cbrt();
    if vp * j <= a * a {
        vp
    } else {
        0.5 * a * (-a / j + (a * a / (j * j) + 4.0 * d / a).sqrt())
    }
}

/// Peak velocity vp ∈ [d/t, hi] of the stretched profile with jerk-limited ramps
/// (no amax phase): d = vp·(t − 2√(vp/J)). With s = √vp this is the cubic
/// (2/√J)·s³ − t·s² + d = 0, whose root below its local minimum s = √J·t/3 is taken in
/// closed form (trigonometric) and polished by Newton steps; the bracketed search
/// remains as the fallback.
fn jerk_limited_peak(d: f64, t: f64, j: f64, hi: f64) -> f64 {
    let g = |vp: f64| vp * (t - 2.0 * (vp / j).sqrt()) - d;
    let k = 2.0 / j.sqrt();
    // Monic: x³ + b·x² + e = 0, b = −t/k, e = d/k; x = y − b/3: y³ + p·y + q = 0.
    let (b, e) = (-t / k, d / k);
    let p = -b * b / 3.0;
    let q = 2.0 * b * b * b / 27.0 + e;
    let (s_lo, s_hi) = ((d / t).sqrt(), hi.sqrt());
    if p < 0.0 {
        let r = (-p / 3.0).sqrt();
        let c = (-q / (2.0 * r * r * r)).clamp(-1.0, 1.0);
        let phi = c.acos() / 3.0;
        // The middle of the three real roots.
        let mut x = 2.0 * r * (phi - 2.0 * std::f64::consts::FRAC_PI_3).cos() - b / 3.0;
        for _ in 0..3 {
            x = x.clamp(s_lo, s_hi);
            let h = x * x * (k * x - t) + d;
            let dh = x * (3.0 * k * x - 2.0 * t);
            if dh >= 0.0 {
                break;
            }
            let step = h / dh;
            x -= step;
            if step.abs() <= 1e-15 * x {
                break;
            }
        }
        let x = x.clamp(s_lo, s_hi);
        let vp = x * x;
        if g(vp).abs() <= 1e-13 * d.max(1e-300) {
            return vp;
        }
    }
    solve(g, d / t, hi)
}

/// Phases of a symmetric motion: ramp 0 → vp, cruise `tc`, ramp vp → 0.
#[inline]
fn symmetric(vp: f64, tc: f64, lim: &Limits1) -> Phases {
    let (t1, t2, _) = ramp_from_rest(vp, lim);
    let mut ph = Phases::default();
    ph.push(t1, lim.j);
    ph.push(t2, 0.0);
    ph.push(t1, -lim.j);
    ph.push(tc, 0.0);
    ph.push(t1, -lim.j);
    ph.push(t2, 0.0);
    ph.push(t1, lim.j);
    ph
}

/// Time-optimal rest-to-rest phases over a distance `d` ≥ 0.
#[inline]
pub fn time_optimal(d: f64, lim: &Limits1) -> Phases {
    if d <= 0.0 {
        return Phases::default();
    }
    let (_, _, half_v) = ramp_from_rest(lim.v, lim);
    if d >= 2.0 * half_v {
        symmetric(lim.v, (d - 2.0 * half_v) / lim.v, lim)
    } else {
        symmetric(peak_velocity(d, lim).min(lim.v), 0.0, lim)
    }
}

/// Duration of [`time_optimal`]`(d, lim)`, bit for bit (the same sum in the same
/// order), without building the phases.
#[inline]
pub fn time_optimal_duration(d: f64, lim: &Limits1) -> f64 {
    if d <= 0.0 {
        return 0.0;
    }
    let (_, _, half_v) = ramp_from_rest(lim.v, lim);
    let (vp, tc) = if d >= 2.0 * half_v {
        (lim.v, (d - 2.0 * half_v) / lim.v)
    } else {
        (peak_velocity(d, lim).min(lim.v), 0.0)
    };
    let (t1, t2, _) = ramp_from_rest(vp, lim);
    let nz = |x: f64| if x > 0.0 { x } else { 0.0 };
    let (t1, t2, tc) = (nz(t1), nz(t2), nz(tc));
    t1 + t2 + t1 + tc + t1 + t2 + t1
}

/// Rest-to-rest phases over `d` ≥ 0 finishing exactly at `t` (≥ the minimum): the
/// peak velocity vp solves d = vp·(t − T_ramp(vp)).
#[inline]
pub fn stretched(d: f64, t: f64, lim: &Limits1) -> Phases {
    if d <= 0.0 {
        return Phases::default();
    }
    let (a, j) = (lim.a, lim.j);
    // Acceleration-limited ramps: vp²/A − vp(t − A/J) + d = 0, smaller root.
    let b = t - a / j;
    let disc = b * b - 4.0 * d / a;
    let vp_big = if disc >= 0.0 {
        0.5 * a * (b - disc.sqrt())
    } else {
        f64::NAN
    };
    let vp = if vp_big * j >= a * a {
        vp_big
    } else {
        // Jerk-limited ramps: d = vp·t − 2·vp^1.5/√J, increasing up to vp = J t²/9.
        let hi = (a * a / j).min(j * t * t / 9.0).min(lim.v);
        jerk_limited_peak(d, t, j, hi)
    };
    let vp = vp.min(lim.v);
    let (t1, t2, _) = ramp_from_rest(vp, lim);
    // The cruise fills the remaining time exactly, so every joint ends at `t`.
    symmetric(vp, (t - 2.0 * (2.0 * t1 + t2)).max(0.0), lim)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The closed-form jerk-limited peak velocity equals the bracketed root.
    #[test]
    fn jerk_limited_peak_matches_root_search() {
        let j = 2.7;
        for k in 1..200 {
            let d = 1e-4 * k as f64 * k as f64;
            // Minimum duration (jerk-limited, no amax): 4·(d/(2J))^(1/3).
            let t_min = 4.0 * (d / (2.0 * j)).cbrt();
            for s in [1.0, 1.0 + 1e-9, 1.001, 1.1, 1.5, 3.0, 10.0] {
                let t = t_min * s;
                let hi = j * t * t / 9.0;
                let g = |vp: f64| vp * (t - 2.0 * (vp / j).sqrt()) - d;
                let want = solve(g, d / t, hi);
                let got = jerk_limited_peak(d, t, j, hi);
                assert!(
                    (got - want).abs() <= 1e-9 * want,
                    "d {d} t {t}: {got} vs {want}"
                );
            }
        }
    }
}
