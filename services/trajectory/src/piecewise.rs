//! One joint's motion as up to [`MAX_PHASES`] polynomial pieces (degree ≤ 5).
//!
//! Every profile — a single cubic or quintic, the three LSPB pieces, the up to twelve
//! constant-jerk phases of soft motion — is stored the same way (start times, ends and
//! cubic coefficients in flat arrays, plus a hold slot for the final state), so
//! sampling is a short scan over the piece ends and one Horner evaluation, with no
//! allocation and no division.

/// Most pieces one joint's motion can have (brake 2 + stop 3 + rest-to-rest 7).
pub const MAX_PHASES: usize = 12;

/// A constant-jerk phase: duration and jerk.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Phase {
    /// Duration (s).
    pub t: f64,
    /// Jerk (rad/s³).
    pub j: f64,
}

/// A short fixed-capacity list of constant-jerk phases.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Phases {
    /// Phases in order; only the first `n` are used.
    pub p: [Phase; MAX_PHASES],
    /// Number of phases used.
    pub n: usize,
}

impl Phases {
    /// Appends a phase; zero-length phases are dropped.
    #[inline]
    pub fn push(&mut self, t: f64, j: f64) {
        if t > 0.0 && self.n < MAX_PHASES {
            self.p[self.n] = Phase { t, j };
            self.n += 1;
        }
    }
    /// Appends all phases of `other`.
    pub fn extend(&mut self, other: &Phases) {
        for ph in &other.p[..other.n] {
            self.push(ph.t, ph.j);
        }
    }
    /// Total duration.
    pub fn duration(&self) -> f64 {
        self.p[..self.n].iter().map(|p| p.t).sum()
    }
    /// Integrates the phases from (p, v, a).
    #[inline]
    pub fn integrate(&self, s: Kin) -> Kin {
        self.p[..self.n]
            .iter()
            .fold(s, |s, ph| s.advance(ph.t, ph.j))
    }
}

/// Position, velocity, acceleration of one joint.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Kin {
    /// Position.
    pub p: f64,
    /// Velocity.
    pub v: f64,
    /// Acceleration.
    pub a: f64,
}

impl Kin {
    /// State after `t` seconds at constant jerk `j`.
    #[inline]
    pub fn advance(self, t: f64, j: f64) -> Kin {
        const SIXTH: f64 = 1.0 / 6.0;
        Kin {
            p: self.p + t * (self.v + t * (0.5 * self.a + t * j * SIXTH)),
            v: self.v + t * (self.a + 0.5 * t * j),
            a: self.a + t * j,
        }
    }
}

/// Slots of a joint's table: the pieces plus one "hold" slot after the last.
const SLOTS: usize = MAX_PHASES + 1;
/// Length of the piece-end table searched by [`Piecewise::slot`], padded with +∞.
const SEARCH: usize = MAX_PHASES;

/// One joint's motion: pieces of polynomials in local time, each starting where the
/// previous ends. After the last piece the joint holds its final state. Pieces are
/// cubic (c0..c3); a quintic is a single piece whose c4, c5 live in `c45`.
///
/// Layout for sampling: slot `n` (after the last piece) holds the final state as a
/// constant "piece" [p, v, a/2, 0] starting at +∞, so its local time clamps to 0 and
/// the same Horner evaluation returns (p, v, a, 0) — no branch for "finished".
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Piecewise {
    n: usize,
    /// c4, c5 of the first piece (quintic); zero otherwise.
    c45: [f64; 2],
    /// End time of each piece (cumulative from 0); +∞ from index `n` on, so the
    /// number of ends ≤ t is the slot index (the scan stops at the padding).
    end: [f64; SEARCH],
    /// Start time of each slot (+∞ for the hold slot).
    t0: [f64; SLOTS],
    /// Coefficients c0..c3 of q(τ) = Σ cᵢ τⁱ, τ = local time in the slot.
    c: [[f64; 4]; SLOTS],
    /// Final (q, qd, qdd), returned at and after the end.
    fin: Kin,
}

impl Piecewise {
    /// A joint that holds still at `p`.
    pub const fn hold(p: f64) -> Self {
        let mut c = [[0.0; 4]; SLOTS];
        c[0][0] = p;
        Self {
            n: 0,
            c45: [0.0; 2],
            end: [f64::INFINITY; SEARCH],
            t0: [f64::INFINITY; SLOTS],
            c,
            fin: Kin { p, v: 0.0, a: 0.0 },
        }
    }

    /// Writes the hold slot (index `n`) from `fin`.
    #[inline]
    fn seal(&mut self) {
        let n = self.n.min(MAX_PHASES);
        let f = self.fin;
        self.t0[n] = f64::INFINITY;
        self.c[n] = [f.p, f.v, 0.5 * f.a, 0.0];
    }

    /// Constant-jerk phases from `start`; `fin` overrides the integrated final state
    /// (to land exactly on the target despite round-off).
    pub fn from_phases(start: Kin, phases: &Phases, fin: Option<Kin>) -> Self {
        let mut out = Self::hold(start.p);
        out.set_phases(start, phases, fin);
        out
    }

    /// In-place [`Piecewise::from_phases`] (no copy of the whole table).
    pub fn set_phases(&mut self, start: Kin, phases: &Phases, fin: Option<Kin>) {
        let n = phases.n.min(MAX_PHASES);
        let mut s = start;
        let mut t = 0.0;
        for (k, ph) in phases.p[..n].iter().enumerate() {
            self.t0[k] = t;
            t += ph.t;
            self.end[k] = t;
            self.c[k] = [s.p, s.v, 0.5 * s.a, ph.j * (1.0 / 6.0)];
            s = s.advance(ph.t, ph.j);
        }
        self.end[n..].fill(f64::INFINITY);
        self.n = n;
        self.c45 = [0.0; 2];
        self.fin = fin.unwrap_or(s);
        self.seal();
    }

    /// [`Piecewise::set_phases`] for several joints at once, phase by phase across
    /// the joints: the joints' integration chains are independent, so they overlap
    /// instead of running one long serial chain per joint.
    pub fn set_phases_many(out: &mut [Piecewise], start: &[Kin], phases: &[Phases], fin: &[Kin]) {
        let m = out.len().min(start.len()).min(phases.len()).min(fin.len());
        let (out, start, phases, fin) = (&mut out[..m], &start[..m], &phases[..m], &fin[..m]);
        let mut s = [Kin::default(); 8];
        let mut t = [0.0; 8];
        let mut n_max = 0;
        for (i, pw) in out.iter_mut().enumerate().take(8) {
            s[i] = start[i];
            pw.n = phases[i].n.min(MAX_PHASES);
            pw.end = [f64::INFINITY; SEARCH];
            pw.c45 = [0.0; 2];
            pw.fin = fin[i];
            pw.seal();
            n_max = n_max.max(pw.n);
        }
        let m = m.min(8);
        for k in 0..n_max {
            for i in 0..m {
                let ph = &phases[i];
                if k < out[i].n {
                    let p = ph.p[k];
                    let pw = &mut out[i];
                    pw.t0[k] = t[i];
                    t[i] += p.t;
                    pw.end[k] = t[i];
                    let si = s[i];
                    pw.c[k] = [si.p, si.v, 0.5 * si.a, p.j * (1.0 / 6.0)];
                    s[i] = si.advance(p.t, p.j);
                }
            }
        }
    }

    /// A single polynomial piece (degree ≤ 5) of length `t` ending in `fin`.
    pub fn polynomial(t: f64, c: [f64; 6], fin: Kin) -> Self {
        let mut out = Self::hold(fin.p);
        out.n = 1;
        out.c45 = [c[4], c[5]];
        out.end[0] = t;
        out.t0[0] = 0.0;
        out.c[0] = [c[0], c[1], c[2], c[3]];
        out.fin = fin;
        out.seal();
        out
    }

    /// Appends a cubic piece of length `t` (used by LSPB).
    pub fn push_piece(&mut self, t: f64, c: [f64; 4], fin: Kin) {
        if self.n < MAX_PHASES && t > 0.0 {
            let t0 = self.duration();
            self.t0[self.n] = t0;
            self.end[self.n] = t0 + t;
            self.c[self.n] = c;
            self.n += 1;
        }
        self.fin = fin;
        self.seal();
    }

    /// Duration of the motion.
    #[inline]
    pub fn duration(&self) -> f64 {
        if self.n == 0 {
            0.0
        } else {
            self.end[self.n - 1]
        }
    }

    /// True when the first piece has degree > 3 (a quintic).
    #[inline]
    pub fn is_quintic(&self) -> bool {
        self.c45 != [0.0; 2]
    }

    #[inline]
    fn coefficients(&self, i: usize) -> [f64; 6] {
        let c = &self.c[i];
        let h = if i == 0 { self.c45 } else { [0.0; 2] };
        [c[0], c[1], c[2], c[3], h[0], h[1]]
    }

    /// Position range [min, max] over the whole motion. Piece ends are the next
    /// piece's c0; a piece only needs its interior looked at (by `interior`) when its
    /// velocity changes sign inside it.
    pub fn position_range(&self, interior: impl Fn(&[f64; 6], f64) -> (f64, f64)) -> (f64, f64) {
        let quintic = self.is_quintic();
        if !quintic {
            return self.cubic_position_range();
        }
        let (mut lo, mut hi) = (self.fin.p, self.fin.p);
        for i in 0..self.n {
            let c = &self.c[i];
            lo = lo.min(c[0]);
            hi = hi.max(c[0]);
            let len = self.end[i] - self.t0[i];
            let monotone = !quintic && {
                // Velocity at both ends and at its extremum inside: one sign?
                let v_end = c[1] + len * (2.0 * c[2] + len * 3.0 * c[3]);
                let (mut lo_v, mut hi_v) = (c[1].min(v_end), c[1].max(v_end));
                if c[3] != 0.0 {
                    let x = -c[2] / (3.0 * c[3]);
                    if x > 0.0 && x < len {
                        let vx = c[1] + x * (2.0 * c[2] + x * 3.0 * c[3]);
                        lo_v = lo_v.min(vx);
                        hi_v = hi_v.max(vx);
                    }
                }
                lo_v >= 0.0 || hi_v <= 0.0
            };
            if !monotone {
                let (a, b) = interior(&self.coefficients(i), len);
                lo = lo.min(a);
                hi = hi.max(b);
            }
        }
        (lo, hi)
    }

    /// [`Piecewise::position_range`] of cubic pieces: q has its extremes at the piece
    /// ends (each piece's c0, and the final state) and where the velocity
    /// v(x) = c1 + 2c2·x + 3c3·x² vanishes inside a piece. A piece is skipped when v
    /// keeps one sign over it: the same sign at both ends (the next slot's c1) and no
    /// vertex of opposite sign in between.
    fn cubic_position_range(&self) -> (f64, f64) {
        let (mut lo, mut hi) = (self.fin.p, self.fin.p);
        for i in 0..self.n.min(MAX_PHASES) {
            let [c0, c1, c2, c3] = self.c[i];
            lo = lo.min(c0);
            hi = hi.max(c0);
            let v_end = self.c[i + 1][1];
            let len = self.end[i] - self.t0[i];
            let (up, down) = (c1 >= 0.0 && v_end >= 0.0, c1 <= 0.0 && v_end <= 0.0);
            if up || down {
                // One sign at both ends: v can only change sign around its vertex,
                // which lies inside when the acceleration changes sign in the piece.
                let a_end = c2 + 3.0 * c3 * len;
                if c2 * a_end >= 0.0 {
                    continue;
                }
                let xv = -c2 / (3.0 * c3);
                let vv = c1 + xv * (2.0 * c2 + xv * 3.0 * c3);
                if (up && vv >= 0.0) || (down && vv <= 0.0) {
                    continue;
                }
            }
            // Roots of 3c3·x² + 2c2·x + c1 in (0, len), by the stable quadratic formula.
            let (a, b) = (3.0 * c3, 2.0 * c2);
            let mut take = |x: f64| {
                if x > 0.0 && x < len {
                    let q = c0 + x * (c1 + x * (c2 + x * c3));
                    lo = lo.min(q);
                    hi = hi.max(q);
                }
            };
            if a == 0.0 {
                if b != 0.0 {
                    take(-c1 / b);
                }
            } else {
                let disc = (b * b - 4.0 * a * c1).max(0.0);
                let q = -0.5 * (b + b.signum() * disc.sqrt());
                if q != 0.0 {
                    take(q / a);
                    take(c1 / q);
                } else {
                    take(-b / (2.0 * a));
                }
            }
        }
        (lo, hi)
    }

    /// Final state.
    pub fn final_state(&self) -> Kin {
        self.fin
    }

    /// The pieces as (start, end, coefficients c0..c5) — for peak analysis.
    pub fn pieces(&self) -> impl Iterator<Item = (f64, f64, [f64; 6])> + '_ {
        (0..self.n).map(move |i| (self.t0[i], self.end[i], self.coefficients(i)))
    }

    /// Slot of time `t`: the number of piece ends ≤ t (0 before the first end, `n`
    /// from the last on). A plain scan: consecutive samples rarely change piece, so
    /// its branches predict well — measured faster than a branch-free binary search
    /// over the padded table, whose four dependent loads lengthen the critical path.
    #[inline(always)]
    fn slot(&self, t: f64) -> usize {
        let mut i = 0;
        while i < MAX_PHASES && t >= self.end[i] {
            i += 1;
        }
        i
    }

    /// (q, qd, qdd, jerk) of the cubic part at time `t`: exact for every profile but
    /// a quintic's first piece. Before 0 the start state, after the end the final
    /// state (local time clamps to 0 in the first and the hold slot).
    #[inline(always)]
    pub fn eval_cubic(&self, t: f64) -> [f64; 4] {
        let i = self.slot(t);
        let x = (t - self.t0[i]).max(0.0);
        let [c0, c1, c2, c3] = self.c[i];
        let (c2x2, c3x3) = (2.0 * c2, 3.0 * c3);
        [
            c0 + x * (c1 + x * (c2 + x * c3)),
            c1 + x * (c2x2 + x * c3x3),
            c2x2 + x * (6.0 * c3),
            6.0 * c3,
        ]
    }

    /// (q, qd, qdd, jerk) at time `t`; before 0 the start, after the end the final
    /// state.
    #[inline]
    pub fn eval(&self, t: f64) -> [f64; 4] {
        let [q, qd, qdd, j] = self.eval_cubic(t);
        let x = t.max(0.0);
        if !self.is_quintic() || x >= self.end[0] {
            return [q, qd, qdd, j];
        }
        let [c4, c5] = self.c45;
        let x2 = x * x;
        [
            q + x2 * x2 * (c4 + x * c5),
            qd + x2 * x * (4.0 * c4 + x * 5.0 * c5),
            qdd + x2 * (12.0 * c4 + x * 20.0 * c5),
            j + x * (24.0 * c4 + x * 60.0 * c5),
        ]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The cubic position range holds every sampled position and is reached by one
    /// (fine-grid sampling of random constant-jerk phase lists, with velocity sign
    /// changes inside pieces).
    #[test]
    fn cubic_position_range_matches_dense_sampling() {
        let mut seed = 17u64;
        let mut next = || {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (seed >> 11) as f64 / (1u64 << 53) as f64
        };
        for _ in 0..500 {
            let mut ph = Phases::default();
            for _ in 0..1 + (next() * 11.0) as usize {
                ph.push(0.05 + next(), (2.0 * next() - 1.0) * 4.0);
            }
            let start = Kin {
                p: 2.0 * next() - 1.0,
                v: 2.0 * next() - 1.0,
                a: 2.0 * next() - 1.0,
            };
            let pw = Piecewise::from_phases(start, &ph, None);
            let (lo, hi) = pw.cubic_position_range();
            let n = 20_000;
            let (mut slo, mut shi) = (f64::INFINITY, f64::NEG_INFINITY);
            for k in 0..=n {
                let q = pw.eval(pw.duration() * k as f64 / n as f64)[0];
                slo = slo.min(q);
                shi = shi.max(q);
            }
            assert!(
                lo <= slo + 1e-12 && hi >= shi - 1e-12,
                "{lo} {hi} vs {slo} {shi}"
            );
            assert!(
                slo - lo <= 1e-6 && hi - shi <= 1e-6,
                "{lo} {hi} vs {slo} {shi}"
            );
        }
    }
}
