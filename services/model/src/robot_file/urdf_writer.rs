//! A robot as URDF (and the overlay that adds what URDF cannot say), so viewers and
//! other tools (RViz, Foxglove, Pinocchio) can load a DH robot. Pure text, no I/O.
//!
//! Frames: URDF link `i` is the robot's joint frame after the joint's motion, before
//! the constant rest of the DH row. For a standard DH row
//! `T = Rz(θ + q) Tz(d) Tx(a) Rx(α)` (revolute) the joint's `<origin>` is the previous
//! row's rest `B_{i-1} = Tz(d) Tx(a) Rx(α)` followed by `Rz(θ)`, the axis is z, and link
//! `i`'s `<inertial>` sits at `B_i` · COM with `B_i`'s rotation (the tensor keeps frame
//! `i`'s axes). Prismatic rows move along z after `Rz(θ) Tz(d)`. Placed joints (a robot
//! loaded from URDF) are written as they are. A fixed joint carries the last rest and
//! the tool offset to a massless link `tool`, the tip the overlay names. Each link gets a
//! cylinder along its segment (a visual only). Numbers are printed shortest-round-trip,
//! so loading the file back gives the same model to the last bit of each constant.

use std::fmt::Write as _;

use nalgebra::{Matrix3, Vector3};

use crate::math::Pose;
use crate::robot::{JointKind, Robot};

/// Roll, pitch, yaw (URDF's fixed-axis x-y-z: `R = Rz(yaw) Ry(pitch) Rx(roll)`) of `r`.
fn rpy(r: &Matrix3<f64>) -> Vector3<f64> {
    let sp = (-r[(2, 0)]).clamp(-1.0, 1.0);
    let pitch = sp.asin();
    if (1.0 - sp.abs()) < 1e-12 {
        // Gimbal lock: roll and yaw share one axis; put it all in yaw.
        let yaw = (-r[(0, 1)]).atan2(r[(1, 1)]);
        return Vector3::new(0.0, pitch, yaw);
    }
    Vector3::new(
        r[(2, 1)].atan2(r[(2, 2)]),
        pitch,
        r[(1, 0)].atan2(r[(0, 0)]),
    )
}

fn v3(v: &Vector3<f64>) -> String {
    format!("{} {} {}", v.x, v.y, v.z)
}

fn origin(p: &Pose) -> String {
    format!(
        "<origin xyz=\"{}\" rpy=\"{}\"/>",
        v3(&p.translation),
        v3(&rpy(&p.rotation))
    )
}

fn rot_z(theta: f64) -> Pose {
    Pose::from_xyz_rpy(Vector3::zeros(), Vector3::new(0.0, 0.0, theta))
}

fn trans(x: f64, y: f64, z: f64) -> Pose {
    Pose::from_xyz_rpy(Vector3::new(x, y, z), Vector3::zeros())
}

fn rot_x(alpha: f64) -> Pose {
    Pose::from_xyz_rpy(Vector3::zeros(), Vector3::new(alpha, 0.0, 0.0))
}

/// XML text with `&`, `<`, `>`, `"` escaped (names come from user files).
fn xml(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

/// A cylinder from the link frame's origin to `to` (in the link frame), as a `<visual>`.
fn segment_visual(to: &Vector3<f64>, radius: f64) -> String {
    let len = to.norm();
    if len < 1e-9 {
        return format!(
            "    <visual><geometry><sphere radius=\"{radius}\"/></geometry></visual>\n"
        );
    }
    // A cylinder is along its z axis: turn z onto the segment.
    let dir = to / len;
    let z = Vector3::z();
    let axis = z.cross(&dir);
    let rot = if axis.norm() < 1e-12 {
        if dir.z > 0.0 {
            Matrix3::identity()
        } else {
            Matrix3::from_diagonal(&Vector3::new(1.0, -1.0, -1.0))
        }
    } else {
        let angle = z.dot(&dir).clamp(-1.0, 1.0).acos();
        *nalgebra::Rotation3::from_axis_angle(&nalgebra::Unit::new_normalize(axis), angle).matrix()
    };
    let pose = Pose {
        rotation: rot,
        translation: to / 2.0,
    };
    format!(
        "    <visual>{}<geometry><cylinder radius=\"{radius}\" length=\"{len}\"/></geometry></visual>\n",
        origin(&pose)
    )
}

/// The robot as URDF text: links `base_link`, one per joint (named after the joint,
/// `<joint>_link`), and `tool`; joints named as in the robot file. Limits: position,
/// velocity and effort (URDF has no acceleration or jerk: see [`overlay_toml`]).
pub fn to_urdf(robot: &Robot) -> String {
    let mut s = String::new();
    let _ = writeln!(s, "<?xml version=\"1.0\"?>");
    let _ = writeln!(
        s,
        "<!-- {} written by microrobot from its robot file. Acceleration and jerk limits,\n     rotor inertia and gear ratios are not URDF: the overlay beside it adds them. -->",
        xml(robot.name())
    );
    let _ = writeln!(s, "<robot name=\"{}\">", xml(robot.name()));
    let _ = writeln!(s, "  <link name=\"base_link\"/>");
    let mut parent = "base_link".to_string();
    // The constant part of the previous DH row, still to be applied (identity at the base).
    let mut rest = Pose::IDENTITY;
    for j in robot.joints() {
        let link = format!("{}_link", j.name);
        let (joint_origin, axis, next_rest) = match (&j.placement, j.kind) {
            (Some(p), _) => (rest.compose(&p.origin), p.axis, Pose::IDENTITY),
            (None, JointKind::Revolute) => (
                rest.compose(&rot_z(j.dh.theta)),
                Vector3::z(),
                trans(0.0, 0.0, j.dh.d)
                    .compose(&trans(j.dh.a, 0.0, 0.0))
                    .compose(&rot_x(j.dh.alpha)),
            ),
            (None, JointKind::Prismatic) => (
                rest.compose(&rot_z(j.dh.theta))
                    .compose(&trans(0.0, 0.0, j.dh.d)),
                Vector3::z(),
                trans(j.dh.a, 0.0, 0.0).compose(&rot_x(j.dh.alpha)),
            ),
        };
        // Link i's frame in the URDF is the joint frame; the robot's frame i is
        // `next_rest` further. The inertial goes there.
        let l = &j.link;
        let inertial_pose = Pose {
            rotation: next_rest.rotation,
            translation: next_rest.transform_point(&l.com),
        };
        let i = &l.inertia;
        let _ = writeln!(s, "  <link name=\"{}\">", xml(&link));
        let _ = writeln!(
            s,
            "    <inertial>{}<mass value=\"{}\"/><inertia ixx=\"{}\" ixy=\"{}\" ixz=\"{}\" iyy=\"{}\" iyz=\"{}\" izz=\"{}\"/></inertial>",
            origin(&inertial_pose),
            l.mass,
            i[(0, 0)],
            i[(0, 1)],
            i[(0, 2)],
            i[(1, 1)],
            i[(1, 2)],
            i[(2, 2)]
        );
        s.push_str(&segment_visual(&next_rest.translation, 0.02));
        let _ = writeln!(s, "  </link>");
        let kind = match j.kind {
            JointKind::Revolute => "revolute",
            JointKind::Prismatic => "prismatic",
        };
        let lim = &j.limits;
        let _ = writeln!(s, "  <joint name=\"{}\" type=\"{kind}\">", xml(&j.name));
        let _ = writeln!(s, "    <parent link=\"{}\"/>", xml(&parent));
        let _ = writeln!(s, "    <child link=\"{}\"/>", xml(&link));
        let _ = writeln!(s, "    {}", origin(&joint_origin));
        let _ = writeln!(s, "    <axis xyz=\"{}\"/>", v3(&axis));
        let _ = writeln!(
            s,
            "    <limit lower=\"{}\" upper=\"{}\" velocity=\"{}\" effort=\"{}\"/>",
            lim.min, lim.max, lim.velocity, lim.effort
        );
        if j.viscous_friction != 0.0 || j.coulomb_friction != 0.0 {
            let _ = writeln!(
                s,
                "    <dynamics damping=\"{}\" friction=\"{}\"/>",
                j.viscous_friction, j.coulomb_friction
            );
        }
        let _ = writeln!(s, "  </joint>");
        parent = link;
        rest = next_rest;
    }
    let _ = writeln!(s, "  <link name=\"tool\"/>");
    let _ = writeln!(s, "  <joint name=\"tool_joint\" type=\"fixed\">");
    let _ = writeln!(s, "    <parent link=\"{}\"/>", xml(&parent));
    let _ = writeln!(s, "    <child link=\"tool\"/>");
    let _ = writeln!(s, "    {}", origin(&rest.compose(robot.tool())));
    let _ = writeln!(s, "  </joint>");
    let _ = writeln!(s, "</robot>");
    s
}

/// `key = value`, or nothing for a limit the robot does not have (NaN: a URDF robot
/// without an overlay; the written overlay then lacks it too).
fn limit(s: &mut String, key: &str, value: f64) {
    if value.is_finite() {
        let _ = writeln!(s, "{key} = {value:?}");
    }
}

/// The overlay (TOML) that loads `urdf_file` (the text of [`to_urdf`], named relative to
/// the overlay) as the same robot: tip link `tool`, gravity, per joint the limits, rotor
/// inertia and gear ratio URDF cannot carry, and the payload, in the robot files' units.
pub fn overlay_toml(robot: &Robot, urdf_file: &str) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "# {} as URDF ({urdf_file}) plus what URDF cannot say; written by microrobot.",
        robot.name()
    );
    let _ = writeln!(s, "[robot]");
    let _ = writeln!(s, "urdf = {:?}", urdf_file);
    let _ = writeln!(s, "name = {:?}", robot.name());
    let _ = writeln!(s, "tip_link = \"tool\"");
    let g = robot.gravity();
    let _ = writeln!(s, "gravity_mps2 = [{:?}, {:?}, {:?}]", g.x, g.y, g.z);
    let deg = 180.0 / std::f64::consts::PI;
    for j in robot.joints() {
        let l = &j.limits;
        let _ = writeln!(s, "\n[joints.{:?}]", j.name);
        match j.kind {
            JointKind::Revolute => {
                limit(&mut s, "acc_deg_s2", l.acceleration * deg);
                limit(&mut s, "jerk_deg_s3", l.jerk * deg);
                let _ = writeln!(s, "rotor_inertia_kgmm2 = {:?}", j.rotor_inertia * 1e6);
            }
            JointKind::Prismatic => {
                limit(&mut s, "acc_mm_s2", l.acceleration * 1e3);
                limit(&mut s, "jerk_mm_s3", l.jerk * 1e3);
                let _ = writeln!(s, "rotor_mass_kg = {:?}", j.rotor_inertia);
            }
        }
        let _ = writeln!(s, "gear_ratio = {:?}", j.gear_ratio);
    }
    if let Some(p) = robot.payload() {
        // In the tool frame, which the overlay's tip link `tool` reproduces.
        let c = p.com * 1e3;
        let i = p.inertia * 1e6;
        let row = |r: usize| format!("[{:?}, {:?}, {:?}]", i[(r, 0)], i[(r, 1)], i[(r, 2)]);
        let _ = writeln!(s, "\n[payload]");
        let _ = writeln!(s, "mass_kg = {:?}", p.mass);
        let _ = writeln!(s, "com_mm = [{:?}, {:?}, {:?}]", c.x, c.y, c.z);
        let _ = writeln!(s, "inertia_kgmm2 = [{}, {}, {}]", row(0), row(1), row(2));
    }
    s
}
