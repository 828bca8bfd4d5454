//! The shortest jerk-limited stop from any state, for stop and e-stop.

use crate::piecewise::{Kin, Piecewise};
use crate::soft::{brake::brake, velocity::velocity_change};
use crate::sync::limits1;
use crate::{KinematicLimits, MAX_JOINTS, MotionState, Trajectory, TrajectoryError, validate};

/// Shortest jerk-limited stop from `start`: every joint independently (NOT
/// synchronised — each stops as fast as it can) to zero velocity and acceleration,
/// within its limits after an unavoidable brake when |a| > amax or the velocity limit
/// is bound to be crossed. The trajectory's duration is that of the slowest joint.
/// Errors only on bad input (dof, non-finite values, bad limits); the start may be
/// outside the limits and the stop is not refused for overrunning a position limit —
/// stopping is always the safest thing to do.
pub fn stop_trajectory(
    dof: usize,
    start: &MotionState,
    limits: &KinematicLimits,
) -> Result<Trajectory, TrajectoryError> {
    validate::dof(dof)?;
    validate::limits(dof, limits)?;
    let mut joints = [Piecewise::hold(0.0); MAX_JOINTS];
    let (mut duration, mut braked) = (0.0f64, false);
    for i in 0..dof {
        validate::finite(i, "start.q", start.q[i])?;
        validate::finite(i, "start.qd", start.qd[i])?;
        validate::finite(i, "start.qdd", start.qdd[i])?;
        let lim = limits1(limits, i);
        let k0 = Kin {
            p: start.q[i],
            v: start.qd[i],
            a: start.qdd[i],
        };
        let mut ph = brake(k0, &lim);
        braked |= ph.n > 0;
        let k1 = ph.integrate(k0);
        ph.extend(&velocity_change(k1.v, k1.a, 0.0, &lim));
        let pw = Piecewise::from_phases(k0, &ph, None);
        let fin = pw.final_state();
        joints[i] = Piecewise::from_phases(
            k0,
            &ph,
            Some(Kin {
                p: fin.p,
                v: 0.0,
                a: 0.0,
            }),
        );
        duration = duration.max(pw.duration());
    }
    Ok(Trajectory::from_parts(dof, duration, braked, joints))
}
