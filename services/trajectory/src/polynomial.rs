//! Cubic and quintic point-to-point polynomials over a fixed duration (seed eq. 21–24).

/// Coefficients c0..c3 of q(t) = c0 + c1 t + c2 t² + c3 t³ with q(0) = q0, q(T) = q1,
/// q̇(0) = v0, q̇(T) = v1 (seed eq. 21–22; eq. 21 reads 6(θf − θi)/(tf − ti)²).
pub fn cubic_coefficients(q0: f64, q1: f64, v0: f64, v1: f64, t: f64) -> [f64; 4] {
    let h = q1 - q0;
    [
        q0,
        v0,
        3.0 * h / (t * t) - (2.0 * v0 + v1) / t,
        -2.0 * h / (t * t * t) + (v0 + v1) / (t * t),
    ]
}

/// Coefficients c0..c5 of the quintic with boundary positions, velocities and
/// accelerations (seed eq. 23–24 with the errata of docs/seed-arm.md: C4 contains 30(θi − θf)
/// and C5 −(θ̈i − θ̈f)tf²).
#[allow(clippy::too_many_arguments)]
pub fn quintic_coefficients(
    q0: f64,
    q1: f64,
    v0: f64,
    v1: f64,
    a0: f64,
    a1: f64,
    t: f64,
) -> [f64; 6] {
    let h = q1 - q0;
    let (t2, t3) = (t * t, t * t * t);
    [
        q0,
        v0,
        0.5 * a0,
        (20.0 * h - (8.0 * v1 + 12.0 * v0) * t - (3.0 * a0 - a1) * t2) / (2.0 * t3),
        (-30.0 * h + (14.0 * v1 + 16.0 * v0) * t + (3.0 * a0 - 2.0 * a1) * t2) / (2.0 * t3 * t),
        (12.0 * h - 6.0 * (v1 + v0) * t + (a1 - a0) * t2) / (2.0 * t3 * t2),
    ]
}
