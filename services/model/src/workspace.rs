//! Reachable workspace (seed section 2.3): the set of tool-origin positions over
//! the joint limits, estimated by sampling joint space uniformly inside the
//! limits. Produces a point cloud, the bounding box, and voxel estimates of the
//! volume (and of the area of its projection on the base xy plane, for planar
//! arms). Sampling runs on all available cores; progress goes to a callback.
//!
//! Volume estimate: the union of the grid cubes (side `h`, grid anchored at the
//! base origin) that contain at least one sampled tool position, times `h³`.
//! For a fixed `h` it grows monotonically with the number of samples towards the
//! volume of the voxel cover, which exceeds the true volume by at most the
//! boundary layer (≈ surface area × h / 2 on average); it converges to the true
//! volume as `h → 0` with samples growing like `h⁻³`. The area estimate is the
//! same construction in 2-D on the xy projection.

use crate::JointVector;
use crate::data::ModelData;
use crate::kinematics::update_kinematics;
use crate::robot::Robot;
use nalgebra::Point3;
use std::collections::HashSet;
use std::hash::{BuildHasherDefault, Hasher};
use std::sync::Mutex;
use std::sync::atomic::{AtomicUsize, Ordering};

/// Sampling settings.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct WorkspaceOptions {
    /// Number of joint-space samples.
    pub samples: usize,
    /// Voxel edge length `h`, m.
    pub voxel_size_m: f64,
    /// Seed of the sample generator (results do not depend on the thread count).
    pub seed: u64,
    /// At most this many points are kept in the point cloud (evenly thinned).
    pub max_points: usize,
    /// Worker threads; 0 uses all available cores (at most 64).
    pub threads: usize,
}

impl Default for WorkspaceOptions {
    fn default() -> Self {
        WorkspaceOptions {
            samples: 200_000,
            voxel_size_m: 0.002,
            seed: 1,
            max_points: 50_000,
            threads: 0,
        }
    }
}

/// Progress report: `done` of `total` samples evaluated.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct WorkspaceProgress {
    /// Samples evaluated so far.
    pub done: usize,
    /// Samples requested.
    pub total: usize,
}

/// Axis-aligned bounding box, m.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BoundingBox {
    /// Smallest coordinates.
    pub min: Point3<f64>,
    /// Largest coordinates.
    pub max: Point3<f64>,
}

/// A sampled reachable workspace.
#[derive(Clone, Debug, PartialEq)]
pub struct Workspace {
    /// Tool positions in the base frame (thinned to at most `max_points`).
    pub points: Vec<Point3<f64>>,
    /// Bounding box of all samples.
    pub bounds: BoundingBox,
    /// Number of joint-space samples evaluated.
    pub samples: usize,
    /// Voxel edge length `h`, m.
    pub voxel_size_m: f64,
    /// Occupied voxels.
    pub occupied_voxels: usize,
    /// `occupied_voxels · h³`, m³ (see the module documentation).
    pub volume_m3: f64,
    /// Occupied cells of the xy projection.
    pub occupied_cells_xy: usize,
    /// `occupied_cells_xy · h²`, m²: the reachable area of a planar arm in the
    /// base xy plane.
    pub area_xy_m2: f64,
}

/// Inputs the sampler refuses.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum WorkspaceError {
    /// `samples` is zero.
    #[error("workspace sampling needs at least one sample")]
    NoSamples,
    /// The voxel size is not positive and finite.
    #[error("voxel size {0} m must be positive and finite")]
    BadVoxelSize(f64),
    /// The grid would exceed ±2²⁰ voxels per axis.
    #[error("voxel size {voxel_size_m} m is too small for a workspace of extent {extent_m} m")]
    GridTooFine {
        /// Requested voxel size.
        voxel_size_m: f64,
        /// Largest coordinate magnitude reached.
        extent_m: f64,
    },
}

/// Multiplicative hasher for packed voxel keys (the default SipHash is slower
/// than the forward kinematics it would sit next to).
#[derive(Default)]
struct KeyHasher(u64);

impl Hasher for KeyHasher {
    fn finish(&self) -> u64 {
        self.0
    }
    fn write(&mut self, bytes: &[u8]) {
        for b in bytes {
            self.0 = (self.0 ^ u64::from(*b)).wrapping_mul(0x0100_0000_01b3);
        }
    }
    fn write_u64(&mut self, k: u64) {
        self.0 = (k ^ (k >> 29)).wrapping_mul(0xbf58_476d_1ce4_e5b9) ^ (k >> 32);
    }
}

type KeySet = HashSet<u64, BuildHasherDefault<KeyHasher>>;

const CHUNK: usize = 8192;
/// More workers than this only add overhead (and could fail to spawn).
const MAX_THREADS: usize = 64;
const AXIS_BITS: u32 = 21;
const AXIS_OFFSET: i64 = 1 << (AXIS_BITS - 1);

/// Counter-based uniform `[0, 1)` number for (sample, joint): independent of the
/// order and thread in which samples are evaluated.
fn uniform(seed: u64, sample: u64, joint: u64) -> f64 {
    let mut z = seed
        .wrapping_add(sample.wrapping_mul(0x9e37_79b9_7f4a_7c15))
        .wrapping_add(joint.wrapping_mul(0xd1b5_4a32_d192_ed03));
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^= z >> 31;
    (z >> 11) as f64 / (1u64 << 53) as f64
}

fn cell(x: f64, h: f64) -> Option<u64> {
    let i = (x / h).floor();
    if i.is_nan() || i.abs() >= (AXIS_OFFSET - 1) as f64 {
        return None;
    }
    Some((i as i64 + AXIS_OFFSET) as u64)
}

struct Partial {
    voxels: KeySet,
    cells: KeySet,
    points: Vec<(usize, Point3<f64>)>,
    min: Point3<f64>,
    max: Point3<f64>,
    overflow: f64,
}

/// Samples the reachable workspace of `robot` (tool origin positions) over its
/// joint limits. `progress` is called after every chunk of samples from the
/// worker threads (so it must be `Sync`); the CLI draws a bar from it.
pub fn reachable_workspace(
    robot: &Robot,
    options: &WorkspaceOptions,
    progress: &(dyn Fn(WorkspaceProgress) + Sync),
) -> Result<Workspace, WorkspaceError> {
    if options.samples == 0 {
        return Err(WorkspaceError::NoSamples);
    }
    let h = options.voxel_size_m;
    if !(h > 0.0 && h.is_finite()) {
        return Err(WorkspaceError::BadVoxelSize(h));
    }
    let threads = if options.threads == 0 {
        std::thread::available_parallelism()
            .map(|n| n.get())
            .unwrap_or(1)
    } else {
        options.threads
    }
    .clamp(1, MAX_THREADS);
    let total = options.samples;
    let stride = total.div_ceil(options.max_points.max(1));
    let n_chunks = total.div_ceil(CHUNK);
    let next_chunk = AtomicUsize::new(0);
    let done = AtomicUsize::new(0);
    let results: Mutex<Vec<Partial>> = Mutex::new(Vec::new());
    let (lo, hi) = robot.position_limits();
    let dof = robot.dof();

    let worker = || {
        let mut data = ModelData::new(robot);
        let mut part = Partial {
            voxels: KeySet::default(),
            cells: KeySet::default(),
            points: Vec::new(),
            min: Point3::new(f64::INFINITY, f64::INFINITY, f64::INFINITY),
            max: Point3::new(f64::NEG_INFINITY, f64::NEG_INFINITY, f64::NEG_INFINITY),
            overflow: 0.0,
        };
        let mut q = JointVector::zeros();
        loop {
            let c = next_chunk.fetch_add(1, Ordering::Relaxed);
            if c >= n_chunks {
                break;
            }
            let end = (c + 1).saturating_mul(CHUNK).min(total);
            for s in c * CHUNK..end {
                for j in 0..dof {
                    q[j] = lo[j] + uniform(options.seed, s as u64, j as u64) * (hi[j] - lo[j]);
                }
                update_kinematics(robot, &mut data, &q);
                let p = Point3::from(data.tool_frame().translation);
                part.min = part.min.inf(&p);
                part.max = part.max.sup(&p);
                match (cell(p.x, h), cell(p.y, h), cell(p.z, h)) {
                    (Some(ix), Some(iy), Some(iz)) => {
                        part.cells.insert(ix << AXIS_BITS | iy);
                        part.voxels.insert((ix << AXIS_BITS | iy) << AXIS_BITS | iz);
                    }
                    _ => part.overflow = part.overflow.max(p.coords.amax()),
                }
                if s % stride == 0 {
                    part.points.push((s, p));
                }
            }
            let d = done.fetch_add(end - c * CHUNK, Ordering::Relaxed) + (end - c * CHUNK);
            progress(WorkspaceProgress { done: d, total });
        }
        if let Ok(mut r) = results.lock() {
            r.push(part);
        }
    };
    std::thread::scope(|scope| {
        for _ in 1..threads {
            scope.spawn(worker);
        }
        worker();
    });

    let parts = results
        .into_inner()
        .unwrap_or_else(|poison| poison.into_inner());
    let mut voxels = KeySet::default();
    let mut cells = KeySet::default();
    let mut points = Vec::new();
    let mut min = Point3::new(f64::INFINITY, f64::INFINITY, f64::INFINITY);
    let mut max = Point3::new(f64::NEG_INFINITY, f64::NEG_INFINITY, f64::NEG_INFINITY);
    let mut overflow = 0.0_f64;
    for p in parts {
        voxels.extend(p.voxels);
        cells.extend(p.cells);
        points.extend(p.points);
        min = min.inf(&p.min);
        max = max.sup(&p.max);
        overflow = overflow.max(p.overflow);
    }
    if overflow > 0.0 {
        return Err(WorkspaceError::GridTooFine {
            voxel_size_m: h,
            extent_m: overflow,
        });
    }
    points.sort_by_key(|(s, _)| *s);
    Ok(Workspace {
        points: points.into_iter().map(|(_, p)| p).collect(),
        bounds: BoundingBox { min, max },
        samples: total,
        voxel_size_m: h,
        occupied_voxels: voxels.len(),
        volume_m3: voxels.len() as f64 * h * h * h,
        occupied_cells_xy: cells.len(),
        area_xy_m2: cells.len() as f64 * h * h,
    })
}
