//! [`Trajectory`]: a planned, synchronised multi-joint motion, sampled allocation-free.

use crate::piecewise::{Kin, Piecewise};
use crate::{
    JointVector, KinematicLimits, MAX_JOINTS, MotionRequest, Profile, Sample, TrajectoryError,
    lspb, peaks, polynomial, sync, validate,
};

/// A synchronised multi-joint motion. All planning happens in [`Trajectory::plan`];
/// the value is `Copy` (no heap) and sampling never allocates.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Trajectory {
    dof: usize,
    duration: f64,
    braked: bool,
    /// Some joint's first piece is a quintic (degree 5): sampling takes the general path.
    quintic: bool,
    joints: [Piecewise; MAX_JOINTS],
}

/// Peak values of a trajectory per joint, to compare with limits.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Peaks {
    /// Lowest position reached.
    pub position_min: JointVector,
    /// Highest position reached.
    pub position_max: JointVector,
    /// max |qd|.
    pub velocity: JointVector,
    /// max |qdd|.
    pub acceleration: JointVector,
    /// max |jerk| inside pieces (jumps of qdd, as in cubic and LSPB, are not counted).
    pub jerk: JointVector,
}

impl Trajectory {
    /// Plans `req`. Errors name the joint and the field; never panics.
    ///
    /// Cubic, quintic and LSPB take the requested duration (their peaks are reported
    /// by [`Trajectory::peaks`] and checked by [`Trajectory::check_limits`]; use
    /// [`minimum_duration`] to get the shortest duration within the limits). Soft
    /// motion is time-optimal within vmax, amax, jmax from any start state inside the
    /// limits, synchronised so all joints finish together (see `sync`). Every profile
    /// must stay inside the position limits.
    pub fn plan(req: &MotionRequest) -> Result<Trajectory, TrajectoryError> {
        let mut traj = Trajectory::empty();
        traj.plan_into(req)?;
        Ok(traj)
    }

    /// A trajectory of no joints, to [`Trajectory::plan_into`] later.
    pub const fn empty() -> Trajectory {
        Trajectory {
            dof: 0,
            duration: 0.0,
            braked: false,
            quintic: false,
            joints: [Piecewise::hold(0.0); MAX_JOINTS],
        }
    }

    /// [`Trajectory::plan`] into an existing value, without moving the ~4 kB joint
    /// table (what a planner loop replanning every cycle wants). On error `self` is
    /// emptied (dof 0), so keep the running trajectory in another slot.
    pub fn plan_into(&mut self, req: &MotionRequest) -> Result<(), TrajectoryError> {
        let r = self.plan_inner(req);
        if r.is_err() {
            self.dof = 0;
            self.duration = 0.0;
        }
        r
    }

    fn plan_inner(&mut self, req: &MotionRequest) -> Result<(), TrajectoryError> {
        let dof = req.dof;
        validate::dof(dof)?;
        let soft = matches!(req.profile, Profile::Soft { .. });
        // One branch-free pass over everything; the field-by-field checks (which name
        // the first bad joint and field) run only when it finds a problem.
        if !validate::all_ok(dof, &req.limits, &req.start, &req.target, soft) {
            validate::limits(dof, &req.limits)?;
            validate::state(
                dof,
                &req.start,
                &req.limits,
                ["start.q", "start.qd", "start.qdd"],
                soft,
            )?;
            validate::state(
                dof,
                &req.target,
                &req.limits,
                ["target.q", "target.qd", "target.qdd"],
                false,
            )?;
        }
        let (s, g) = (&req.start, &req.target);
        let joints = &mut self.joints;
        let mut braked = false;
        // Rest-to-rest soft motions are monotone between validated positions.
        let mut monotone = false;
        let duration = match req.profile {
            Profile::Cubic { duration: t } => {
                validate::duration("profile.duration", t)?;
                for i in 0..dof {
                    let c = polynomial::cubic_coefficients(s.q[i], g.q[i], s.qd[i], g.qd[i], t);
                    let a1 = 2.0 * c[2] + 6.0 * c[3] * t;
                    let fin = Kin {
                        p: g.q[i],
                        v: g.qd[i],
                        a: a1,
                    };
                    joints[i] = Piecewise::polynomial(t, [c[0], c[1], c[2], c[3], 0.0, 0.0], fin);
                }
                t
            }
            Profile::Quintic { duration: t } => {
                validate::duration("profile.duration", t)?;
                for i in 0..dof {
                    let c = polynomial::quintic_coefficients(
                        s.q[i], g.q[i], s.qd[i], g.qd[i], s.qdd[i], g.qdd[i], t,
                    );
                    let fin = Kin {
                        p: g.q[i],
                        v: g.qd[i],
                        a: g.qdd[i],
                    };
                    joints[i] = Piecewise::polynomial(t, c, fin);
                }
                t
            }
            Profile::Lspb {
                duration: t,
                cruise_velocity,
            } => {
                validate::duration("profile.duration", t)?;
                for i in 0..dof {
                    for (field, x) in [
                        ("start.qd", s.qd[i]),
                        ("start.qdd", s.qdd[i]),
                        ("target.qd", g.qd[i]),
                        ("target.qdd", g.qdd[i]),
                    ] {
                        if x != 0.0 {
                            return Err(TrajectoryError::Unsupported {
                                joint: i,
                                field,
                                reason: "LSPB starts and ends at rest",
                            });
                        }
                    }
                    let v = match cruise_velocity {
                        Some(v) => {
                            validate::finite(i, "profile.cruise_velocity", v[i])?;
                            v[i]
                        }
                        None => lspb::default_cruise_velocity(s.q[i], g.q[i], t),
                    };
                    lspb::check_cruise_velocity(s.q[i], g.q[i], t, v).map_err(|reason| {
                        TrajectoryError::Unsupported {
                            joint: i,
                            field: "profile.cruise_velocity",
                            reason,
                        }
                    })?;
                    joints[i] = lspb::piecewise(s.q[i], g.q[i], t, v);
                }
                t
            }
            Profile::Soft { min_duration } => {
                if let Some(t) = min_duration {
                    validate::duration("profile.min_duration", t)?;
                }
                let (duration, b, rest) =
                    sync::plan_soft(dof, s, &g.q, &req.limits, min_duration, joints);
                braked = b;
                monotone = rest;
                duration
            }
        };
        self.dof = dof;
        self.duration = duration;
        self.braked = braked;
        self.quintic = self.joints[..dof].iter().any(Piecewise::is_quintic);
        if monotone {
            return Ok(());
        }
        self.check_positions(&req.limits)
    }

    /// A trajectory that holds `q` forever (duration 0).
    pub fn hold(dof: usize, q: &JointVector) -> Result<Trajectory, TrajectoryError> {
        validate::dof(dof)?;
        let mut joints = [Piecewise::hold(0.0); MAX_JOINTS];
        for i in 0..dof {
            validate::finite(i, "q", q[i])?;
            joints[i] = Piecewise::hold(q[i]);
        }
        Ok(Trajectory {
            dof,
            duration: 0.0,
            braked: false,
            quintic: false,
            joints,
        })
    }

    pub(crate) fn from_parts(
        dof: usize,
        duration: f64,
        braked: bool,
        joints: [Piecewise; MAX_JOINTS],
    ) -> Self {
        Trajectory {
            dof,
            duration,
            braked,
            quintic: joints[..dof.min(MAX_JOINTS)]
                .iter()
                .any(Piecewise::is_quintic),
            joints,
        }
    }

    /// Number of active joints.
    pub fn dof(&self) -> usize {
        self.dof
    }

    /// Duration of the motion (s); all joints are at their targets from then on.
    pub fn duration(&self) -> f64 {
        self.duration
    }

    /// True when soft motion first had to brake back under vmax (or amax).
    pub fn braked(&self) -> bool {
        self.braked
    }

    /// Position, velocity, acceleration and jerk of every joint at time `t` (s).
    /// Before 0: the start state; from the end on: the final state with zero jerk.
    /// Allocation-free, division-free: per joint a short scan over its piece ends
    /// and one cubic Horner evaluation.
    #[inline]
    pub fn sample(&self, t: f64) -> Sample {
        let mut out = Sample::default();
        self.write_sample(t, &mut out);
        out
    }

    /// [`Trajectory::sample`] written into `out` (every lane; those past `dof` are
    /// zeroed): no 256-byte zeroing and copy of a returned value, for loops that keep
    /// one `Sample` per cycle.
    #[inline]
    pub fn sample_into(&self, t: f64, out: &mut Sample) {
        // Lanes past dof are usually zero already (same trajectory shape every
        // cycle): check instead of storing (and no memset call for a few lanes).
        for k in self.dof.min(MAX_JOINTS)..MAX_JOINTS {
            for v in [&mut out.q, &mut out.qd, &mut out.qdd, &mut out.jerk] {
                if v[k] != 0.0 {
                    v[k] = 0.0;
                }
            }
        }
        self.write_sample(t, out);
    }

    /// Writes lanes 0..dof of `out` (q, qd, qdd, jerk at `t`).
    #[inline(always)]
    fn write_sample(&self, t: f64, out: &mut Sample) {
        let n = self.dof.min(MAX_JOINTS);
        let joints = &self.joints[..n];
        let (q, qd) = (out.q.as_mut_slice(), out.qd.as_mut_slice());
        let (qdd, jerk) = (out.qdd.as_mut_slice(), out.jerk.as_mut_slice());
        if t >= self.duration {
            // From the common end on, every joint reports its exact final state.
            for (i, pw) in joints.iter().enumerate() {
                let f = pw.final_state();
                q[i] = f.p;
                qd[i] = f.v;
                qdd[i] = f.a;
                jerk[i] = 0.0;
            }
        } else if self.quintic {
            for (i, pw) in joints.iter().enumerate() {
                [q[i], qd[i], qdd[i], jerk[i]] = pw.eval(t);
            }
        } else {
            for (i, pw) in joints.iter().enumerate() {
                [q[i], qd[i], qdd[i], jerk[i]] = pw.eval_cubic(t);
            }
        }
    }

    /// [`Trajectory::sample`]. The per-joint piece hints are no longer needed (the
    /// piece search is branch-free); they are accepted and left as they are.
    #[inline]
    pub fn sample_from(&self, t: f64, _hints: &mut [usize; MAX_JOINTS]) -> Sample {
        self.sample(t)
    }

    /// Peak values per joint (computed on demand; not for the hot path).
    pub fn peaks(&self) -> Peaks {
        let mut p = Peaks::default();
        for i in 0..self.dof {
            let [qlo, qhi, v, a, j] = peaks::extremes(&self.joints[i]);
            p.position_min[i] = qlo;
            p.position_max[i] = qhi;
            p.velocity[i] = v;
            p.acceleration[i] = a;
            p.jerk[i] = j;
        }
        p
    }

    /// Checks peak |qd|, |qdd| (and |jerk| when `check_jerk`, e.g. for quintic) and
    /// positions against `limits` (1e-9 relative tolerance); the error names the
    /// first offending joint and field.
    pub fn check_limits(
        &self,
        limits: &KinematicLimits,
        check_jerk: bool,
    ) -> Result<(), TrajectoryError> {
        let p = self.peaks();
        self.check_positions(limits)?;
        for i in 0..self.dof {
            let checks = [
                ("limits.velocity", p.velocity[i], limits.velocity[i]),
                (
                    "limits.acceleration",
                    p.acceleration[i],
                    limits.acceleration[i],
                ),
                (
                    "limits.jerk",
                    if check_jerk { p.jerk[i] } else { 0.0 },
                    limits.jerk[i],
                ),
            ];
            for (field, peak, lim) in checks {
                if peak > lim * (1.0 + validate::LIMIT_TOL) {
                    return Err(TrajectoryError::OutOfRange {
                        joint: i,
                        field,
                        value: peak,
                        min: -lim,
                        max: lim,
                    });
                }
            }
        }
        Ok(())
    }

    fn check_positions(&self, limits: &KinematicLimits) -> Result<(), TrajectoryError> {
        for i in 0..self.dof {
            let (lo, hi) = peaks::position_range(&self.joints[i]);
            let (pmin, pmax) = (limits.position_min[i], limits.position_max[i]);
            let tol = validate::LIMIT_TOL * (pmax - pmin).abs().max(1.0);
            if lo < pmin - tol {
                return Err(TrajectoryError::PositionOverrun {
                    joint: i,
                    field: "limits.position_min",
                    reached: lo,
                    limit: pmin,
                });
            }
            if hi > pmax + tol {
                return Err(TrajectoryError::PositionOverrun {
                    joint: i,
                    field: "limits.position_max",
                    reached: hi,
                    limit: pmax,
                });
            }
        }
        Ok(())
    }
}

/// Shortest duration of `req`'s profile within `req.limits` (the seed's "optimal
/// planning"): v and a for cubic and LSPB (their jerk is unbounded), v, a and jerk
/// for quintic, the time-optimal duration for soft motion. The duration inside
/// `req.profile` is ignored. Polynomials: bisection on T to 1e-12 relative.
pub fn minimum_duration(req: &MotionRequest) -> Result<f64, TrajectoryError> {
    match req.profile {
        Profile::Soft { .. } => {
            let mut r = *req;
            r.profile = Profile::Soft { min_duration: None };
            Ok(Trajectory::plan(&r)?.duration())
        }
        Profile::Lspb { .. } => {
            validate::dof(req.dof)?;
            validate::limits(req.dof, &req.limits)?;
            let mut t = 0.0f64;
            for i in 0..req.dof {
                let h = (req.target.q[i] - req.start.q[i]).abs();
                validate::finite(i, "target.q", h)?;
                let (v, a) = (req.limits.velocity[i], req.limits.acceleration[i]);
                let ti = if h >= v * v / a {
                    h / v + v / a
                } else {
                    2.0 * (h / a).sqrt()
                };
                t = t.max(ti);
            }
            Ok(t)
        }
        Profile::Cubic { .. } | Profile::Quintic { .. } => {
            let quintic = matches!(req.profile, Profile::Quintic { .. });
            let with = |t: f64| {
                let mut r = *req;
                r.profile = if quintic {
                    Profile::Quintic { duration: t }
                } else {
                    Profile::Cubic { duration: t }
                };
                Trajectory::plan(&r)
            };
            let feasible = |t: f64| with(t).map(|tr| tr.check_limits(&req.limits, quintic).is_ok());
            let mut hi = 1e-3;
            let mut n = 0;
            while !feasible(hi)? {
                hi *= 2.0;
                n += 1;
                if n > 80 {
                    return Err(TrajectoryError::Unsupported {
                        joint: 0,
                        field: "start",
                        reason: "no duration respects the limits (boundary velocity or acceleration too high)",
                    });
                }
            }
            let mut lo = if n == 0 { 0.0 } else { hi * 0.5 };
            while hi - lo > 1e-12 * hi {
                let m = 0.5 * (lo + hi);
                if feasible(m).unwrap_or(false) {
                    hi = m
                } else {
                    lo = m
                }
            }
            Ok(hi)
        }
    }
}
