//! Kinematic part of the study: the reachable workspace (seed Figure 10) and the
//! Jacobian columns and tool paths when one joint sweeps its range (Figures 12–13).

use anyhow::{Result, anyhow};
use microrobot_model::workspace::{Workspace, WorkspaceOptions, reachable_workspace};
use microrobot_model::{
    JointVector, ModelData, Robot, TaskRows, forward_kinematics, jacobian, rank,
};

/// Points per joint sweep.
pub const SWEEP_POINTS: usize = 361;

/// The workspace estimated at two voxel sizes (to show how the volume converges).
#[derive(Debug, Clone)]
pub struct WorkspaceStudy {
    /// Sampled workspace at voxel size `h` (points, bounds, volume).
    pub fine: Workspace,
    /// Volume at voxel size `2h` (m³).
    pub coarse_volume_m3: f64,
}

/// Samples the workspace with `samples` joint-space samples. The voxel size is
/// chosen so that about 20 samples fall in each voxel of the bounding box
/// (`h = ∛(20·V_box/samples)`), found from a first pass of `samples/20` samples.
pub fn workspace(
    robot: &Robot,
    samples: usize,
    progress: &(dyn Fn(usize, usize) + Sync),
) -> Result<WorkspaceStudy> {
    let samples = samples.max(1000);
    let pilot_opts = WorkspaceOptions {
        samples: (samples / 20).max(500),
        voxel_size_m: 1.0,
        max_points: 1,
        ..WorkspaceOptions::default()
    };
    let pilot =
        reachable_workspace(robot, &pilot_opts, &|_| {}).map_err(|e| anyhow!("workspace: {e}"))?;
    let ext = pilot.bounds.max - pilot.bounds.min;
    let span = ext.x.max(ext.y).max(ext.z).max(1e-6);
    // Flat workspaces (planar arms) have a zero extent: use the largest one.
    let vbox = ext.x.max(span * 1e-3) * ext.y.max(span * 1e-3) * ext.z.max(span * 1e-3);
    let h = (20.0 * vbox / samples as f64).cbrt().max(span * 1e-4);
    let opts = WorkspaceOptions {
        samples,
        voxel_size_m: h,
        max_points: 30_000,
        ..WorkspaceOptions::default()
    };
    let fine = reachable_workspace(robot, &opts, &|p| progress(p.done, p.total))
        .map_err(|e| anyhow!("workspace: {e}"))?;
    let coarse = reachable_workspace(
        robot,
        &WorkspaceOptions {
            voxel_size_m: 2.0 * h,
            max_points: 1,
            ..opts
        },
        &|_| {},
    )
    .map_err(|e| anyhow!("workspace: {e}"))?;
    Ok(WorkspaceStudy {
        fine,
        coarse_volume_m3: coarse.volume_m3,
    })
}

/// One joint swept over its range, the others at the reference configuration.
#[derive(Debug, Clone)]
pub struct Sweep {
    /// Swept joint (0-based).
    pub joint: usize,
    /// Joint positions (rad or m).
    pub q: Vec<f64>,
    /// Linear rows of the swept joint's Jacobian column: ∂p/∂q_j (m/rad).
    pub dp: Vec<[f64; 3]>,
    /// Tool position (m).
    pub p: Vec<[f64; 3]>,
}

/// The reference configuration: the middle of every joint's range.
pub fn reference_configuration(robot: &Robot) -> JointVector {
    let (lo, hi) = robot.position_limits();
    (lo + hi) * 0.5
}

/// Sweeps each joint in turn over its range.
pub fn sweeps(robot: &Robot) -> Vec<Sweep> {
    let q_ref = reference_configuration(robot);
    let mut data = ModelData::new(robot);
    robot
        .joints()
        .iter()
        .enumerate()
        .map(|(j, joint)| {
            let mut s = Sweep {
                joint: j,
                q: Vec::with_capacity(SWEEP_POINTS),
                dp: Vec::with_capacity(SWEEP_POINTS),
                p: Vec::with_capacity(SWEEP_POINTS),
            };
            for k in 0..SWEEP_POINTS {
                let mut q = q_ref;
                q[j] = joint.limits.min
                    + (joint.limits.max - joint.limits.min) * k as f64 / (SWEEP_POINTS - 1) as f64;
                let jac = jacobian(robot, &mut data, &q);
                let pose = forward_kinematics(robot, &mut data, &q);
                let t = pose.translation.vector;
                s.q.push(q[j]);
                s.dp.push([jac[(0, j)], jac[(1, j)], jac[(2, j)]]);
                s.p.push([t.x, t.y, t.z]);
            }
            s
        })
        .collect()
}

/// Rank of the full 6-row Jacobian at the reference configuration.
pub fn reference_rank(robot: &Robot) -> usize {
    let mut data = ModelData::new(robot);
    let jac = jacobian(robot, &mut data, &reference_configuration(robot));
    rank(&jac, robot.dof(), TaskRows::Full)
}

/// Largest rank of the full Jacobian over `count` random configurations inside the
/// limits (a rank-deficient arm, e.g. with two collinear axes, stays below 6).
pub fn max_rank(robot: &Robot, count: usize) -> usize {
    let mut data = ModelData::new(robot);
    let mut rng = Rng(0x2545_f491_4f6c_dd1d);
    (0..count)
        .map(|_| {
            let q = rng.configuration(robot);
            rank(&jacobian(robot, &mut data, &q), robot.dof(), TaskRows::Full)
        })
        .max()
        .unwrap_or(0)
}

/// A small xorshift generator for reproducible random configurations.
struct Rng(u64);

impl Rng {
    fn uniform(&mut self) -> f64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        (self.0 >> 11) as f64 / (1u64 << 53) as f64
    }

    fn configuration(&mut self, robot: &Robot) -> JointVector {
        let (lo, hi) = robot.position_limits();
        let mut q = JointVector::zeros();
        for i in 0..robot.dof() {
            q[i] = lo[i] + self.uniform() * (hi[i] - lo[i]);
        }
        q
    }
}

/// max |∂p_axis/∂q_j| over 2000 random configurations inside the limits and the
/// sweep of joint `j` (m/rad): zero when joint `j` never moves the tool along `axis`.
pub fn max_jacobian_element(robot: &Robot, sweeps: &[Sweep], j: usize, axis: usize) -> f64 {
    let mut m = sweeps
        .get(j)
        .map(|s| s.dp.iter().fold(0.0f64, |m, d| m.max(d[axis].abs())))
        .unwrap_or(0.0);
    let mut data = ModelData::new(robot);
    let mut rng = Rng(0x9e37_79b9_7f4a_7c15);
    for _ in 0..2000 {
        let q = rng.configuration(robot);
        let jac = jacobian(robot, &mut data, &q);
        m = m.max(jac[(axis, j)].abs());
    }
    m
}
