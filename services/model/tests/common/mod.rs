//! Shared helpers for the integration tests: random robot files and states.
#![allow(dead_code, clippy::needless_range_loop)]

use microrobot_model::{JointVector, Robot};
use proptest::prelude::*;

/// One random joint, in the file's units (mm, deg, kg, kg·mm²).
#[derive(Clone, Debug)]
pub struct JointSpec {
    pub prismatic: bool,
    pub dh: [f64; 4],
    pub mass: f64,
    pub com: [f64; 3],
    /// Factor A of the inertia A Aᵀ + 10·1 (kg·mm²): symmetric positive definite.
    pub a: [f64; 9],
    pub rotor: f64,
    pub viscous: f64,
    pub coulomb: f64,
}

#[derive(Clone, Debug)]
pub struct RobotSpec {
    pub gravity: [f64; 3],
    pub joints: Vec<JointSpec>,
    pub tool: Option<([f64; 3], [f64; 3])>,
    pub payload: Option<(f64, [f64; 3], [f64; 3])>,
}

fn arr3(r: std::ops::Range<f64>) -> impl Strategy<Value = [f64; 3]> {
    [r.clone(), r.clone(), r]
}

pub fn joint_spec() -> impl Strategy<Value = JointSpec> {
    (
        prop::bool::weighted(0.3),
        [
            -180.0..180.0,
            -200.0..200.0,
            -300.0..300.0,
            -180.0..180.0f64,
        ],
        0.05..5.0f64,
        arr3(-150.0..150.0),
        prop::array::uniform9(-60.0..60.0f64),
        (0.0..2000.0f64, 0.0..0.5f64, 0.0..0.3f64),
    )
        .prop_map(
            |(prismatic, dh, mass, com, a, (rotor, viscous, coulomb))| JointSpec {
                prismatic,
                dh,
                mass,
                com,
                a,
                rotor,
                viscous,
                coulomb,
            },
        )
}

pub fn robot_spec(max_joints: usize) -> impl Strategy<Value = RobotSpec> {
    (
        arr3(-10.0..10.0),
        prop::collection::vec(joint_spec(), 1..=max_joints),
        prop::option::of((arr3(-100.0..100.0), arr3(-180.0..180.0))),
        prop::option::of((0.0..2.0f64, arr3(-50.0..50.0), arr3(1.0..500.0))),
    )
        .prop_map(|(gravity, joints, tool, payload)| RobotSpec {
            gravity,
            joints,
            tool,
            payload,
        })
}

fn v3(v: &[f64; 3]) -> String {
    format!("[{:?}, {:?}, {:?}]", v[0], v[1], v[2])
}

/// The spec as a robot file in the format of docs/seed-arm.md.
pub fn to_toml(spec: &RobotSpec) -> String {
    let mut s = format!(
        "[robot]\nname = \"random\"\ngravity_mps2 = {}\n",
        v3(&spec.gravity)
    );
    for (i, j) in spec.joints.iter().enumerate() {
        let a = &j.a;
        let mut inertia = [[0.0; 3]; 3];
        for r in 0..3 {
            for c in 0..3 {
                inertia[r][c] = (0..3).map(|k| a[3 * r + k] * a[3 * c + k]).sum::<f64>();
            }
            inertia[r][r] += 10.0;
        }
        // Symmetrise exactly.
        for r in 0..3 {
            for c in 0..r {
                inertia[r][c] = inertia[c][r];
            }
        }
        let inertia_s = format!(
            "[{}, {}, {}]",
            v3(&inertia[0]),
            v3(&inertia[1]),
            v3(&inertia[2])
        );
        let [th, d, al_a, al] = j.dh;
        s += &format!("\n[[joints]]\nname = \"j{i}\"\n");
        if j.prismatic {
            s += &format!(
                "kind = \"prismatic\"\ndh = {{ theta_deg = {th:?}, d_mm = {d:?}, a_mm = {al_a:?}, alpha_deg = {al:?} }}\n\
                 limits = {{ min_mm = -300.0, max_mm = 300.0, vel_mm_s = 500.0, acc_mm_s2 = 1000.0, jerk_mm_s3 = 10000.0, force_n = 100.0 }}\n\
                 link = {{ mass_kg = {:?}, com_mm = {}, inertia_kgmm2 = {inertia_s}, rotor_mass_kg = {:?} }}\n\
                 viscous_friction_nsm = {:?}\ncoulomb_friction_n = {:?}\n",
                j.mass,
                v3(&j.com),
                j.rotor / 1000.0,
                j.viscous,
                j.coulomb
            );
        } else {
            s += &format!(
                "kind = \"revolute\"\ndh = {{ theta_deg = {th:?}, d_mm = {d:?}, a_mm = {al_a:?}, alpha_deg = {al:?} }}\n\
                 limits = {{ min_deg = -180.0, max_deg = 180.0, vel_deg_s = 90.0, acc_deg_s2 = 90.0, jerk_deg_s3 = 900.0, torque_nm = 100.0 }}\n\
                 link = {{ mass_kg = {:?}, com_mm = {}, inertia_kgmm2 = {inertia_s}, rotor_inertia_kgmm2 = {:?} }}\n\
                 gear_ratio = 50.0\nviscous_friction_nms = {:?}\ncoulomb_friction_nm = {:?}\n",
                j.mass,
                v3(&j.com),
                j.rotor,
                j.viscous,
                j.coulomb
            );
        }
    }
    if let Some((xyz, rpy)) = &spec.tool {
        s += &format!("\n[tool]\nxyz_mm = {}\nrpy_deg = {}\n", v3(xyz), v3(rpy));
    }
    if let Some((m, com, diag)) = &spec.payload {
        s += &format!(
            "\n[payload]\nmass_kg = {m:?}\ncom_mm = {}\ninertia_kgmm2 = [[{:?}, 0.0, 0.0], [0.0, {:?}, 0.0], [0.0, 0.0, {:?}]]\n",
            v3(com),
            diag[0],
            diag[1],
            diag[2]
        );
    }
    s
}

pub fn build(spec: &RobotSpec) -> Robot {
    Robot::from_toml_str(&to_toml(spec), "random.toml")
        .unwrap_or_else(|e| panic!("{e}\n{}", to_toml(spec)))
}

/// A random state: q, qd, qdd, each in [-1, 1] scaled (prismatic q in metres).
pub fn state() -> impl Strategy<Value = ([f64; 8], [f64; 8], [f64; 8])> {
    (
        prop::array::uniform8(-3.0..3.0f64),
        prop::array::uniform8(-2.0..2.0f64),
        prop::array::uniform8(-5.0..5.0f64),
    )
}

/// Joint vector from an array, zero beyond `dof`; prismatic positions scaled to ±0.3 m.
pub fn jv(robot: &Robot, a: &[f64; 8], position: bool) -> JointVector {
    let mut v = JointVector::zeros();
    for (i, j) in robot.joints().iter().enumerate() {
        let scale = if position && j.kind == microrobot_model::JointKind::Prismatic {
            0.1
        } else {
            1.0
        };
        v[i] = a[i] * scale;
    }
    v
}

/// Largest absolute entry of the first `n` entries.
pub fn scale(v: &JointVector, n: usize) -> f64 {
    (0..n).map(|i| v[i].abs()).fold(0.0, f64::max)
}

/// One random placed joint (URDF-style), SI units: origin xyz (m) and rpy
/// (rad), an axis (normalised by the model), inertia as for [`JointSpec`].
#[derive(Clone, Debug)]
pub struct PlacedJointSpec {
    pub prismatic: bool,
    pub xyz: [f64; 3],
    pub rpy: [f64; 3],
    pub axis: [f64; 3],
    pub mass: f64,
    pub com: [f64; 3],
    pub a: [f64; 9],
    pub rotor: f64,
    pub viscous: f64,
    pub coulomb: f64,
}

#[derive(Clone, Debug)]
pub struct PlacedSpec {
    pub gravity: [f64; 3],
    pub joints: Vec<PlacedJointSpec>,
    pub tool: ([f64; 3], [f64; 3]),
}

pub fn placed_spec(max_joints: usize) -> impl Strategy<Value = PlacedSpec> {
    let joint = (
        prop::bool::weighted(0.3),
        arr3(-0.3..0.3),
        arr3(-3.2..3.2),
        arr3(-1.0..1.0),
        0.05..5.0f64,
        arr3(-0.15..0.15),
        prop::array::uniform9(-0.06..0.06f64),
        (0.0..0.002f64, 0.0..0.5f64, 0.0..0.3f64),
    )
        .prop_map(
            |(prismatic, xyz, rpy, axis, mass, com, a, (rotor, viscous, coulomb))| {
                PlacedJointSpec {
                    prismatic,
                    xyz,
                    rpy,
                    axis,
                    mass,
                    com,
                    a,
                    rotor,
                    viscous,
                    coulomb,
                }
            },
        );
    (
        arr3(-10.0..10.0),
        prop::collection::vec(joint, 1..=max_joints),
        (arr3(-0.1..0.1), arr3(-3.2..3.2)),
    )
        .prop_map(|(gravity, joints, tool)| PlacedSpec {
            gravity,
            joints,
            tool,
        })
}

fn pose(xyz: &[f64; 3], rpy: &[f64; 3]) -> microrobot_model::Pose {
    microrobot_model::Pose::from_xyz_rpy(
        nalgebra::Vector3::from(*xyz),
        nalgebra::Vector3::from(*rpy),
    )
}

/// The robot of a [`PlacedSpec`], assembled with `Robot::new`.
pub fn build_placed(spec: &PlacedSpec) -> Robot {
    use microrobot_model::{
        DhParameters, Joint, JointKind, JointLimits, JointPlacement, LinkInertia,
    };
    use nalgebra::{Matrix3, Vector3};
    let joints = spec
        .joints
        .iter()
        .enumerate()
        .map(|(i, j)| {
            let a = Matrix3::from_row_slice(&j.a);
            let mut axis = Vector3::from(j.axis);
            if axis.norm() < 0.1 {
                axis = Vector3::z();
            }
            Joint {
                name: format!("j{i}"),
                kind: if j.prismatic {
                    JointKind::Prismatic
                } else {
                    JointKind::Revolute
                },
                dh: DhParameters {
                    theta: 0.0,
                    d: 0.0,
                    a: 0.0,
                    alpha: 0.0,
                },
                placement: Some(JointPlacement {
                    origin: pose(&j.xyz, &j.rpy),
                    axis,
                }),
                // A full turn (inverse kinematics wraps such joints), ±0.3 m.
                limits: JointLimits {
                    min: if j.prismatic {
                        -0.3
                    } else {
                        -std::f64::consts::PI
                    },
                    max: if j.prismatic {
                        0.3
                    } else {
                        std::f64::consts::PI
                    },
                    velocity: 1.0,
                    acceleration: 1.0,
                    jerk: 1.0,
                    effort: 1.0,
                },
                link: LinkInertia {
                    mass: j.mass,
                    com: Vector3::from(j.com),
                    inertia: a * a.transpose() + Matrix3::identity() * 1e-5,
                },
                rotor_inertia: j.rotor,
                gear_ratio: 1.0,
                viscous_friction: j.viscous,
                coulomb_friction: j.coulomb,
            }
        })
        .collect();
    Robot::new(
        "placed",
        nalgebra::Vector3::from(spec.gravity),
        joints,
        pose(&spec.tool.0, &spec.tool.1),
        None,
    )
    .unwrap_or_else(|e| panic!("{e}"))
}

/// The same robot as a DH robot, with every joint placed instead: frame `i` of
/// the placed robot is DH frame `i-1` turned by joint `i`'s motion,
/// `⁰T_{i-1} M_i(q)`, so joint `i`'s placement is DH row `i-1`'s constant part
/// `Rz(θ) Tz(d) Tx(a) Rx(α)` (the identity for the first), each link's inertia
/// moves by its own row's constant part, and so does the tool.
pub fn to_placed(robot: &Robot) -> Robot {
    use microrobot_model::{JointPlacement, Pose};
    use nalgebra::{Rotation3, Vector3};
    let constant = |j: &microrobot_model::Joint| {
        let dh = &j.dh;
        let rz = Rotation3::from_axis_angle(&Vector3::z_axis(), dh.theta);
        let rx = Rotation3::from_axis_angle(&Vector3::x_axis(), dh.alpha);
        Pose {
            rotation: (rz * rx).into_inner(),
            translation: Vector3::new(0.0, 0.0, dh.d) + rz * Vector3::new(dh.a, 0.0, 0.0),
        }
    };
    let mut previous = Pose::IDENTITY;
    let mut joints = Vec::new();
    for j in robot.joints() {
        let c = constant(j);
        let mut placed = j.clone();
        placed.placement = Some(JointPlacement {
            origin: previous,
            axis: Vector3::z(),
        });
        placed.link = j.link.transformed(&c);
        joints.push(placed);
        previous = c;
    }
    Robot::new(
        robot.name(),
        robot.gravity(),
        joints,
        previous.compose(robot.tool()),
        robot.payload().copied(),
    )
    .unwrap_or_else(|e| panic!("{e}"))
}

/// |P Jᵀe| / (|J|_F |e|): the cosine-like size of the projected gradient of
/// ½|e|² at `q` (components pushing a joint out through a limit it rests on
/// removed). Zero at a KKT point of the bound-constrained least squares.
pub fn projected_gradient(
    robot: &Robot,
    data: &mut microrobot_model::ModelData,
    q: &JointVector,
    target: &nalgebra::Vector3<f64>,
) -> f64 {
    use microrobot_model::{forward_kinematics, jacobian};
    let n = robot.dof();
    let jac = jacobian(robot, data, q);
    let e = target - forward_kinematics(robot, data, q).translation.vector;
    let mut g = vec![0.0; n];
    let mut jn = 0.0;
    for c in 0..n {
        for r in 0..3 {
            g[c] += jac[(r, c)] * e[r];
            jn += jac[(r, c)] * jac[(r, c)];
        }
        let l = &robot.joints()[c].limits;
        if (q[c] >= l.max && g[c] > 0.0) || (q[c] <= l.min && g[c] < 0.0) {
            g[c] = 0.0;
        }
    }
    let gn = g.iter().map(|x| x * x).sum::<f64>().sqrt();
    if gn == 0.0 {
        0.0
    } else {
        gn / (jn.sqrt() * e.norm())
    }
}
