//! Linear segment with parabolic blends, rest to rest over a fixed duration
//! (seed section 3.2.3): accelerate at a = V/tb for tb, cruise at V, decelerate.

use crate::piecewise::{Kin, Piecewise};

/// The seed's default cruise velocity, 1.5·(q1 − q0)/T.
pub fn default_cruise_velocity(q0: f64, q1: f64, t: f64) -> f64 {
    1.5 * (q1 - q0) / t
}

/// Checks |q1 − q0|/T < |V| ≤ 2|q1 − q0|/T with the sign of q1 − q0 (V = 0 only
/// when q1 = q0). Returns the reason on refusal.
pub fn check_cruise_velocity(q0: f64, q1: f64, t: f64, v: f64) -> Result<(), &'static str> {
    let h = q1 - q0;
    if h == 0.0 {
        return if v == 0.0 {
            Ok(())
        } else {
            Err("must be 0 when q1 = q0")
        };
    }
    if v * h <= 0.0 {
        return Err("has the wrong sign for q1 - q0");
    }
    let (lo, hi) = (h.abs() / t, 2.0 * h.abs() / t);
    if v.abs() <= lo {
        Err("too slow: |V| must exceed |q1 - q0|/T")
    } else if v.abs() > hi * (1.0 + 1e-12) {
        Err("too fast: |V| must be at most 2|q1 - q0|/T")
    } else {
        Ok(())
    }
}

/// Blend duration tb = T − (q1 − q0)/V.
pub fn blend_time(q0: f64, q1: f64, t: f64, v: f64) -> f64 {
    if v == 0.0 {
        0.0
    } else {
        (t - (q1 - q0) / v).min(0.5 * t)
    }
}

/// The LSPB profile as three pieces (expects a checked cruise velocity).
pub(crate) fn piecewise(q0: f64, q1: f64, t: f64, v: f64) -> Piecewise {
    let fin = Kin {
        p: q1,
        v: 0.0,
        a: 0.0,
    };
    if v == 0.0 {
        return Piecewise::hold(q1);
    }
    let tb = blend_time(q0, q1, t, v);
    let a = v / tb;
    let mut pw = Piecewise::polynomial(tb, [q0, 0.0, 0.5 * a, 0.0, 0.0, 0.0], fin);
    let qb = q0 + 0.5 * a * tb * tb;
    pw.push_piece(t - 2.0 * tb, [qb, v, 0.0, 0.0], fin);
    let qc = q1 - 0.5 * a * tb * tb;
    pw.push_piece(tb, [qc, v, -0.5 * a, 0.0], fin);
    pw
}
