//! URDF text to the serial chain between two links (parsed by the `urdf-rs`
//! crate). Fixed joints are merged into their parent body, links off the
//! base→tip path into the path body they hang from (moving joints locked),
//! every `<inertial>` moved into its body frame. Errors name the file, the
//! element and the joint or link: `panda.urdf: joint[panda_joint4].axis: …`.

use super::RobotFileError;
use crate::MAX_JOINTS;
use crate::math::Pose;
use crate::robot::{
    DhParameters, Joint, JointKind, JointLimits, JointPlacement, LinkFrame, LinkInertia,
};
use nalgebra::{Matrix3, SymmetricEigen, Unit, UnitQuaternion, Vector3};
use std::collections::HashMap;
use urdf_rs::JointType;

/// Which part of the URDF becomes the robot, from the overlay (if any).
pub(crate) struct Selection<'a> {
    pub base_link: Option<&'a str>,
    pub tip_link: Option<&'a str>,
    /// Lock positions of joints off the path (rad or m), by joint name.
    pub lock: &'a [(String, f64)],
    /// The file that set `base_link`, `tip_link` and `lock` (for their errors).
    pub overlay: &'a str,
}

/// The chain read from a URDF; rate limits it lacks are NaN.
pub(crate) struct UrdfChain {
    pub name: String,
    pub joints: Vec<Joint>,
    /// Tip link frame in the last joint's frame.
    pub tip: Pose,
    pub links: Vec<LinkFrame>,
    pub warnings: Vec<String>,
}

type Res<T> = Result<T, RobotFileError>;

struct Ctx<'a> {
    file: &'a str,
}

impl Ctx<'_> {
    fn invalid(&self, key: String, message: impl Into<String>) -> RobotFileError {
        RobotFileError::Invalid {
            file: self.file.to_string(),
            key,
            message: message.into(),
        }
    }

    fn finite(&self, key: String, values: &[f64]) -> Res<()> {
        match values.iter().find(|v| !v.is_finite()) {
            Some(&value) => Err(RobotFileError::NonFinite {
                file: self.file.to_string(),
                key,
                value,
            }),
            None => Ok(()),
        }
    }
}

fn pose_of(p: &urdf_rs::Pose) -> Pose {
    Pose::from_xyz_rpy(Vector3::from(p.xyz.0), Vector3::from(p.rpy.0))
}

fn is_moving(t: &JointType) -> bool {
    matches!(
        t,
        JointType::Revolute | JointType::Continuous | JointType::Prismatic
    )
}

fn type_name(t: &JointType) -> &'static str {
    match t {
        JointType::Revolute => "revolute",
        JointType::Continuous => "continuous",
        JointType::Prismatic => "prismatic",
        JointType::Fixed => "fixed",
        JointType::Floating => "floating",
        JointType::Planar => "planar",
        JointType::Spherical => "spherical",
    }
}

/// A link's `<inertial>` in the link frame; `None` when the link has none (all
/// zero: urdf-rs reads a missing element as zeros).
fn link_inertia(
    ctx: &Ctx,
    link: &urdf_rs::Link,
    warnings: &mut Vec<String>,
) -> Res<Option<LinkInertia>> {
    let inl = &link.inertial;
    let i = &inl.inertia;
    let key = format!("link[{}].inertial", link.name);
    ctx.finite(format!("{key}.origin.xyz"), &inl.origin.xyz.0)?;
    ctx.finite(format!("{key}.origin.rpy"), &inl.origin.rpy.0)?;
    ctx.finite(format!("{key}.mass"), &[inl.mass.value])?;
    ctx.finite(
        format!("{key}.inertia"),
        &[i.ixx, i.ixy, i.ixz, i.iyy, i.iyz, i.izz],
    )?;
    let raw = Matrix3::new(
        i.ixx, i.ixy, i.ixz, i.ixy, i.iyy, i.iyz, i.ixz, i.iyz, i.izz,
    );
    let origin = pose_of(&inl.origin);
    if inl.mass.value == 0.0 && raw == Matrix3::zeros() && origin == Pose::IDENTITY {
        return Ok(None);
    }
    if inl.mass.value < 0.0 {
        return Err(ctx.invalid(
            format!("{key}.mass"),
            format!("{} kg is negative", inl.mass.value),
        ));
    }
    let scale = raw.abs().max().max(1e-300);
    let eig = SymmetricEigen::new(raw).eigenvalues;
    if eig.min() < -1e-9 * scale {
        return Err(ctx.invalid(
            format!("{key}.inertia"),
            format!(
                "not positive semi-definite: eigenvalue {:e} kg·m² < 0",
                eig.min()
            ),
        ));
    }
    if let Some(w) = triangle_warning(&raw) {
        warnings.push(format!("{}: {key}.inertia: {w}", ctx.file));
    }
    Ok(Some(LinkInertia {
        mass: inl.mass.value,
        com: origin.translation,
        inertia: origin.rotation * raw * origin.rotation.transpose(),
    }))
}

/// The principal moments of a physical body satisfy `I_a + I_b ≥ I_c`; many
/// published models (the seed arm's among them) do not. A warning, not an error.
pub(crate) fn triangle_warning(inertia: &Matrix3<f64>) -> Option<String> {
    let e = SymmetricEigen::new(*inertia).eigenvalues;
    let tol = 1e-9 * e.abs().max();
    let (a, b, c) = (e[0], e[1], e[2]);
    (a + b < c - tol || a + c < b - tol || b + c < a - tol).then(|| {
        format!(
            "principal moments {a:e}, {b:e}, {c:e} kg·m² break the triangle inequality (loaded anyway)"
        )
    })
}

/// The chain from `base_link` to `tip_link` of the URDF `text` (file name `file`).
pub(crate) fn load(text: &str, file: &str, sel: &Selection) -> Res<UrdfChain> {
    let ctx = Ctx { file };
    let model = urdf_rs::read_from_string(text).map_err(|e| RobotFileError::UrdfSyntax {
        file: file.to_string(),
        message: e.to_string(),
    })?;
    let mut warnings = Vec::new();

    // Index links and joints; every number checked finite.
    let mut link_index: HashMap<&str, usize> = HashMap::new();
    for (k, l) in model.links.iter().enumerate() {
        if link_index.insert(l.name.as_str(), k).is_some() {
            return Err(ctx.invalid(format!("link[{}]", l.name), "link name used twice"));
        }
    }
    let mut parent_joint: Vec<Option<usize>> = vec![None; model.links.len()];
    let mut child_joints: Vec<Vec<usize>> = vec![Vec::new(); model.links.len()];
    let mut joint_names: HashMap<&str, usize> = HashMap::new();
    for (k, j) in model.joints.iter().enumerate() {
        let key = format!("joint[{}]", j.name);
        if joint_names.insert(j.name.as_str(), k).is_some() {
            return Err(ctx.invalid(key, "joint name used twice"));
        }
        ctx.finite(format!("{key}.origin.xyz"), &j.origin.xyz.0)?;
        ctx.finite(format!("{key}.origin.rpy"), &j.origin.rpy.0)?;
        ctx.finite(format!("{key}.axis.xyz"), &j.axis.xyz.0)?;
        let l = &j.limit;
        ctx.finite(
            format!("{key}.limit"),
            &[l.lower, l.upper, l.effort, l.velocity],
        )?;
        if let Some(d) = &j.dynamics {
            ctx.finite(format!("{key}.dynamics"), &[d.damping, d.friction])?;
        }
        let parent = *link_index.get(j.parent.link.as_str()).ok_or_else(|| {
            ctx.invalid(
                format!("{key}.parent"),
                format!("link \"{}\" is not defined", j.parent.link),
            )
        })?;
        let child = *link_index.get(j.child.link.as_str()).ok_or_else(|| {
            ctx.invalid(
                format!("{key}.child"),
                format!("link \"{}\" is not defined", j.child.link),
            )
        })?;
        if let Some(other) = parent_joint[child] {
            return Err(ctx.invalid(
                format!("{key}.child"),
                format!(
                    "link \"{}\" is already the child of joint \"{}\"",
                    j.child.link, model.joints[other].name
                ),
            ));
        }
        parent_joint[child] = Some(k);
        child_joints[parent].push(k);
    }
    let parent_link = |joint: usize| link_index[model.joints[joint].parent.link.as_str()];
    // Ancestors of `link` (joints, tip to root); refuses a cycle.
    let ancestry = |link: usize| -> Res<Vec<usize>> {
        let mut out = Vec::new();
        let mut cur = link;
        while let Some(j) = parent_joint[cur] {
            if out.len() > model.joints.len() {
                return Err(ctx.invalid(
                    format!("link[{}]", model.links[link].name),
                    "its joints form a cycle",
                ));
            }
            out.push(j);
            cur = parent_link(j);
        }
        Ok(out)
    };

    let find_link = |name: &str, key: &str| -> Res<usize> {
        link_index
            .get(name)
            .copied()
            .ok_or_else(|| RobotFileError::Invalid {
                file: sel.overlay.to_string(),
                key: key.to_string(),
                message: format!("{file} has no link \"{name}\""),
            })
    };
    let base = match sel.base_link {
        Some(name) => find_link(name, "robot.base_link")?,
        None => {
            let roots: Vec<usize> = (0..model.links.len())
                .filter(|&k| parent_joint[k].is_none())
                .collect();
            match roots.as_slice() {
                [one] => *one,
                [] => {
                    return Err(ctx.invalid("robot".into(), "no root link (no links, or a cycle)"));
                }
                _ => {
                    let names: Vec<&str> = roots
                        .iter()
                        .map(|&k| model.links[k].name.as_str())
                        .collect();
                    return Err(ctx.invalid(
                        "robot".into(),
                        format!(
                            "several root links ({}): name base_link in an overlay",
                            names.join(", ")
                        ),
                    ));
                }
            }
        }
    };
    let tip = match sel.tip_link {
        Some(name) => find_link(name, "robot.tip_link")?,
        None => default_tip(&ctx, &model, &ancestry)?,
    };

    // The path base → tip.
    let mut path = Vec::new();
    let mut cur = tip;
    while cur != base {
        let Some(j) = parent_joint[cur] else {
            return Err(RobotFileError::Invalid {
                file: sel.overlay.to_string(),
                key: "robot.tip_link".into(),
                message: format!(
                    "{file}: no path from base_link \"{}\" to tip_link \"{}\"",
                    model.links[base].name, model.links[tip].name
                ),
            });
        };
        path.push(j);
        cur = parent_link(j);
        if path.len() > model.joints.len() {
            return Err(ctx.invalid(
                format!("link[{}]", model.links[tip].name),
                "its joints form a cycle",
            ));
        }
    }
    path.reverse();
    let moving = path
        .iter()
        .filter(|&&j| is_moving(&model.joints[j].joint_type))
        .count();
    for &j in &path {
        let joint = &model.joints[j];
        let key = format!("joint[{}]", joint.name);
        if joint.mimic.is_some() {
            return Err(ctx.invalid(
                format!("{key}.mimic"),
                "a mimic joint on the base→tip path is not supported",
            ));
        }
        if !is_moving(&joint.joint_type) && joint.joint_type != JointType::Fixed {
            return Err(ctx.invalid(
                key,
                format!(
                    "a {} joint on the base→tip path is not supported (revolute, continuous, prismatic, fixed)",
                    type_name(&joint.joint_type)
                ),
            ));
        }
    }
    if moving == 0 || moving > MAX_JOINTS {
        return Err(ctx.invalid(
            "robot".into(),
            format!(
                "{moving} moving joints from \"{}\" to \"{}\", a robot has 1 to {MAX_JOINTS}",
                model.links[base].name, model.links[tip].name
            ),
        ));
    }

    // Lock values of joints off the path.
    let on_path = |j: usize| path.contains(&j);
    for (name, value) in sel.lock {
        let key = format!("lock.{name}");
        let lock_err = |message: String| RobotFileError::Invalid {
            file: sel.overlay.to_string(),
            key: key.clone(),
            message,
        };
        let Some(&j) = joint_names.get(name.as_str()) else {
            return Err(lock_err(format!("{file} has no joint \"{name}\"")));
        };
        let joint = &model.joints[j];
        if on_path(j) || !is_moving(&joint.joint_type) {
            return Err(lock_err(format!(
                "only moving joints off the base→tip path are locked (\"{name}\" is {})",
                if on_path(j) {
                    "on the path"
                } else {
                    type_name(&joint.joint_type)
                }
            )));
        }
        if joint.joint_type != JointType::Continuous
            && !(joint.limit.lower..=joint.limit.upper).contains(value)
        {
            return Err(lock_err(format!(
                "{value} is outside the joint's limits [{}, {}]",
                joint.limit.lower, joint.limit.upper
            )));
        }
    }
    let lock_value = |j: usize| -> f64 {
        let joint = &model.joints[j];
        match sel.lock.iter().find(|(n, _)| *n == joint.name) {
            Some((_, v)) => *v,
            None if joint.joint_type == JointType::Continuous => 0.0,
            None => 0.0_f64.max(joint.limit.lower).min(joint.limit.upper),
        }
    };
    // Pose of a joint's child in its parent link frame, off-path joints locked.
    let locked_pose = |j: usize| -> Pose {
        let joint = &model.joints[j];
        let origin = pose_of(&joint.origin);
        let axis = Vector3::from(joint.axis.xyz.0);
        let q = lock_value(j);
        let motion = match joint.joint_type {
            JointType::Revolute | JointType::Continuous if axis.norm() > 0.0 => Pose {
                rotation: *UnitQuaternion::from_axis_angle(&Unit::new_normalize(axis), q)
                    .to_rotation_matrix()
                    .matrix(),
                translation: Vector3::zeros(),
            },
            JointType::Prismatic if axis.norm() > 0.0 => Pose {
                rotation: Matrix3::identity(),
                translation: axis.normalize() * q,
            },
            _ => Pose::IDENTITY,
        };
        origin.compose(&motion)
    };

    // Walk the path: placements, link frames, bodies.
    let mut joints: Vec<Joint> = Vec::with_capacity(moving);
    let mut links = vec![LinkFrame {
        name: model.links[base].name.clone(),
        frame: 0,
        offset: Pose::IDENTITY,
    }];
    let mut offset = Pose::IDENTITY; // current path link in the current body frame
    // Body of each path link: None for the base body (fixed to the ground).
    let mut path_links: Vec<(usize, Option<usize>, Pose)> = vec![(base, None, Pose::IDENTITY)];
    for &j in &path {
        let joint = &model.joints[j];
        let child = link_index[joint.child.link.as_str()];
        let key = format!("joint[{}]", joint.name);
        if !is_moving(&joint.joint_type) {
            offset = offset.compose(&pose_of(&joint.origin));
        } else {
            let axis = Vector3::from(joint.axis.xyz.0);
            let norm = axis.norm();
            if norm == 0.0 {
                return Err(ctx.invalid(format!("{key}.axis"), "the axis is the zero vector"));
            }
            let kind = if joint.joint_type == JointType::Prismatic {
                JointKind::Prismatic
            } else {
                JointKind::Revolute
            };
            let limits = joint_limits(&ctx, joint, &key)?;
            let (viscous, coulomb) = match &joint.dynamics {
                Some(d) => (d.damping, d.friction),
                None => (0.0, 0.0),
            };
            if viscous < 0.0 || coulomb < 0.0 {
                return Err(ctx.invalid(
                    format!("{key}.dynamics"),
                    format!("damping {viscous} and friction {coulomb} must be >= 0"),
                ));
            }
            joints.push(Joint {
                name: joint.name.clone(),
                kind,
                dh: DhParameters {
                    theta: 0.0,
                    d: 0.0,
                    a: 0.0,
                    alpha: 0.0,
                },
                placement: Some(JointPlacement {
                    origin: offset.compose(&pose_of(&joint.origin)),
                    axis: axis / norm,
                }),
                limits,
                link: LinkInertia::ZERO,
                rotor_inertia: 0.0,
                gear_ratio: 1.0,
                viscous_friction: viscous,
                coulomb_friction: coulomb,
            });
            offset = Pose::IDENTITY;
        }
        let body = joints.len().checked_sub(1);
        links.push(LinkFrame {
            name: joint.child.link.clone(),
            frame: joints.len(),
            offset,
        });
        path_links.push((child, body, offset));
    }

    // Every link rigidly attached to a path body: the path links and the
    // subtrees hanging off them (through non-path joints, locked).
    for &(link, body, pose) in &path_links {
        let Some(body) = body else { continue };
        let mut stack = vec![(link, pose)];
        while let Some((l, pose)) = stack.pop() {
            let inertia = link_inertia(&ctx, &model.links[l], &mut warnings)?;
            let moving_path_link = l == link
                && parent_joint[l].is_some_and(|j| is_moving(&model.joints[j].joint_type));
            match inertia {
                Some(i) => {
                    let b = &mut joints[body].link;
                    *b = b.combined(&i.transformed(&pose));
                }
                None if moving_path_link => {
                    return Err(ctx.invalid(
                        format!("link[{}].inertial", model.links[l].name),
                        format!(
                            "missing: the link moves with joint \"{}\" on the base→tip path",
                            joints[body].name
                        ),
                    ));
                }
                None => {}
            }
            for &cj in &child_joints[l] {
                if on_path(cj) {
                    continue;
                }
                let child = link_index[model.joints[cj].child.link.as_str()];
                stack.push((child, pose.compose(&locked_pose(cj))));
            }
        }
    }
    // Off-path links of the base body and beyond the tip are checked too.
    for l in &model.links {
        link_inertia(&ctx, l, &mut Vec::new())?;
    }

    Ok(UrdfChain {
        name: model.name.clone(),
        joints,
        tip: offset,
        links,
        warnings,
    })
}

/// Position, velocity and effort limits from `<limit>`; a continuous joint gets
/// one turn, [−π, π] (the inverse kinematics wraps full-turn joints). Rate and
/// effort limits not given (≤ 0) and acceleration and jerk are NaN until an
/// overlay gives them.
fn joint_limits(ctx: &Ctx, joint: &urdf_rs::Joint, key: &str) -> Res<JointLimits> {
    let l = &joint.limit;
    let (min, max) = if joint.joint_type == JointType::Continuous {
        (-std::f64::consts::PI, std::f64::consts::PI)
    } else {
        if l.lower == 0.0 && l.upper == 0.0 && l.velocity == 0.0 {
            return Err(ctx.invalid(
                format!("{key}.limit"),
                "missing (required for revolute and prismatic joints)",
            ));
        }
        if l.lower > l.upper {
            return Err(ctx.invalid(
                format!("{key}.limit.lower"),
                format!("{} is above upper = {}", l.lower, l.upper),
            ));
        }
        (l.lower, l.upper)
    };
    let given = |x: f64| {
        if x.is_finite() && x > 0.0 {
            x
        } else {
            f64::NAN
        }
    };
    Ok(JointLimits {
        min,
        max,
        velocity: given(l.velocity),
        acceleration: given(l.acceleration),
        jerk: given(l.jerk),
        effort: given(l.effort),
    })
}

/// The child link of the last moving joint, if the moving joints lie on one
/// path from the root; else an error asking for `tip_link`.
fn default_tip(
    ctx: &Ctx,
    model: &urdf_rs::Robot,
    ancestry: &dyn Fn(usize) -> Res<Vec<usize>>,
) -> Res<usize> {
    let link_of = |name: &str| model.links.iter().position(|l| l.name == name);
    let mut deepest: Option<(usize, Vec<usize>)> = None;
    let mut moving = Vec::new();
    for (k, j) in model.joints.iter().enumerate() {
        if j.joint_type == JointType::Fixed {
            continue;
        }
        moving.push(k);
        let Some(child) = link_of(&j.child.link) else {
            continue;
        };
        let up = ancestry(child)?;
        if deepest.as_ref().is_none_or(|(_, d)| up.len() > d.len()) {
            deepest = Some((child, up));
        }
    }
    let Some((child, up)) = deepest else {
        return Err(ctx.invalid("robot".into(), "no moving joint"));
    };
    if let Some(&off) = moving.iter().find(|k| !up.contains(k)) {
        return Err(ctx.invalid(
            "robot".into(),
            format!(
                "the moving joints do not form one path (joint \"{}\" branches off): name tip_link in an overlay",
                model.joints[off].name
            ),
        ));
    }
    Ok(child)
}
