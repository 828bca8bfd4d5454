//! Inverse kinematics by damped least squares (Levenberg-Marquardt): a full
//! pose or a position-only target, joint limits honoured by clamping every step,
//! damping that grows near singularities and with redundancy, random restarts
//! inside the limits, and an honest report of the residual.

use crate::data::ModelData;
use crate::kinematics::{jacobian_from_frames, update_kinematics};
use crate::robot::Robot;
use crate::{Jacobian, JointVector};
use nalgebra::{Isometry3, Matrix3, Matrix6, Rotation3, SVector, Vector3};

/// What the tool should reach.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum IkTarget {
    /// Tool frame pose in the base frame (position and orientation).
    Pose(Isometry3<f64>),
    /// Tool origin position in the base frame, m; orientation free.
    Position(Vector3<f64>),
}

/// Solver settings; [`Default`] suits arms of a few centimetres to a metre.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct IkOptions {
    /// Iteration budget per attempt.
    pub max_iterations: usize,
    /// Converged when the position error is below this, m.
    pub position_tolerance_m: f64,
    /// Converged when the orientation error is below this, rad (pose targets).
    pub orientation_tolerance_rad: f64,
    /// Initial Levenberg-Marquardt damping λ (in metres, the unit of the
    /// weighted error).
    pub initial_damping: f64,
    /// Length that converts orientation error to the position scale, m/rad;
    /// `None` uses the arm's reach.
    pub orientation_weight_m: Option<f64>,
    /// Extra attempts from pseudo-random seeds inside the limits after the first
    /// attempt (from the caller's seed) fails.
    pub restarts: usize,
    /// Seed of the restart generator (results are reproducible).
    pub restart_seed: u64,
}

impl Default for IkOptions {
    fn default() -> Self {
        IkOptions {
            max_iterations: 200,
            position_tolerance_m: 1e-9,
            orientation_tolerance_rad: 1e-9,
            initial_damping: 1e-3,
            orientation_weight_m: None,
            restarts: 8,
            restart_seed: 0x5eed,
        }
    }
}

/// Outcome of a solve. `q` is the best configuration found (within the joint
/// limits) even when `converged` is false; the errors are its true residuals.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct IkSolution {
    /// Joint positions (zero beyond `dof`).
    pub q: JointVector,
    /// Both residuals below their tolerances.
    pub converged: bool,
    /// Iterations used, over all attempts.
    pub iterations: usize,
    /// Distance from the tool origin to the target position, m.
    pub position_error_m: f64,
    /// Rotation angle between tool and target orientation, rad (0 for
    /// position-only targets).
    pub orientation_error_rad: f64,
}

/// Inputs the solver refuses.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum IkError {
    /// The target contains NaN or infinity.
    #[error("IK target is not finite")]
    NonFiniteTarget,
    /// The seed configuration contains NaN or infinity (first offending index).
    #[error("IK seed q[{0}] is not finite")]
    NonFiniteSeed(usize),
    /// A tolerance or the damping is not a positive finite number.
    #[error("IK option {0} must be positive and finite")]
    BadOption(&'static str),
}

/// Weighted task error of the current frames: position error, then orientation
/// error (axis-angle of `R_target R_toolᵀ`) times `weight`.
fn task_error(data: &ModelData, target: &IkTarget, weight: f64) -> (SVector<f64, 6>, f64, f64) {
    let tool = data.tool_frame();
    let mut e = SVector::<f64, 6>::zeros();
    match target {
        IkTarget::Position(p) => {
            let dp = p - tool.translation;
            e.fixed_rows_mut::<3>(0).copy_from(&dp);
            (e, dp.norm(), 0.0)
        }
        IkTarget::Pose(iso) => {
            let dp = iso.translation.vector - tool.translation;
            let r_t: Matrix3<f64> = *iso.rotation.to_rotation_matrix().matrix();
            let w = rotation_error(&(r_t * tool.rotation.transpose()));
            e.fixed_rows_mut::<3>(0).copy_from(&dp);
            e.fixed_rows_mut::<3>(3).copy_from(&(w * weight));
            (e, dp.norm(), w.norm())
        }
    }
}

/// The rotation vector θ·axis of the rotation matrix `r`, accurate to rounding at
/// small angles: θ = atan2(|v|, (tr r − 1)/2) with v = vee(r − rᵀ)/2 = sin θ · axis.
/// (`acos((tr r − 1)/2)`, as nalgebra's `scaled_axis` computes θ, cannot resolve angles
/// below ~2e-8 rad, which kept IK from converging to its 1e-9 rad tolerance.)
/// Beyond 90° the skew part loses the axis; nalgebra's form is exact enough there.
fn rotation_error(r: &Matrix3<f64>) -> Vector3<f64> {
    let v = 0.5
        * Vector3::new(
            r[(2, 1)] - r[(1, 2)],
            r[(0, 2)] - r[(2, 0)],
            r[(1, 0)] - r[(0, 1)],
        );
    let c = 0.5 * (r.trace() - 1.0);
    if c < 0.0 {
        return Rotation3::from_matrix_unchecked(*r).scaled_axis();
    }
    let s = v.norm();
    if s == 0.0 {
        return Vector3::zeros();
    }
    v * (s.atan2(c) / s)
}

/// Splitmix64: a tiny reproducible generator for restart seeds.
fn splitmix(state: &mut u64) -> f64 {
    *state = state.wrapping_add(0x9e37_79b9_7f4a_7c15);
    let mut z = *state;
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^= z >> 31;
    (z >> 11) as f64 / (1u64 << 53) as f64
}

/// Rough reach of the arm: sum of link lengths, offsets and prismatic travel.
fn reach(robot: &Robot) -> f64 {
    let mut r = robot.tool().translation.norm();
    for j in robot.joints() {
        r += match &j.placement {
            Some(p) => p.origin.translation.norm(),
            None => j.dh.a.abs() + j.dh.d.abs(),
        };
        if j.kind == crate::JointKind::Prismatic {
            r += j.limits.min.abs().max(j.limits.max.abs());
        }
    }
    r.max(1e-3)
}

/// Checks the target, the seed and the options; returns the orientation weight (m/rad).
fn validate(
    robot: &Robot,
    target: &IkTarget,
    seed: &JointVector,
    options: &IkOptions,
) -> Result<f64, IkError> {
    let finite_target = match target {
        IkTarget::Position(p) => p.iter().all(|x| x.is_finite()),
        IkTarget::Pose(iso) => {
            iso.translation.vector.iter().all(|x| x.is_finite())
                && iso.rotation.coords.iter().all(|x| x.is_finite())
        }
    };
    if !finite_target {
        return Err(IkError::NonFiniteTarget);
    }
    let n = robot.dof();
    if let Some(i) = (0..n).find(|&i| !seed[i].is_finite()) {
        return Err(IkError::NonFiniteSeed(i));
    }
    for (name, v) in [
        ("position_tolerance_m", options.position_tolerance_m),
        (
            "orientation_tolerance_rad",
            options.orientation_tolerance_rad,
        ),
        ("initial_damping", options.initial_damping),
    ] {
        if !(v > 0.0 && v.is_finite()) {
            return Err(IkError::BadOption(name));
        }
    }
    match options.orientation_weight_m {
        Some(w) if w > 0.0 && w.is_finite() => Ok(w),
        Some(_) => Err(IkError::BadOption("orientation_weight_m")),
        None => Ok(reach(robot)),
    }
}

/// Solves for joint positions reaching `target`, starting from `seed`.
///
/// Each iteration solves `(J Jᵀ + λ² 1) y = e`, steps `Δq = Jᵀ y` (damped least
/// squares over the selected rows), clamps into the limits and keeps the step
/// only if the error drops (λ shrinks) — otherwise λ grows and the step is
/// retried. Rank deficiency (redundancy, collinear axes, singular poses) only
/// makes `J Jᵀ` singular, which λ² keeps invertible. If an attempt ends without
/// convergence, up to `options.restarts` attempts start from pseudo-random
/// configurations. The best configuration found is returned either way.
pub fn solve(
    robot: &Robot,
    data: &mut ModelData,
    target: &IkTarget,
    seed: &JointVector,
    options: &IkOptions,
) -> Result<IkSolution, IkError> {
    let weight = validate(robot, target, seed, options)?;
    let n = robot.dof();
    let joints = robot.joints();

    let mut best: Option<IkSolution> = None;
    let mut total_iterations = 0;
    let mut rng = options.restart_seed;
    for attempt in 0..=options.restarts {
        let mut q = JointVector::zeros();
        for i in 0..n {
            let l = &joints[i].limits;
            q[i] = if attempt == 0 {
                l.clamp(seed[i])
            } else {
                let u = splitmix(&mut rng);
                l.min + u * (l.max - l.min)
            };
        }
        let sol = attempt_solve(robot, data, target, q, options, weight);
        total_iterations += sol.iterations;
        let better = match &best {
            None => true,
            Some(b) => {
                (sol.converged && !b.converged)
                    || (sol.converged == b.converged
                        && sol.position_error_m + sol.orientation_error_rad * weight
                            < b.position_error_m + b.orientation_error_rad * weight)
            }
        };
        if better {
            best = Some(sol);
        }
        if sol.converged {
            break;
        }
    }
    let mut out = best.unwrap_or(IkSolution {
        q: *seed,
        converged: false,
        iterations: 0,
        position_error_m: f64::INFINITY,
        orientation_error_rad: f64::INFINITY,
    });
    out.iterations = total_iterations;
    Ok(out)
}

/// The per-cycle entry point (teleoperation, tracking): damped least squares from
/// `seed` only — no random restarts, so the solution stays on the seed's branch and
/// never flips configuration by itself — within `options.max_iterations`. Allocates
/// nothing. `q` is the seed's best improvement even when not converged (at the edge
/// of the workspace it is the closest point the local descent reaches).
pub fn solve_local(
    robot: &Robot,
    data: &mut ModelData,
    target: &IkTarget,
    seed: &JointVector,
    options: &IkOptions,
) -> Result<IkSolution, IkError> {
    let weight = validate(robot, target, seed, options)?;
    let mut q = JointVector::zeros();
    for (i, j) in robot.joints().iter().enumerate() {
        q[i] = j.limits.clamp(seed[i]);
    }
    Ok(attempt_solve(robot, data, target, q, options, weight))
}

fn attempt_solve(
    robot: &Robot,
    data: &mut ModelData,
    target: &IkTarget,
    mut q: JointVector,
    options: &IkOptions,
    weight: f64,
) -> IkSolution {
    let n = robot.dof();
    let joints = robot.joints();
    let rows = match target {
        IkTarget::Position(_) => 3,
        IkTarget::Pose(_) => 6,
    };
    update_kinematics(robot, data, &q);
    let (mut e, mut pos_err, mut ori_err) = task_error(data, target, weight);
    let mut lambda = options.initial_damping;
    let mut revolute_full_turn = [false; crate::MAX_JOINTS];
    for (i, j) in robot.joints().iter().enumerate() {
        revolute_full_turn[i] = j.kind == crate::JointKind::Revolute
            && j.limits.max - j.limits.min >= 2.0 * std::f64::consts::PI - 1e-9;
    }
    let mut iterations = 0;
    let converged =
        |p: f64, o: f64| p < options.position_tolerance_m && o < options.orientation_tolerance_rad;
    while iterations < options.max_iterations && !converged(pos_err, ori_err) {
        iterations += 1;
        let mut jac: Jacobian = jacobian_from_frames(robot, data);
        for r in 3..6 {
            for c in 0..n {
                jac[(r, c)] *= weight;
            }
        }
        if rows == 3 {
            jac.fixed_rows_mut::<3>(3).fill(0.0);
        }
        // Joints resting on a limit and pushed outwards are locked for this
        // iteration (a one-step active set), so the others take up the motion.
        {
            let e_dir = jac.transpose() * e;
            for i in 0..n {
                let at_min = q[i] <= joints[i].limits.min && e_dir[i] < 0.0;
                let at_max = q[i] >= joints[i].limits.max && e_dir[i] > 0.0;
                if (at_min || at_max) && !revolute_full_turn[i] {
                    jac.column_mut(i).fill(0.0);
                }
            }
        }
        let jjt: Matrix6<f64> = jac * jac.transpose();
        let mut accepted = false;
        while lambda < 1e6 {
            let mut a = jjt + Matrix6::identity() * (lambda * lambda);
            if rows == 3 {
                // Unused rows: keep the system well posed without coupling.
                for r in 3..6 {
                    a[(r, r)] = 1.0;
                }
            }
            let Some(chol) = a.cholesky() else {
                lambda *= 4.0;
                continue;
            };
            let y = chol.solve(&e);
            let dq = jac.transpose() * y;
            let q_new = step_within_limits(&q, &dq, joints, &revolute_full_turn);
            update_kinematics(robot, data, &q_new);
            let (e_new, p_new, o_new) = task_error(data, target, weight);
            if e_new.norm() < e.norm() {
                q = q_new;
                e = e_new;
                pos_err = p_new;
                ori_err = o_new;
                lambda = (lambda * 0.3).max(1e-12);
                accepted = true;
                break;
            }
            lambda *= 4.0;
        }
        if !accepted {
            // No damping improves the error: a local minimum (or the boundary
            // of the reachable set); restore the frames of q and stop.
            update_kinematics(robot, data, &q);
            break;
        }
    }
    IkSolution {
        q,
        converged: converged(pos_err, ori_err),
        iterations,
        position_error_m: pos_err,
        orientation_error_rad: ori_err,
    }
}

/// `q + dq` kept inside the limits: clamped, except that a revolute joint whose
/// range spans a full turn wraps around (`q ± 2π`) instead of stopping at the
/// end of its range.
fn step_within_limits(
    q: &JointVector,
    dq: &JointVector,
    joints: &[crate::Joint],
    revolute_full_turn: &[bool; crate::MAX_JOINTS],
) -> JointVector {
    let tau = 2.0 * std::f64::consts::PI;
    let mut out = *q;
    for (i, j) in joints.iter().enumerate() {
        let mut v = q[i] + dq[i];
        let l = &j.limits;
        if revolute_full_turn[i] && v.is_finite() {
            if v > l.max {
                v -= tau * ((v - l.max) / tau).ceil();
            } else if v < l.min {
                v += tau * ((l.min - v) / tau).ceil();
            }
        }
        out[i] = l.clamp(v);
    }
    out
}
