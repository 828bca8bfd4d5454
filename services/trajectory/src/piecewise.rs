//! One joint's motion as up to [`MAX_PHASES`] polynomial pieces (degree ≤ 5).
//!
//! Every profile — a single cubic or quintic, the three LSPB pieces, the up to nine
//! constant-jerk phases of soft motion — is stored the same way, so sampling is one
//! short scan and one Horner evaluation, with no allocation.

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

/// One joint's motion: pieces of polynomials in local time, each starting where the
/// previous ends. After the last piece the joint holds its final state. Pieces are
/// cubic (c0..c3); a quintic is a single piece whose c4, c5 live in `c45`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Piecewise {
    n: usize,
    /// c4, c5 of the first piece (quintic); zero otherwise.
    c45: [f64; 2],
    /// End time of each piece (cumulative from 0); +∞ past the last piece, so the
    /// piece index is a branch-free count.
    end: [f64; MAX_PHASES],
    /// Coefficients c0..c3 of q(τ) = Σ cᵢ τⁱ, τ = local time in the piece.
    c: [[f64; 4]; MAX_PHASES],
    /// Final (q, qd, qdd), returned at and after the end.
    fin: Kin,
}

impl Piecewise {
    /// A joint that holds still at `p`.
    pub const fn hold(p: f64) -> Self {
        Self {
            n: 0,
            c45: [0.0; 2],
            end: [f64::INFINITY; MAX_PHASES],
            c: [[0.0; 4]; MAX_PHASES],
            fin: Kin { p, v: 0.0, a: 0.0 },
        }
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
        let mut s = start;
        let mut t = 0.0;
        self.n = 0;
        self.end = [f64::INFINITY; MAX_PHASES];
        self.c45 = [0.0; 2];
        for ph in &phases.p[..phases.n] {
            let i = self.n;
            t += ph.t;
            self.end[i] = t;
            self.c[i] = [s.p, s.v, 0.5 * s.a, ph.j / 6.0];
            self.n += 1;
            s = s.advance(ph.t, ph.j);
        }
        self.fin = fin.unwrap_or(s);
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
            pw.n = phases[i].n;
            pw.end = [f64::INFINITY; MAX_PHASES];
            pw.c45 = [0.0; 2];
            pw.fin = fin[i];
            n_max = n_max.max(phases[i].n);
        }
        let m = m.min(8);
        for k in 0..n_max {
            for i in 0..m {
                let ph = &phases[i];
                if k < ph.n {
                    let p = ph.p[k];
                    let pw = &mut out[i];
                    t[i] += p.t;
                    pw.end[k] = t[i];
                    let si = s[i];
                    pw.c[k] = [si.p, si.v, 0.5 * si.a, p.j / 6.0];
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
        out.c[0] = [c[0], c[1], c[2], c[3]];
        out.fin = fin;
        out
    }

    /// Appends a cubic piece of length `t` (used by LSPB).
    pub fn push_piece(&mut self, t: f64, c: [f64; 4], fin: Kin) {
        if self.n < MAX_PHASES && t > 0.0 {
            let t0 = self.duration();
            self.end[self.n] = t0 + t;
            self.c[self.n] = c;
            self.n += 1;
        }
        self.fin = fin;
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
        let (mut lo, mut hi) = (self.fin.p, self.fin.p);
        let quintic = self.c45 != [0.0; 2];
        for i in 0..self.n {
            let c = &self.c[i];
            lo = lo.min(c[0]);
            hi = hi.max(c[0]);
            let len = self.end[i] - if i == 0 { 0.0 } else { self.end[i - 1] };
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

    /// Final state.
    pub fn final_state(&self) -> Kin {
        self.fin
    }

    /// The pieces as (start, end, coefficients c0..c5) — for peak analysis.
    pub fn pieces(&self) -> impl Iterator<Item = (f64, f64, [f64; 6])> + '_ {
        (0..self.n).map(move |i| {
            let t0 = if i == 0 { 0.0 } else { self.end[i - 1] };
            (t0, self.end[i], self.coefficients(i))
        })
    }

    /// (q, qd, qdd, jerk) at time `t`; before 0 the start, after the end the final
    /// state. The piece search starts at `*hint` (the piece of the previous call) and
    /// updates it: O(1) when time moves forward in small steps; any hint is safe.
    #[inline]
    pub fn eval_from(&self, t: f64, hint: &mut usize) -> [f64; 4] {
        let mut i = (*hint).min(MAX_PHASES);
        if i > 0 && (t < self.end[i - 1] || t.is_nan()) {
            i = 0;
        }
        while i < MAX_PHASES && t >= self.end[i] {
            i += 1;
        }
        *hint = i;
        if i >= self.n {
            return [self.fin.p, self.fin.v, self.fin.a, 0.0];
        }
        let t0 = if i == 0 { 0.0 } else { self.end[i - 1] };
        let x = (t - t0).max(0.0);
        let c = &self.c[i];
        let q = c[0] + x * (c[1] + x * (c[2] + x * c[3]));
        let qd = c[1] + x * (2.0 * c[2] + x * 3.0 * c[3]);
        let qdd = 2.0 * c[2] + x * 6.0 * c[3];
        let j = 6.0 * c[3];
        if i != 0 || self.c45 == [0.0; 2] {
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
