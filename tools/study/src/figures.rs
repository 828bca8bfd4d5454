//! The study's figures (seed Figures 10, 12, 13, 19–34): which ones, their sizes and
//! what each one draws. Angles in degrees and lengths in millimetres, as in the seed;
//! each joint's axis in its type's unit ([`super::units::Units`]).

use std::path::Path;

use anyhow::Result;
use microrobot_model::Robot;

use super::Study;
use super::cases::{Case, Method};
use super::plot::{Panel, Series, draw, thin};
use super::units::{Units, kinds};

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

/// The y-axis unit of a quantity drawn for every joint: one unit, or one per joint
/// type present ("deg/s (revolute), mm/s (prismatic)").
fn axis_unit(robot: &Robot, f: impl Fn(Units) -> String) -> String {
    let ks = kinds(robot);
    match ks.as_slice() {
        [k] => f(Units(*k)),
        _ => ks
            .iter()
            .map(|k| format!("{} ({})", f(Units(*k)), Units(*k).kind_name()))
            .collect::<Vec<_>>()
            .join(", "),
    }
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
/// A quantity of every joint: title, time-derivative order, value at sample k of joint i.
type JointQuantity = (&'static str, usize, fn(&Case, usize, usize) -> f64);

/// Draws `job` into `out/figures/`; returns (file, width, height, caption).
pub fn draw_job(study: &Study, job: &Job, out: &Path) -> Result<(String, u32, u32, String)> {
    let robot = &study.robot;
    let dof = robot.dof();
    let name = robot.name();
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
                    let u = Units::of(robot, s.joint);
                    let (sc, js) = (u.scale(), u.jacobian_scale());
                    Panel {
                        title: format!("joint {} swept", s.joint + 1),
                        x_label: format!("q{} ({})", s.joint + 1, u.display(0)),
                        y_label: format!("∂P/∂q{} ({})", s.joint + 1, u.jacobian()),
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
                                    .map(|(q, d)| (q * sc, d[a] * js))
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
                    "{name}: Jacobian linear column of each joint against its position (others mid-range)"
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
            let u = Units::of(robot, 0);
            let sc = u.scale();
            let cs: Vec<&Case> = study.cases.iter().filter(|c| c.method == m).collect();
            let quantities: [Joint1Quantity; 4] = [
                ("position", u.display(0), |c, k| c.q[k][0]),
                ("velocity", u.display(1), |c, k| c.qd[k][0]),
                ("acceleration", u.display(2), |c, k| c.qdd[k][0]),
                ("jerk", u.display(3), |c, k| c.jerk[k][0]),
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
            let u = Units::of(robot, 0);
            let panel = Panel {
                title: format!("joint 1 {} by inverse dynamics", u.effort_word()),
                x_label: "t (s)".into(),
                y_label: format!("τ1 ({})", u.effort()),
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
                format!(
                    "{name}: {} — joint 1 {} at each final time",
                    m.title(),
                    u.effort_word()
                ),
                vec![panel],
            )
        }
        Job::Kinematics(m, k) => {
            let Some(c) = case(study, m, k) else {
                anyhow::bail!("no case for {} #{k}", m.key());
            };
            let quantities: [JointQuantity; 4] = [
                ("position", 0, |c, k, i| c.q[k][i]),
                ("velocity", 1, |c, k, i| c.qd[k][i]),
                ("acceleration", 2, |c, k, i| c.qdd[k][i]),
                ("jerk", 3, |c, k, i| c.jerk[k][i]),
            ];
            let panels = quantities
                .iter()
                .map(|(title, order, f)| Panel {
                    title: (*title).into(),
                    x_label: "t (s)".into(),
                    y_label: axis_unit(robot, |u| u.display(*order)),
                    series: (0..dof)
                        .map(|i| {
                            let u = Units::of(robot, i);
                            let sc = u.scale();
                            Series {
                                label: format!("joint {} ({})", i + 1, u.display(*order)),
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
                title: "joint efforts by inverse dynamics (RNEA)".into(),
                x_label: "t (s)".into(),
                y_label: format!("τ ({})", axis_unit(robot, |u| u.effort().to_string())),
                series: (0..dof)
                    .map(|i| Series {
                        label: format!("joint {} ({})", i + 1, Units::of(robot, i).effort()),
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
                    "{name}: {} history, {}, tf = {} s",
                    axis_unit(robot, |u| u.effort_word().to_string()),
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
