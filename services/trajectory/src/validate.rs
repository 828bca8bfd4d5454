//! Input validation: every bad value becomes an error naming the joint and field.

use crate::{KinematicLimits, MAX_JOINTS, MotionState, TrajectoryError};

/// Tolerance for "inside the limits" checks on a start state (relative).
pub(crate) const LIMIT_TOL: f64 = 1e-9;

pub(crate) fn dof(dof: usize) -> Result<(), TrajectoryError> {
    if dof == 0 || dof > MAX_JOINTS {
        Err(TrajectoryError::BadDof(dof))
    } else {
        Ok(())
    }
}

pub(crate) fn finite(joint: usize, field: &'static str, value: f64) -> Result<(), TrajectoryError> {
    if value.is_finite() {
        Ok(())
    } else {
        Err(TrajectoryError::NotFinite {
            joint,
            field,
            value,
        })
    }
}

pub(crate) fn positive(
    joint: usize,
    field: &'static str,
    value: f64,
) -> Result<(), TrajectoryError> {
    finite(joint, field, value)?;
    if value > 0.0 {
        Ok(())
    } else {
        Err(TrajectoryError::NotPositive {
            joint,
            field,
            value,
        })
    }
}

/// A duration (reported on joint 0).
pub(crate) fn duration(field: &'static str, value: f64) -> Result<(), TrajectoryError> {
    positive(0, field, value)
}

pub(crate) fn limits(dof: usize, l: &KinematicLimits) -> Result<(), TrajectoryError> {
    for i in 0..dof {
        positive(i, "limits.velocity", l.velocity[i])?;
        positive(i, "limits.acceleration", l.acceleration[i])?;
        positive(i, "limits.jerk", l.jerk[i])?;
        finite(i, "limits.position_min", l.position_min[i])?;
        finite(i, "limits.position_max", l.position_max[i])?;
        if l.position_min[i] > l.position_max[i] {
            return Err(TrajectoryError::OutOfRange {
                joint: i,
                field: "limits.position_min",
                value: l.position_min[i],
                min: f64::NEG_INFINITY,
                max: l.position_max[i],
            });
        }
    }
    Ok(())
}

fn within(
    joint: usize,
    field: &'static str,
    value: f64,
    bound: f64,
) -> Result<(), TrajectoryError> {
    if value.abs() > bound * (1.0 + LIMIT_TOL) {
        Err(TrajectoryError::OutOfRange {
            joint,
            field,
            value,
            min: -bound,
            max: bound,
        })
    } else {
        Ok(())
    }
}

fn position(
    joint: usize,
    field: &'static str,
    q: f64,
    l: &KinematicLimits,
) -> Result<(), TrajectoryError> {
    let (lo, hi) = (l.position_min[joint], l.position_max[joint]);
    let tol = LIMIT_TOL * (hi - lo).abs().max(1.0);
    if q < lo - tol || q > hi + tol {
        Err(TrajectoryError::OutOfRange {
            joint,
            field,
            value: q,
            min: lo,
            max: hi,
        })
    } else {
        Ok(())
    }
}

/// Finite values; positions inside the limits; |qd|, |qdd| inside the limits when
/// `check_dynamics`.
pub(crate) fn state(
    dof: usize,
    s: &MotionState,
    l: &KinematicLimits,
    which: [&'static str; 3],
    check_dynamics: bool,
) -> Result<(), TrajectoryError> {
    for i in 0..dof {
        finite(i, which[0], s.q[i])?;
        finite(i, which[1], s.qd[i])?;
        finite(i, which[2], s.qdd[i])?;
        position(i, which[0], s.q[i], l)?;
        if check_dynamics {
            within(i, which[1], s.qd[i], l.velocity[i])?;
            within(i, which[2], s.qdd[i], l.acceleration[i])?;
        }
    }
    Ok(())
}

/// True when [`limits`] and [`state`] (start with `check_dynamics`, target without)
/// would all pass: the same conditions, evaluated without early exits (NaN fails every
/// comparison). A fast path only: on `false` the callers run the checks that name the
/// joint and field.
pub(crate) fn all_ok(
    dof: usize,
    l: &KinematicLimits,
    start: &MotionState,
    target: &MotionState,
    check_dynamics: bool,
) -> bool {
    let mut ok = dof <= MAX_JOINTS;
    for i in 0..dof.min(MAX_JOINTS) {
        let (v, a, j) = (l.velocity[i], l.acceleration[i], l.jerk[i]);
        let (lo, hi) = (l.position_min[i], l.position_max[i]);
        ok &= (v > 0.0) & (a > 0.0) & (j > 0.0);
        ok &= v.is_finite() & a.is_finite() & j.is_finite() & lo.is_finite() & hi.is_finite();
        ok &= lo <= hi;
        let tol = LIMIT_TOL * (hi - lo).abs().max(1.0);
        for s in [start, target] {
            ok &= (s.q[i] >= lo - tol) & (s.q[i] <= hi + tol);
            ok &= s.qd[i].is_finite() & s.qdd[i].is_finite();
        }
        if check_dynamics {
            ok &= start.qd[i].abs() <= v * (1.0 + LIMIT_TOL);
            ok &= start.qdd[i].abs() <= a * (1.0 + LIMIT_TOL);
        }
    }
    ok
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The fast path agrees with the field-by-field checks on requests with one value
    /// replaced by something bad or borderline.
    #[test]
    fn all_ok_agrees_with_the_detailed_checks() {
        let bad = [
            f64::NAN,
            f64::INFINITY,
            -f64::INFINITY,
            0.0,
            -1.0,
            1e9,
            1.0 + 1e-12,
            2.0,
        ];
        let base_l = KinematicLimits::uniform(1.0, 2.0, 3.0, -1.0, 1.0);
        let base_s = MotionState {
            q: crate::JointVector::repeat(0.5),
            qd: crate::JointVector::repeat(0.5),
            qdd: crate::JointVector::repeat(-1.0),
        };
        let mut n = 0;
        for field in 0..11 {
            for &x in &bad {
                for joint in [0, 3] {
                    for dynamics in [false, true] {
                        let (mut l, mut s, mut t) = (base_l, base_s, base_s);
                        match field {
                            0 => l.velocity[joint] = x,
                            1 => l.acceleration[joint] = x,
                            2 => l.jerk[joint] = x,
                            3 => l.position_min[joint] = x,
                            4 => l.position_max[joint] = x,
                            5 => s.q[joint] = x,
                            6 => s.qd[joint] = x,
                            7 => s.qdd[joint] = x,
                            8 => t.q[joint] = x,
                            9 => t.qd[joint] = x,
                            _ => t.qdd[joint] = x,
                        }
                        let detailed = limits(4, &l).is_ok()
                            && state(4, &s, &l, ["s.q", "s.qd", "s.qdd"], dynamics).is_ok()
                            && state(4, &t, &l, ["t.q", "t.qd", "t.qdd"], false).is_ok();
                        assert_eq!(
                            all_ok(4, &l, &s, &t, dynamics),
                            detailed,
                            "field {field} = {x} on joint {joint}, dynamics {dynamics}"
                        );
                        n += usize::from(!detailed);
                    }
                }
            }
        }
        assert!(n > 100, "only {n} bad requests");
    }
}
