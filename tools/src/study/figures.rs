//! The study's figures (seed Figures 10, 12, 13, 19–34): which ones, their sizes and
//! what each one draws. Angles in degrees and lengths in millimetres, as in the seed.

use std::path::Path;

use anyhow::Result;
use microrobot_model::{JointKind, Robot};

use super::Study;
use super::cases::{Case, Method};
use super::plot::{Panel, Series, draw, thin};

/// One figure to draw.
#[derive(Debug, Clone, Copy)]
pub enum Job {
    /// Workspace projections XY, XZ, YZ (Figure 10).
    Workspace,
    /// Jacobian linear column of each joint against its angle (Figure 12).
    Jacobian,
    /// Tool paths when each joint sweeps its range (Figure 13).
    Paths,
    /// Joint 1's q, qd, qdd, jerk at every final time (Figures 19, 22, 25, 28).
    Joint1(Method),
    /// Joint 1's torque at every final time (Figures 20, 23, 26, 29).
    Joint1Torque(Method),
    /// q, qd, qdd, jerk of every joint (Figures 21, 24, 27, 30).
    Kinematics(Method, usize),
    /// Torque history of every joint (Figures 31–34).
    Torque(Method, usize),
}

/// Sizes (width, height) in pixels.
pub const WIDE: (u32, u32) = (1800, 640);
/// Six-panel figures.
pub const GRID6: (u32, u32) = (1800, 1000);
/// Four-panel figures.
pub const GRID4: (u32, u32) = (1400, 1000);
/// Single-panel torque figures.
pub const SINGLE: (u32, u32) = (1200, 700);

/// Every figure of the study.
pub fn jobs(study: &Study) -> Vec<Job> {
    let mut v = vec![Job::Workspace, Job::Jacobian, Job::Paths];
    for m in Method::ALL {
        v.push(Job::Joint1(m));
        v.push(Job::Joint1Torque(m));
        for k in 0..study.args.final_times.len() {
            v.push(Job::Kinematics(m, k));
            v.push(Job::Torque(m, k));
        }
    }
    v
}

/// Display scale and unit of joint `i`'s position: degrees or millimetres.
pub fn joint_unit(robot: &Robot, i: usize) -> (f64, &'static str) {
    match robot.joints().get(i).map(|j| j.kind) {
        Some(JointKind::Prismatic) => (1e3, "mm"),
        _ => (180.0 / std::f64::consts::PI, "deg"),
    }
}

fn all_revolute(robot: &Robot) -> bool {
    robot.joints().iter().all(|j| j.kind == JointKind::Revolute)
}

/// Formats a final time for file names and legends ("5", "2.5").
pub fn tf_label(tf: f64) -> String {
    let s = format!("{tf}");
    s.trim_end_matches(".0").to_string()
}

fn case(study: &Study, m: Method, k: usize) -> Option<&Case> {
    let tf = *study.args.final_times.get(k)?;
    study.cases.iter().find(|c| c.method == m && c.tf == tf)
}

fn history(c: &Case, f: impl Fn(usize) -> f64) -> Vec<(f64, f64)> {
    thin((0..c.t.len()).map(|k| (c.t[k], f(k))).collect())
}

/// What a job draws: file name, size, grid, caption, panels.
type Figure = (String, (u32, u32), (usize, usize), String, Vec<Panel>);
/// A quantity of joint 1 over time: title, unit, value at sample k.
type Joint1Quantity = (&'static str, String, fn(&Case, usize) -> f64);
/// A quantity of every joint: title, unit suffix, value at sample k of joint i.
type JointQuantity = (&'static str, &'static str, fn(&Case, usize, usize) -> f64);

/// Draws `job` into `out/figures/`; returns (file, width, height, caption).
pub fn draw_job(study: &Study, job: &Job, out: &Path) -> Result<(String, u32, u32, String)> {
    let robot = &study.robot;
    let dof = robot.dof();
    let name = robot.name();
    let ang = if all_revolute(robot) {
        "deg"
    } else {
        "deg or mm"
    };
    let (file, size, grid, caption, panels): Figure = match *job {
        Job::Workspace => {
            let pts = &study.workspace.fine.points;
            let proj = |a: usize, b: usize, ta: &str, tb: &str| Panel {
                title: format!("{ta}{tb} projection"),
                x_label: format!("{ta} (mm)"),
                y_label: format!("{tb} (mm)"),
                series: vec![Series {
                    label: String::new(),
                    color: 0,
                    points: pts.iter().map(|p| (p[a] * 1e3, p[b] * 1e3)).collect(),
                }],
                scatter: true,
                equal_axes: true,
            };
            (
                "workspace.png".into(),
                WIDE,
                (1, 3),
                format!(
                    "{name}: reachable workspace of the tool origin ({} of {} samples shown)",
                    pts.len(),
                    study.workspace.fine.samples
                ),
                vec![
                    proj(0, 1, "X", "Y"),
                    proj(0, 2, "X", "Z"),
                    proj(1, 2, "Y", "Z"),
                ],
            )
        }
        Job::Jacobian => {
            let panels = study
                .sweeps
                .iter()
                .map(|s| {
                    let (sc, u) = joint_unit(robot, s.joint);
                    let per = if u == "deg" { "mm/rad" } else { "mm/mm" };
                    Panel {
                        title: format!("joint {} swept", s.joint + 1),
                        x_label: format!("q{} ({u})", s.joint + 1),
                        y_label: format!("∂P/∂q{} ({per})", s.joint + 1),
                        series: ["dPx", "dPy", "dPz"]
                            .iter()
                            .enumerate()
                            .map(|(a, l)| Series {
                                label: (*l).into(),
                                color: a,
                                points: s
                                    .q
                                    .iter()
                                    .zip(&s.dp)
                                    .map(|(q, d)| (q * sc, d[a] * 1e3))
                                    .collect(),
                            })
                            .collect(),
                        scatter: false,
                        equal_axes: false,
                    }
                })
                .collect();
            let cols = dof.min(3);
            (
                "jacobian.png".into(),
                GRID6,
                (dof.div_ceil(cols), cols),
                format!(
                    "{name}: Jacobian linear column of each joint against its angle (others mid-range)"
                ),
                panels,
            )
        }
        Job::Paths => {
            let proj = |a: usize, b: usize, ta: &str, tb: &str| Panel {
                title: format!("tool paths, {ta}{tb}"),
                x_label: format!("{ta} (mm)"),
                y_label: format!("{tb} (mm)"),
                series: study
                    .sweeps
                    .iter()
                    .map(|s| Series {
                        label: format!("joint {}", s.joint + 1),
                        color: s.joint,
                        points: s.p.iter().map(|p| (p[a] * 1e3, p[b] * 1e3)).collect(),
                    })
                    .collect(),
                scatter: false,
                equal_axes: true,
            };
            (
                "ee_paths.png".into(),
                WIDE,
                (1, 3),
                format!("{name}: tool path as each joint sweeps its range (others mid-range)"),
                vec![
                    proj(0, 1, "X", "Y"),
                    proj(0, 2, "X", "Z"),
                    proj(1, 2, "Y", "Z"),
                ],
            )
        }
        Job::Joint1(m) => {
            let (sc, u) = joint_unit(robot, 0);
            let cs: Vec<&Case> = study.cases.iter().filter(|c| c.method == m).collect();
            let quantities: [Joint1Quantity; 4] = [
                ("position", u.to_string(), |c, k| c.q[k][0]),
                ("velocity", format!("{u}/s"), |c, k| c.qd[k][0]),
                ("acceleration", format!("{u}/s²"), |c, k| c.qdd[k][0]),
                ("jerk", format!("{u}/s³"), |c, k| c.jerk[k][0]),
            ];
            let panels = quantities
                .iter()
                .map(|(title, unit, f)| Panel {
                    title: format!("joint 1 {title}"),
                    x_label: "t (s)".into(),
                    y_label: unit.clone(),
                    series: cs
                        .iter()
                        .enumerate()
                        .map(|(i, c)| Series {
                            label: format!("tf = {} s", tf_label(c.tf)),
                            color: i,
                            points: history(c, |k| f(c, k) * sc),
                        })
                        .collect(),
                    scatter: false,
                    equal_axes: false,
                })
                .collect();
            (
                format!("{}_joint1_final_times.png", m.key()),
                GRID4,
                (2, 2),
                format!("{name}: {} — joint 1 at each final time", m.title()),
                panels,
            )
        }
        Job::Joint1Torque(m) => {
            let cs: Vec<&Case> = study.cases.iter().filter(|c| c.method == m).collect();
            let panel = Panel {
                title: "joint 1 torque by inverse dynamics".into(),
                x_label: "t (s)".into(),
                y_label: "τ1 (N·m)".into(),
                series: cs
                    .iter()
                    .enumerate()
                    .map(|(i, c)| Series {
                        label: format!("tf = {} s", tf_label(c.tf)),
                        color: i,
                        points: history(c, |k| c.tau[k][0]),
                    })
                    .collect(),
                scatter: false,
                equal_axes: false,
            };
            (
                format!("{}_joint1_torque_final_times.png", m.key()),
                SINGLE,
                (1, 1),
                format!("{name}: {} — joint 1 torque at each final time", m.title()),
                vec![panel],
            )
        }
        Job::Kinematics(m, k) => {
            let Some(c) = case(study, m, k) else {
                anyhow::bail!("no case for {} #{k}", m.key());
            };
            let quantities: [JointQuantity; 4] = [
                ("position", "", |c, k, i| c.q[k][i]),
                ("velocity", "/s", |c, k, i| c.qd[k][i]),
                ("acceleration", "/s²", |c, k, i| c.qdd[k][i]),
                ("jerk", "/s³", |c, k, i| c.jerk[k][i]),
            ];
            let panels = quantities
                .iter()
                .map(|(title, per, f)| Panel {
                    title: (*title).into(),
                    x_label: "t (s)".into(),
                    y_label: format!("{ang}{per}"),
                    series: (0..dof)
                        .map(|i| {
                            let (sc, _) = joint_unit(robot, i);
                            Series {
                                label: format!("joint {}", i + 1),
                                color: i,
                                points: history(c, |k| f(c, k, i) * sc),
                            }
                        })
                        .collect(),
                    scatter: false,
                    equal_axes: false,
                })
                .collect();
            (
                format!("{}_{}s_kinematics.png", m.key(), tf_label(c.tf)),
                GRID4,
                (2, 2),
                format!(
                    "{name}: {}, tf = {} s (duration {:.3} s)",
                    m.title(),
                    tf_label(c.tf),
                    c.duration
                ),
                panels,
            )
        }
        Job::Torque(m, k) => {
            let Some(c) = case(study, m, k) else {
                anyhow::bail!("no case for {} #{k}", m.key());
            };
            let panel = Panel {
                title: "joint torques by inverse dynamics (RNEA)".into(),
                x_label: "t (s)".into(),
                y_label: "τ (N·m)".into(),
                series: (0..dof)
                    .map(|i| Series {
                        label: format!("joint {}", i + 1),
                        color: i,
                        points: history(c, |k| c.tau[k][i]),
                    })
                    .collect(),
                scatter: false,
                equal_axes: false,
            };
            (
                format!("{}_{}s_torque.png", m.key(), tf_label(c.tf)),
                SINGLE,
                (1, 1),
                format!(
                    "{name}: torque history, {}, tf = {} s",
                    m.title(),
                    tf_label(c.tf)
                ),
                vec![panel],
            )
        }
    };
    let rel = format!("figures/{file}");
    draw(&out.join(&rel), size, grid, &caption, &panels)?;
    Ok((rel, size.0, size.1, caption))
}
