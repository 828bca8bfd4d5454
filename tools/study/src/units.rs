//! Units by joint type, and whether a robot is the seed arm.
//!
//! Revolute joints: positions in deg (SI rad), rates in deg/s…, effort a torque in
//! N·m. Prismatic joints: mm (SI m), mm/s…, effort a force in N. Tables and figures
//! use the display units; CSV and JSON keys carry the SI unit of their joint's type.

use microrobot_model::{JointKind, JointVector, Robot};

const RAD2DEG: f64 = 180.0 / std::f64::consts::PI;

/// The units of one joint.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Units(pub JointKind);

impl Units {
    /// Units of joint `i` of `robot` (revolute when out of range).
    pub fn of(robot: &Robot, i: usize) -> Units {
        Units(
            robot
                .joints()
                .get(i)
                .map_or(JointKind::Revolute, |j| j.kind),
        )
    }

    /// SI → display factor of a position and its time derivatives.
    pub fn scale(self) -> f64 {
        match self.0 {
            JointKind::Revolute => RAD2DEG,
            JointKind::Prismatic => 1e3,
        }
    }

    /// Display unit of the `order`-th time derivative ("deg", "mm/s²").
    pub fn display(self, order: usize) -> String {
        let base = match self.0 {
            JointKind::Revolute => "deg",
            JointKind::Prismatic => "mm",
        };
        format!("{base}{}", per_time(order))
    }

    /// SI unit of the `order`-th time derivative for key names ("rad", "m_s2").
    pub fn si_key(self, order: usize) -> String {
        let base = match self.0 {
            JointKind::Revolute => "rad",
            JointKind::Prismatic => "m",
        };
        match order {
            0 => base.to_string(),
            1 => format!("{base}_s"),
            n => format!("{base}_s{n}"),
        }
    }

    /// Display unit of the effort: "N·m" or "N".
    pub fn effort(self) -> &'static str {
        match self.0 {
            JointKind::Revolute => "N·m",
            JointKind::Prismatic => "N",
        }
    }

    /// SI effort unit for key names: "nm" or "n".
    pub fn effort_key(self) -> &'static str {
        match self.0 {
            JointKind::Revolute => "nm",
            JointKind::Prismatic => "n",
        }
    }

    /// "torque" or "force".
    pub fn effort_word(self) -> &'static str {
        match self.0 {
            JointKind::Revolute => "torque",
            JointKind::Prismatic => "force",
        }
    }

    /// "revolute" or "prismatic".
    pub fn kind_name(self) -> &'static str {
        kind_name(self.0)
    }

    /// Unit of a Jacobian linear column ∂p/∂q in display form: mm/rad for a
    /// revolute joint; m/m (dimensionless) for a prismatic one.
    pub fn jacobian(self) -> &'static str {
        match self.0 {
            JointKind::Revolute => "mm/rad",
            JointKind::Prismatic => "m/m",
        }
    }

    /// SI → display factor of a Jacobian linear column (1e3 m → mm per rad; 1 for m/m).
    pub fn jacobian_scale(self) -> f64 {
        match self.0 {
            JointKind::Revolute => 1e3,
            JointKind::Prismatic => 1.0,
        }
    }
}

fn per_time(order: usize) -> &'static str {
    ["", "/s", "/s²", "/s³"]
        .get(order)
        .copied()
        .unwrap_or("/s?")
}

/// "revolute" or "prismatic".
pub fn kind_name(k: JointKind) -> &'static str {
    match k {
        JointKind::Revolute => "revolute",
        JointKind::Prismatic => "prismatic",
    }
}

/// The joint types present in `robot`, revolute first.
pub fn kinds(robot: &Robot) -> Vec<JointKind> {
    [JointKind::Revolute, JointKind::Prismatic]
        .into_iter()
        .filter(|k| robot.joints().iter().any(|j| j.kind == *k))
        .collect()
}

/// Largest of `v` over the joints of type `kind`.
pub fn max_over(robot: &Robot, kind: JointKind, v: &JointVector) -> f64 {
    (0..robot.dof())
        .filter(|&i| robot.joints()[i].kind == kind)
        .fold(0.0, |m, i| m.max(v[i]))
}

/// The seed arm's robot file, the reference its claims were made on.
const SEED_ARM_TOML: &str = include_str!("../../../config/robots/seed-arm.toml");

/// Whether `robot` is the seed arm, and if not the first difference found.
///
/// Decided by content, not by file name: the joint count and types, the DH rows
/// (or placements), every link's mass, centre of mass and inertia, the rotor
/// inertias, the tool and the payload must equal those of
/// `config/robots/seed-arm.toml` (compiled in) to 1e-9 relative. Gravity, limits,
/// friction and names are not compared: the same arm mounted or limited differently
/// is still the seed arm, and its claims are checked for that mounting and those
/// limits.
pub fn seed_arm_difference(robot: &Robot) -> Option<String> {
    let seed = match Robot::from_toml_str(SEED_ARM_TOML, "seed-arm.toml") {
        Ok(r) => r,
        Err(e) => return Some(format!("the seed arm's own file does not load: {e}")),
    };
    if robot.dof() != seed.dof() {
        return Some(format!(
            "{} joints, the seed arm has {}",
            robot.dof(),
            seed.dof()
        ));
    }
    let close = |a: f64, b: f64| (a - b).abs() <= 1e-9 * a.abs().max(b.abs()).max(1e-9);
    let all = |a: &[f64], b: &[f64]| a.iter().zip(b).all(|(x, y)| close(*x, *y));
    for (i, (j, s)) in robot.joints().iter().zip(seed.joints()).enumerate() {
        let n = i + 1;
        if j.kind != s.kind {
            return Some(format!(
                "joint {n} is {}, the seed arm's is {}",
                kind_name(j.kind),
                kind_name(s.kind)
            ));
        }
        let dh = |j: &microrobot_model::Joint| [j.dh.theta, j.dh.d, j.dh.a, j.dh.alpha];
        if j.placement.is_some() || !all(&dh(j), &dh(s)) {
            return Some(format!("joint {n}'s DH row differs from the seed arm's"));
        }
        let link = |j: &microrobot_model::Joint| {
            let l = &j.link;
            let mut v = vec![l.mass, l.com.x, l.com.y, l.com.z, j.rotor_inertia];
            v.extend(l.inertia.iter());
            v
        };
        if !all(&link(j), &link(s)) {
            return Some(format!(
                "link {n}'s mass, centre of mass, inertia or rotor inertia differs from the seed arm's"
            ));
        }
    }
    let pose = |p: &microrobot_model::Pose| {
        let mut v: Vec<f64> = p.translation.iter().copied().collect();
        v.extend(p.rotation.iter());
        v
    };
    if !all(&pose(robot.tool()), &pose(seed.tool())) {
        return Some("the tool frame differs from the seed arm's".into());
    }
    if robot.payload().is_some() != seed.payload().is_some() {
        return Some("the payload differs from the seed arm's".into());
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;

    fn robot(file: &str) -> Robot {
        let path = format!("{}/../../config/robots/{file}", env!("CARGO_MANIFEST_DIR"));
        Robot::from_file(std::path::Path::new(&path)).expect("robot loads")
    }

    #[test]
    fn the_seed_arm_is_recognised_by_content() {
        assert_eq!(seed_arm_difference(&robot("seed-arm.toml")), None);
        let rrp = seed_arm_difference(&robot("spherical-rrp.toml")).expect("not the seed");
        assert!(rrp.contains("3 joints"), "{rrp}");
        // Same file, one link heavier: not the seed arm any more.
        let text = SEED_ARM_TOML.replacen("mass_kg = 6.055", "mass_kg = 6.5", 1);
        let heavier = Robot::from_toml_str(&text, "renamed.toml").expect("loads");
        let d = seed_arm_difference(&heavier).expect("differs");
        assert!(d.contains("link 1"), "{d}");
    }

    #[test]
    fn prismatic_units_are_lengths_and_forces() {
        let u = Units(JointKind::Prismatic);
        assert_eq!(
            (u.display(0), u.display(2), u.effort(), u.si_key(1)),
            ("mm".into(), "mm/s²".into(), "N", "m_s".into())
        );
        assert_eq!((u.jacobian(), u.jacobian_scale()), ("m/m", 1.0));
        let r = Units(JointKind::Revolute);
        assert_eq!((r.display(3), r.effort_key()), ("deg/s³".into(), "nm"));
    }
}
