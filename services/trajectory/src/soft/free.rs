//! Fallback for a duration T that the stretch family cannot take (a blocked
//! interval): Ruckig's step-2 profiles without a cruise — jerk phases of ±jmax,
//! `(s1, −s1, s2, −s2)` (UDDU or UDUD), of free lengths, with a hold at ±amax inside
//! the first half (ACC0), the second (ACC1), both or neither — solved for T.
//!
//! The stretch family reaches a joint's durations through a velocity change to a
//! level vp with a = 0 there. When a target lies just past the brake point, profiles
//! whose acceleration does not return to zero between the two halves reach durations
//! the family cannot; Ruckig's time synchronisation uses them, so without them the
//! common duration could come out longer than necessary.
//!
//! Two unknown phase lengths per shape (the others follow from a = 0 at the end, the
//! total T and, for a hold, reaching ±amax); the end velocity and position give two
//! equations, solved by a grid over the triangle of the two unknowns and Newton's
//! method from the best cells. Runs only for blocked durations (from
//! `Stretch::phases`), never on the common path; allocates nothing.

use super::{Kin, Limits1, Phases};

/// Grid cells per axis of the unknowns' triangle.
const GRID: usize = 24;
/// Starting cells kept per jerk pattern for Newton's method.
const STARTS: usize = 4;

/// Phases (v0, a0) → rest at displacement `d` in exactly `t` seconds within `lim`, or
/// `None` when no profile of these shapes does it.
pub fn phases(v0: f64, a0: f64, d: f64, t: f64, lim: &Limits1) -> Option<Phases> {
    if t.is_nan() || t <= 0.0 {
        return None;
    }
    for shape in [Shape::None, Shape::Acc0, Shape::Acc1, Shape::Acc0Acc1] {
        for (s1, s2) in [(1.0, -1.0), (-1.0, 1.0), (1.0, 1.0), (-1.0, -1.0)] {
            let p = Pattern {
                v0,
                a0,
                d,
                t,
                s1,
                s2,
                shape,
                lim: *lim,
            };
            if let Some(ph) = p.solve() {
                return Some(ph);
            }
        }
    }
    None
}

/// Where the profile holds ±amax, if anywhere.
#[derive(Clone, Copy)]
enum Shape {
    /// Jerk phases only; unknowns t1, t3.
    None,
    /// A hold at s1·amax after the first phase; unknowns t2 (the hold), t3.
    Acc0,
    /// A hold at s2·amax before the last phase; unknowns t1, t3.
    Acc1,
    /// Both holds; unknowns t2 (the first hold), t3.
    Acc0Acc1,
}

/// One shape and jerk pattern: phases with jerks s1·J, 0, −s1·J, s2·J, 0, −s2·J.
struct Pattern {
    v0: f64,
    a0: f64,
    d: f64,
    t: f64,
    s1: f64,
    s2: f64,
    shape: Shape,
    lim: Limits1,
}

impl Pattern {
    /// The six phase lengths for the unknowns (x, y), or `None` when one is negative.
    fn lengths(&self, x: f64, y: f64) -> Option<[f64; 6]> {
        let (j, am) = (self.lim.j, self.lim.a);
        let (t1, t2, t3) = match self.shape {
            Shape::Acc0 | Shape::Acc0Acc1 => ((self.s1 * am - self.a0) / (self.s1 * j), x, y),
            Shape::None | Shape::Acc1 => (x, 0.0, y),
        };
        let a3 = self.a0 + self.s1 * j * (t1 - t3);
        let rest = self.t - t1 - t2 - t3;
        let (t5, t6, t7) = match self.shape {
            Shape::Acc1 | Shape::Acc0Acc1 => {
                let t5 = (self.s2 * am - a3) / (self.s2 * j);
                let t7 = am / j;
                (t5, rest - t5 - t7, t7)
            }
            Shape::None | Shape::Acc0 => {
                let diff = -a3 / (self.s2 * j); // t5 − t7
                (0.5 * (rest + diff), 0.0, 0.5 * (rest - diff))
            }
        };
        let ts = [t1, t2, t3, t5, t6, t7];
        ts.iter().all(|&t| t >= 0.0).then_some(ts)
    }

    fn jerks(&self) -> [f64; 6] {
        let j = self.lim.j;
        [
            self.s1 * j,
            0.0,
            -self.s1 * j,
            self.s2 * j,
            0.0,
            -self.s2 * j,
        ]
    }

    /// Scaled residual (end velocity, end position − d).
    fn residual(&self, x: f64, y: f64) -> Option<(f64, f64)> {
        let ts = self.lengths(x, y)?;
        let js = self.jerks();
        let mut k = Kin {
            p: 0.0,
            v: self.v0,
            a: self.a0,
        };
        for i in 0..6 {
            k = k.advance(ts[i], js[i]);
        }
        Some((k.v / self.lim.v, (k.p - self.d) / self.scale_p()))
    }

    fn scale_p(&self) -> f64 {
        self.d.abs().max(self.lim.v * self.t).max(1e-12)
    }

    fn solve(&self) -> Option<Phases> {
        // Best grid cells by residual norm (fixed-size, no allocation).
        let mut best = [(f64::INFINITY, 0.0, 0.0); STARTS];
        let h = self.t / GRID as f64;
        for i in 0..=GRID {
            for k in 0..=(GRID - i) {
                let (x, y) = (i as f64 * h, k as f64 * h);
                if let Some((rv, rp)) = self.residual(x, y) {
                    let r = rv.hypot(rp);
                    if r < best[STARTS - 1].0 {
                        best[STARTS - 1] = (r, x, y);
                        best.sort_by(|a, b| a.0.total_cmp(&b.0));
                    }
                }
            }
        }
        best.iter()
            .filter(|b| b.0.is_finite())
            .find_map(|&(_, x, y)| self.newton(x, y))
    }

    /// Newton's method on (x, y) with a finite-difference Jacobian; the phases when
    /// it lands on the target within the limits.
    fn newton(&self, mut x: f64, mut y: f64) -> Option<Phases> {
        let h = 1e-7 * self.t.max(1e-3);
        for _ in 0..40 {
            let (fv, fp) = self.residual(x, y)?;
            if fv.abs() < 1e-13 && fp.abs() < 1e-13 {
                return self.checked(x, y);
            }
            let probe = |dx: f64, dy: f64| {
                self.residual(x + dx, y + dy).or_else(|| {
                    self.residual(x - dx, y - dy)
                        .map(|(v, p)| (2.0 * fv - v, 2.0 * fp - p))
                })
            };
            let (vx, px) = probe(h, 0.0)?;
            let (vy, py) = probe(0.0, h)?;
            let (j11, j12, j21, j22) = ((vx - fv) / h, (vy - fv) / h, (px - fp) / h, (py - fp) / h);
            let det = j11 * j22 - j12 * j21;
            if det.abs() < 1e-300 || !det.is_finite() {
                return None;
            }
            let dx = (fv * j22 - fp * j12) / det;
            let dy = (fp * j11 - fv * j21) / det;
            // Damped step that stays where every phase length is non-negative.
            let mut step = 1.0;
            loop {
                let (nx, ny) = (x - step * dx, y - step * dy);
                if self.lengths(nx, ny).is_some() {
                    x = nx;
                    y = ny;
                    break;
                }
                step *= 0.5;
                if step < 1e-6 {
                    return None;
                }
            }
        }
        None
    }

    /// The phases for (x, y) if every velocity and acceleration stays within the
    /// limits (extremes of a at phase ends; of v there and where a crosses zero).
    fn checked(&self, x: f64, y: f64) -> Option<Phases> {
        let ts = self.lengths(x, y)?;
        let js = self.jerks();
        let (vm, am) = (self.lim.v * (1.0 + 1e-12), self.lim.a * (1.0 + 1e-12));
        let mut k = Kin {
            p: 0.0,
            v: self.v0,
            a: self.a0,
        };
        let mut ph = Phases::default();
        for i in 0..6 {
            if js[i] != 0.0 {
                let tz = -k.a / js[i];
                if tz > 0.0 && tz < ts[i] && k.advance(tz, js[i]).v.abs() > vm {
                    return None;
                }
            }
            k = k.advance(ts[i], js[i]);
            if k.a.abs() > am || k.v.abs() > vm {
                return None;
            }
            ph.push(ts[i], js[i]);
        }
        Some(ph)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A profile built from four known phases is found again for its own duration and
    /// lands on its own end state.
    #[test]
    fn recovers_a_known_four_phase_profile() {
        let lim = Limits1 {
            v: 2.0,
            a: 3.0,
            j: 5.0,
        };
        let (v0, a0) = (0.8, -0.4);
        // UDUD-like: −J, +J, −J, +J with a ≠ 0 between the halves.
        let js = [-5.0, 5.0, -5.0, 5.0];
        let mut ts = [0.1, 0.05, 0.0, 0.0];
        let a3 = a0 + js[0] * ts[0] + js[1] * ts[1];
        // t5 − t7 = a3 / J (for s2 = −1), choose t7 = 0.2.
        ts[3] = 0.2;
        ts[2] = ts[3] + a3 / 5.0;
        assert!(ts[2] > 0.0);
        let end_from = |v0: f64| {
            let mut k = Kin {
                p: 0.0,
                v: v0,
                a: a0,
            };
            for i in 0..4 {
                k = k.advance(ts[i], js[i]);
            }
            k
        };
        assert!(end_from(v0).a.abs() < 1e-15);
        // Its end velocity is not zero in general: shift v0 so that it is (the end
        // velocity moves one for one with v0), and ask for the position reached.
        let v0 = v0 - end_from(v0).v;
        let k = end_from(v0);
        let t: f64 = ts.iter().sum();
        let ph = phases(v0, a0, k.p, t, &lim).expect("found");
        let end = ph.integrate(Kin {
            p: 0.0,
            v: v0,
            a: a0,
        });
        assert!((ph.duration() - t).abs() < 1e-12);
        assert!((end.p - k.p).abs() < 1e-9 && end.v.abs() < 1e-9 && end.a.abs() < 1e-9);
    }
}
