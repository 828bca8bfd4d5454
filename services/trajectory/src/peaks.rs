//! Extremes of a piecewise polynomial: position range and peak |v|, |a|, |jerk|.

use crate::piecewise::Piecewise;

/// Value of Σ cᵢ xⁱ.
#[inline]
fn horner(c: &[f64], x: f64) -> f64 {
    c.iter().rev().fold(0.0, |acc, &ci| acc * x + ci)
}

/// Derivative coefficients.
fn deriv(c: &[f64; 6]) -> [f64; 6] {
    [c[1], 2.0 * c[2], 3.0 * c[3], 4.0 * c[4], 5.0 * c[5], 0.0]
}

/// (min, max) of the polynomial `c` on [0, len]: endpoints plus the roots of its
/// derivative (exact when the derivative is at most quadratic, else sign changes on
/// a 64-point grid refined by bisection).
fn range(c: &[f64; 6], len: f64) -> (f64, f64) {
    let mut lo = horner(c, 0.0).min(horner(c, len));
    let mut hi = horner(c, 0.0).max(horner(c, len));
    let mut take = |x: f64| {
        if x > 0.0 && x < len {
            let y = horner(c, x);
            lo = lo.min(y);
            hi = hi.max(y);
        }
    };
    let d = deriv(c);
    if d[3] == 0.0 && d[4] == 0.0 {
        let (a, b, cc) = (d[2], d[1], d[0]);
        if a == 0.0 {
            if b != 0.0 {
                take(-cc / b);
            }
        } else {
            let disc = b * b - 4.0 * a * cc;
            if disc >= 0.0 {
                let q = -0.5 * (b + b.signum() * disc.sqrt());
                if q != 0.0 {
                    take(q / a);
                    take(cc / q);
                } else {
                    take(0.0);
                }
            }
        }
    } else {
        const N: usize = 64;
        let h = len / N as f64;
        let mut x0 = 0.0;
        let mut f0 = horner(&d, x0);
        for i in 1..=N {
            let x1 = h * i as f64;
            let f1 = horner(&d, x1);
            if f0 == 0.0 || f0.signum() != f1.signum() {
                let (mut a, mut b, fa) = (x0, x1, f0);
                for _ in 0..60 {
                    let m = 0.5 * (a + b);
                    if horner(&d, m).signum() == fa.signum() {
                        a = m;
                    } else {
                        b = m;
                    }
                }
                take(0.5 * (a + b));
            }
            x0 = x1;
            f0 = f1;
        }
    }
    (lo, hi)
}

/// Extremes of one joint's motion: (q_min, q_max, max|v|, max|a|, max|jerk|).
pub(crate) fn extremes(pw: &Piecewise) -> [f64; 5] {
    let fin = pw.final_state();
    let mut out = [fin.p, fin.p, fin.v.abs(), fin.a.abs(), 0.0];
    for (t0, t1, c) in pw.pieces() {
        let len = t1 - t0;
        let (qlo, qhi) = range(&c, len);
        let dv = deriv(&c);
        let (vlo, vhi) = range(&dv, len);
        let da = deriv(&dv);
        let (alo, ahi) = range(&da, len);
        let (jlo, jhi) = range(&deriv(&da), len);
        out[0] = out[0].min(qlo);
        out[1] = out[1].max(qhi);
        out[2] = out[2].max(vlo.abs()).max(vhi.abs());
        out[3] = out[3].max(alo.abs()).max(ahi.abs());
        out[4] = out[4].max(jlo.abs()).max(jhi.abs());
    }
    out
}

/// Position range only (cheap: used on every plan for the position-limit check).
pub(crate) fn position_range(pw: &Piecewise) -> (f64, f64) {
    pw.position_range(range)
}
