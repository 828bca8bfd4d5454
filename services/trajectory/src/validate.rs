//! Input validation: every bad value becomes an error naming the joint and field.

use crate::{JointState, KinematicLimits, MAX_JOINTS, TrajectoryError};

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
    s: &JointState,
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
