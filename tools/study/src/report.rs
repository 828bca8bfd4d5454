//! The written outputs: `report.md` (+ a plain `report.html` rendering of it), the
//! CSV data and `summary.json`. Tables use the seed's units (deg, mm, kg·mm²), each
//! joint in its type's unit (revolute: deg, N·m; prismatic: mm, N); the CSV files
//! and `summary.json` are SI with the unit, that of the joint's type, in every
//! column name and key.

use std::fmt::Write as _;
use std::path::Path;

use anyhow::{Context, Result};
use microrobot_model::{JointKind, JointVector, Robot};
use serde_json::{Value, json};

use super::Study;
use super::cases::{Case, Method, PARTS};
use super::figures::tf_label;
use super::units::{Units, kinds, max_over};
use super::verdicts::Status;

const RAD2DEG: f64 = 180.0 / std::f64::consts::PI;
/// Most rows of a per-case CSV file (histories are thinned evenly beyond that).
pub const CSV_ROWS: usize = 1000;

fn write(out: &Path, rel: &str, text: &str) -> Result<()> {
    let p = out.join(rel);
    std::fs::write(&p, text).with_context(|| format!("cannot write {}", p.display()))
}

fn joined(v: impl IntoIterator<Item = String>, sep: &str) -> String {
    v.into_iter().collect::<Vec<_>>().join(sep)
}

/// One joint's peaks in one case, keyed in its type's SI units.
fn case_joint(robot: &Robot, c: &Case, i: usize) -> Value {
    let u = Units::of(robot, i);
    let p = &c.peaks;
    let mut o = json!({ "joint": i + 1, "kind": u.kind_name() });
    for (name, order, x) in [
        ("position_min", 0, p.position_min[i]),
        ("position_max", 0, p.position_max[i]),
        ("peak_velocity", 1, p.velocity[i]),
        ("peak_acceleration", 2, p.acceleration[i]),
        ("peak_jerk", 3, p.jerk[i]),
        ("acc_jump", 2, c.stats.acc_jump[i]),
    ] {
        o[format!("{name}_{}", u.si_key(order))] = json!(x);
    }
    o[format!("peak_tau_{}", u.effort_key())] = json!(c.stats.peak_torque[i]);
    o[format!("rms_tau_{}", u.effort_key())] = json!(c.stats.rms_torque[i]);
    o
}

/// Writes the CSV files under `data/` and `summary.json`.
pub fn write_data(study: &Study, out: &Path) -> Result<()> {
    let dof = study.robot.dof();
    std::fs::create_dir_all(out.join("data/cases"))
        .with_context(|| format!("cannot create {}", out.join("data/cases").display()))?;

    let mut s = String::from("x_m,y_m,z_m\n");
    for p in &study.workspace.fine.points {
        let _ = writeln!(s, "{},{},{}", p.x, p.y, p.z);
    }
    write(out, "data/workspace_points.csv", &s)?;

    // One column set per joint type present; a row fills its joint's type's set.
    let ks = kinds(&study.robot);
    let mut s = String::from("joint,kind");
    for k in &ks {
        let (q, per) = (Units(*k).si_key(0), Units(*k).si_key(0));
        let _ = write!(s, ",q_{q},dpx_m_per_{per},dpy_m_per_{per},dpz_m_per_{per}");
    }
    s.push_str(",px_m,py_m,pz_m\n");
    for sw in &study.sweeps {
        let kind = Units::of(&study.robot, sw.joint);
        for k in 0..sw.q.len() {
            let (d, p) = (sw.dp[k], sw.p[k]);
            let _ = write!(s, "{},{}", sw.joint + 1, kind.kind_name());
            for kk in &ks {
                if *kk == kind.0 {
                    let _ = write!(s, ",{},{},{},{}", sw.q[k], d[0], d[1], d[2]);
                } else {
                    s.push_str(",,,,");
                }
            }
            let _ = writeln!(s, ",{},{},{}", p[0], p[1], p[2]);
        }
    }
    write(out, "data/jacobian_sweeps.csv", &s)?;

    let robot = &study.robot;
    let cols = |p: &str, order: usize| {
        joined(
            (0..dof).map(|i| format!("{p}{}_{}", i + 1, Units::of(robot, i).si_key(order))),
            ",",
        )
    };
    let effort_cols = |p: &str| {
        joined(
            (0..dof).map(|i| format!("{p}_{}_{}", Units::of(robot, i).effort_key(), i + 1)),
            ",",
        )
    };
    for c in &study.cases {
        let mut s = format!(
            "t_s,{},{},{},{},{}\n",
            cols("q", 0),
            cols("qd", 1),
            cols("qdd", 2),
            cols("jerk", 3),
            effort_cols("tau")
        );
        let n = c.t.len();
        let stride = n.div_ceil(CSV_ROWS).max(1);
        let mut ks: Vec<usize> = (0..n).step_by(stride).collect();
        if ks.last() != Some(&(n - 1)) {
            ks.push(n - 1);
        }
        for k in ks {
            let row = |v: &microrobot_model::JointVector| {
                joined((0..dof).map(|i| format!("{}", v[i])), ",")
            };
            let _ = writeln!(
                s,
                "{},{},{},{},{},{}",
                c.t[k],
                row(&c.q[k]),
                row(&c.qd[k]),
                row(&c.qdd[k]),
                row(&c.jerk[k]),
                row(&c.tau[k])
            );
        }
        write(
            out,
            &format!("data/cases/{}_{}s.csv", c.method.key(), tf_label(c.tf)),
            &s,
        )?;
    }

    let per_kind = |p: &str, order: usize| {
        joined(
            ks.iter()
                .map(|k| format!("{p}_{}", Units(*k).si_key(order))),
            ",",
        )
    };
    let mut s = format!(
        "method,tf_s,duration_s,{},{},{},{},energy_j,violations,shootings_total,{}\n",
        effort_cols("peak_tau"),
        effort_cols("rms_tau"),
        per_kind("peak_jerk", 3),
        per_kind("acc_jump", 2),
        joined((1..=dof).map(|i| format!("shootings_{i}")), ",")
    );
    let by_kind =
        |v: &JointVector| joined(ks.iter().map(|k| max_over(robot, *k, v).to_string()), ",");
    for c in &study.cases {
        let st = &c.stats;
        let _ = writeln!(
            s,
            "{},{},{},{},{},{},{},{},{},{},{}",
            c.method.key(),
            c.tf,
            c.duration,
            joined((0..dof).map(|i| format!("{}", st.peak_torque[i])), ","),
            joined((0..dof).map(|i| format!("{}", st.rms_torque[i])), ","),
            by_kind(&c.peaks.jerk),
            by_kind(&st.acc_jump),
            st.energy,
            st.violations.len(),
            st.shootings.iter().sum::<usize>(),
            joined(st.shootings.iter().map(|n| n.to_string()), ",")
        );
    }
    write(out, "data/comparison.csv", &s)?;

    let mut s = String::from("method,tf_s,joint,kind");
    for k in &ks {
        let u = Units(*k);
        let _ = write!(
            s,
            ",peak_velocity_{},peak_acceleration_{},peak_jerk_{},position_min_{p},position_max_{p}",
            u.si_key(1),
            u.si_key(2),
            u.si_key(3),
            p = u.si_key(0)
        );
    }
    s.push('\n');
    for c in &study.cases {
        for i in 0..dof {
            let p = &c.peaks;
            let u = Units::of(robot, i);
            let _ = write!(s, "{},{},{},{}", c.method.key(), c.tf, i + 1, u.kind_name());
            for k in &ks {
                if *k == u.0 {
                    let _ = write!(
                        s,
                        ",{},{},{},{},{}",
                        p.velocity[i],
                        p.acceleration[i],
                        p.jerk[i],
                        p.position_min[i],
                        p.position_max[i]
                    );
                } else {
                    s.push_str(",,,,,");
                }
            }
            s.push('\n');
        }
    }
    write(out, "data/kinematic_peaks.csv", &s)?;

    let mut s = String::from("method,kinematic_minimum_s,minimum_s,binding,evaluations\n");
    for m in &study.mintimes {
        let _ = writeln!(
            s,
            "{},{},{},{},{}",
            m.method.key(),
            m.kinematic.map(|v| v.to_string()).unwrap_or_default(),
            m.minimum.map(|v| v.to_string()).unwrap_or_default(),
            m.binding.replace(',', ";"),
            m.evaluations
        );
    }
    write(out, "data/min_final_time.csv", &s)?;

    let mut s = String::from("joint,time_optimal_soft_duration_s\n");
    for (i, d) in study.soft_alone.iter().enumerate() {
        let _ = writeln!(s, "{},{}", i + 1, d);
    }
    let _ = writeln!(s, "all,{}", study.soft_sync);
    write(out, "data/soft_time_optimal.csv", &s)?;

    let v = |x: &JointVector| (0..dof).map(|i| x[i]).collect::<Vec<f64>>();
    let all_revolute = ks == [JointKind::Revolute];
    let ws = &study.workspace.fine;
    let summary = json!({
        "robot": study.args.robot.display().to_string(),
        "program": study.args.program.display().to_string(),
        "seed_arm": study.not_seed.is_none(),
        "not_seed_arm_because": study.not_seed,
        "joints": (0..dof).map(|i| json!({
            "joint": i + 1,
            "name": robot.joints()[i].name,
            "kind": Units::of(robot, i).kind_name(),
        })).collect::<Vec<_>>(),
        "final_times_s": study.args.final_times,
        "soft_time_optimal_s": { "per_joint": study.soft_alone, "synchronised": study.soft_sync },
        "workspace": {
            "samples": ws.samples,
            "voxel_m": ws.voxel_size_m,
            "volume_m3": ws.volume_m3,
            "volume_coarse_m3": study.workspace.coarse_volume_m3,
            "bounds_min_m": [ws.bounds.min.x, ws.bounds.min.y, ws.bounds.min.z],
            "bounds_max_m": [ws.bounds.max.x, ws.bounds.max.y, ws.bounds.max.z],
        },
        "jacobian_rank_reference": study.rank,
        "jacobian_rank_max": study.max_rank,
        "cases": study.cases.iter().map(|c| {
            let mut o = json!({
                "method": c.method.key(),
                "tf_s": c.tf,
                "duration_s": c.duration,
                "energy_j": c.stats.energy,
                "shootings": c.stats.shootings,
                "joints": (0..dof).map(|i| case_joint(robot, c, i)).collect::<Vec<_>>(),
                "violations": c.stats.violations.iter().map(|x| {
                    let u = Units::of(robot, x.joint);
                    let key = if x.quantity == "torque" {
                        u.effort_key().to_string()
                    } else {
                        u.si_key(["position", "velocity", "acceleration", "jerk"]
                            .iter()
                            .position(|q| *q == x.quantity)
                            .unwrap_or(0))
                    };
                    json!({
                        "joint": x.joint + 1,
                        "quantity": if x.quantity == "torque" { u.effort_word() } else { x.quantity },
                        format!("value_{key}"): x.value,
                        format!("limit_{key}"): x.limit,
                    })
                }).collect::<Vec<_>>(),
            });
            for (kind, ki) in [(JointKind::Revolute, 0), (JointKind::Prismatic, 1)] {
                if !ks.contains(&kind) {
                    continue;
                }
                let u = Units(kind);
                let p = c.stats.rms_parts[ki];
                o[format!("acc_jump_{}", u.si_key(2))] = json!(max_over(robot, kind, &c.stats.acc_jump));
                o[format!("rms_parts_{}", u.effort_key())] =
                    json!({ "inertial": p[0], "coriolis": p[1], "gravity": p[2] });
            }
            // Per-joint arrays in one unit, for arms whose joints are all revolute.
            if all_revolute {
                o["peak_velocity_rad_s"] = json!(v(&c.peaks.velocity));
                o["peak_acceleration_rad_s2"] = json!(v(&c.peaks.acceleration));
                o["peak_jerk_rad_s3"] = json!(v(&c.peaks.jerk));
                o["peak_velocity"] = o["peak_velocity_rad_s"].clone();
                o["peak_acceleration"] = o["peak_acceleration_rad_s2"].clone();
                o["peak_torque_nm"] = json!(v(&c.stats.peak_torque));
                o["rms_torque_nm"] = json!(v(&c.stats.rms_torque));
            }
            o
        }).collect::<Vec<_>>(),
        "min_final_time": study.mintimes.iter().map(|m| json!({
            "method": m.method.key(),
            "kinematic_minimum_s": m.kinematic,
            "minimum_s": m.minimum,
            "binding": m.binding,
            "evaluations": m.evaluations,
        })).collect::<Vec<_>>(),
        "verdicts": study.verdicts,
        "figures": study.figures.iter().map(|(f, w, h, c)| json!({
            "file": f, "width": w, "height": h, "caption": c
        })).collect::<Vec<_>>(),
    });
    let text = serde_json::to_string_pretty(&summary).context("summary.json")?;
    write(out, "summary.json", &text)
}

fn f(x: f64, digits: usize) -> String {
    format!("{x:.digits$}")
}

fn table(head: &[String], rows: &[Vec<String>]) -> String {
    let mut s = format!("| {} |\n|", head.join(" | "));
    for _ in head {
        s.push_str("---|");
    }
    s.push('\n');
    for r in rows {
        let _ = writeln!(s, "| {} |", r.join(" | "));
    }
    s
}

fn case_label(c: &Case) -> String {
    format!("{} | {}", c.method.key(), tf_label(c.tf))
}

/// Writes `report.md` and `report.html`.
pub fn write_report(study: &Study, out: &Path) -> Result<()> {
    let md = markdown(study);
    write(out, "report.md", &md)?;
    write(out, "report.html", &html(&md, study.robot.name()))
}

fn markdown(study: &Study) -> String {
    let robot = &study.robot;
    let dof = robot.dof();
    let joints = robot.joints();
    let m = &study.motion;
    let mut s = String::new();
    let total: f64 = study.timings.iter().map(|t| t.1).sum();
    let _ = writeln!(s, "# Study of `{}`\n", robot.name());
    let _ = writeln!(
        s,
        "Robot file `{}`, motion program `{}` (motion \"{}\"). Everything below is computed by `microrobot study` from these two files with the model and trajectory libraries; tables are in the seed's units (degrees, millimetres, kg·mm², N·m), a prismatic joint's positions in mm and its effort, a force, in N; the CSV files under `data/` and `summary.json` are SI. Settings: final times {} s; {} time steps per trajectory; {} workspace samples; {} torque samples per check in the minimum-time search. Computation took {:.2} s ({}).\n",
        study.args.robot.display(),
        study.args.program.display(),
        m.name,
        joined(study.args.final_times.iter().map(|t| tf_label(*t)), ", "),
        study.args.steps,
        study.args.workspace_samples,
        study.args.check_samples,
        total,
        joined(
            study.timings.iter().map(|(n, t)| format!("{n} {t:.2} s")),
            ", "
        )
    );

    // Tables 2–5.
    let _ = writeln!(s, "## 1. Parameters as read (seed Tables 2–5)\n");
    let _ = writeln!(
        s,
        "### Table 2 — Denavit–Hartenberg parameters (standard DH, joint variable added to θ or d)\n"
    );
    let rows: Vec<Vec<String>> = joints
        .iter()
        .enumerate()
        .map(|(i, j)| {
            vec![
                format!("{} ({})", i + 1, j.name),
                match j.kind {
                    JointKind::Revolute => "revolute".into(),
                    JointKind::Prismatic => "prismatic".into(),
                },
                f(j.dh.theta * RAD2DEG, 3),
                f(j.dh.d * 1e3, 3),
                f(j.dh.a * 1e3, 3),
                f(j.dh.alpha * RAD2DEG, 3),
            ]
        })
        .collect();
    s += &table(
        &[
            "joint",
            "kind",
            "θ offset (deg)",
            "d (mm)",
            "a (mm)",
            "α (deg)",
        ]
        .map(String::from),
        &rows,
    );
    let _ = writeln!(s, "\n### Table 3 — Joint ranges\n");
    let rows: Vec<Vec<String>> = joints
        .iter()
        .enumerate()
        .map(|(i, j)| {
            let u = Units::of(robot, i);
            let (sc, u) = (u.scale(), u.display(0));
            vec![
                format!("{}", i + 1),
                format!("{} {u}", f(j.limits.min * sc, 3)),
                format!("{} {u}", f(j.limits.max * sc, 3)),
            ]
        })
        .collect();
    s += &table(&["joint", "min", "max"].map(String::from), &rows);
    let _ = writeln!(s, "\n### Table 4 — Trajectory parameters\n");
    let rows: Vec<Vec<String>> = joints
        .iter()
        .enumerate()
        .map(|(i, j)| {
            let u = Units::of(robot, i);
            let sc = u.scale();
            vec![
                format!("{}", i + 1),
                u.display(0),
                f(m.start[i] * sc, 3),
                f(m.target[i] * sc, 3),
                f(m.start_acc[i] * sc, 3),
                f(m.target_acc[i] * sc, 3),
                f(j.limits.velocity * sc, 3),
                f(j.limits.acceleration * sc, 3),
                f(j.limits.jerk * sc, 3),
                format!("{} {}", f(j.limits.effort, 3), u.effort()),
                f(study.soft_alone[i], 6),
            ]
        })
        .collect();
    s += &table(
        &[
            "joint",
            "unit u",
            "θi (u)",
            "θf (u)",
            "θ̈i (u/s², quintic)",
            "θ̈f (u/s², quintic)",
            "θ̇max (u/s)",
            "θ̈max (u/s²)",
            "Jmax (u/s³)",
            "effort limit",
            "time-optimal soft motion alone (s)",
        ]
        .map(String::from),
        &rows,
    );
    let _ = writeln!(
        s,
        "\nKinematic limits from {}. Quintic boundary accelerations from {}. ti = 0 s; the program's own final time: {}. All joints synchronised, the time-optimal jerk-limited motion takes **{:.6} s**.\n",
        if m.limits.is_some() {
            "the program's `[limits]` (they override the robot file's)"
        } else {
            "the robot file"
        },
        if study.args.quintic_acc_deg_s2.is_some() || study.args.quintic_acc_mm_s2.is_some() {
            "`--quintic-acc-deg-s2` / `--quintic-acc-mm-s2`"
        } else {
            "the program (0 when it gives none)"
        },
        m.duration
            .map(|d| format!("{} s", tf_label(d)))
            .unwrap_or_else(|| "not given".into()),
        study.soft_sync
    );
    let _ = writeln!(
        s,
        "### Table 5 — Inertial parameters (COM and inertia about the COM in frame i)\n"
    );
    let rows: Vec<Vec<String>> = joints
        .iter()
        .enumerate()
        .map(|(i, j)| {
            let l = &j.link;
            let k = 1e6;
            vec![
                format!("{}", i + 1),
                f(l.mass, 4),
                format!(
                    "({}, {}, {})",
                    f(l.com.x * 1e3, 3),
                    f(l.com.y * 1e3, 3),
                    f(l.com.z * 1e3, 3)
                ),
                f(l.inertia[(0, 0)] * k, 3),
                f(l.inertia[(1, 1)] * k, 3),
                f(l.inertia[(2, 2)] * k, 3),
                f(l.inertia[(0, 1)] * k, 3),
                f(l.inertia[(0, 2)] * k, 3),
                f(l.inertia[(1, 2)] * k, 3),
                match j.kind {
                    JointKind::Revolute => format!("{} kg·mm²", f(j.rotor_inertia * k, 3)),
                    JointKind::Prismatic => format!("{} kg", f(j.rotor_inertia, 4)),
                },
            ]
        })
        .collect();
    s += &table(
        &[
            "joint",
            "m (kg)",
            "COM (mm)",
            "Ixx",
            "Iyy",
            "Izz",
            "Ixy",
            "Ixz",
            "Iyz",
            "I_act (rotor; reflected mass for prismatic)",
        ]
        .map(String::from),
        &rows,
    );
    let g = robot.gravity();
    let _ = writeln!(
        s,
        "\nInertia in kg·mm². Gravity in the base frame: ({}, {}, {}) m/s² (|g| = {} m/s²).\n",
        f(g.x, 3),
        f(g.y, 3),
        f(g.z, 3),
        f(g.norm(), 3)
    );

    // Workspace.
    let ws = &study.workspace.fine;
    let _ = writeln!(s, "## 2. Reachable workspace (seed Figure 10)\n");
    let _ = writeln!(s, "![workspace](figures/workspace.png)\n");
    let (lo, hi) = (ws.bounds.min, ws.bounds.max);
    s += &table(
        &["", "X (mm)", "Y (mm)", "Z (mm)"].map(String::from),
        &[
            vec![
                "min".into(),
                f(lo.x * 1e3, 2),
                f(lo.y * 1e3, 2),
                f(lo.z * 1e3, 2),
            ],
            vec![
                "max".into(),
                f(hi.x * 1e3, 2),
                f(hi.y * 1e3, 2),
                f(hi.z * 1e3, 2),
            ],
            vec![
                "extent".into(),
                f((hi.x - lo.x) * 1e3, 2),
                f((hi.y - lo.y) * 1e3, 2),
                f((hi.z - lo.z) * 1e3, 2),
            ],
        ],
    );
    let _ = writeln!(
        s,
        "\nVolume: **{} cm³** ({} mm³) as the union of {} occupied voxels of {} mm; with voxels of {} mm: {} cm³. Tool-origin positions of {} joint-space samples drawn uniformly inside the joint limits; the voxel cover overestimates by about a boundary layer of half a voxel and converges as the voxel shrinks with more samples.\n",
        f(ws.volume_m3 * 1e6, 2),
        f(ws.volume_m3 * 1e9, 0),
        ws.occupied_voxels,
        f(ws.voxel_size_m * 1e3, 3),
        f(2.0 * ws.voxel_size_m * 1e3, 3),
        f(study.workspace.coarse_volume_m3 * 1e6, 2),
        ws.samples
    );

    // Jacobian.
    let qr = super::kinematics::reference_configuration(robot);
    let _ = writeln!(s, "## 3. Jacobian and tool paths (seed Figures 12–13)\n");
    let _ = writeln!(
        s,
        "Each joint sweeps its range while the others stay mid-range, q_ref = ({}). The Jacobian's rank at q_ref is **{}** of {}; its largest rank over 2000 random configurations inside the limits is **{}**.\n",
        joined(
            (0..dof).map(|i| {
                let u = Units::of(robot, i);
                format!("{} {}", f(qr[i] * u.scale(), 1), u.display(0))
            }),
            ", "
        ),
        study.rank,
        dof.min(6),
        study.max_rank
    );
    let _ = writeln!(
        s,
        "![Jacobian](figures/jacobian.png)\n\n![tool paths](figures/ee_paths.png)\n"
    );

    // Trajectories.
    let _ = writeln!(
        s,
        "## 4. Trajectories and torque histories (seed Figures 19–34)\n"
    );
    let _ = writeln!(
        s,
        "Motion from θi to θf of Table 4 by each method: cubic and LSPB from rest to rest, the quintic with the boundary accelerations θ̈i, θ̈f of Table 4, LSPB with cruise velocity 1.5·(θf − θi)/tf, soft motion (time-optimal jerk-limited, synchronised) stretched to the final time when that is longer than its minimum. Torques by recursive Newton–Euler inverse dynamics of the robot file, including rotor inertia and friction; sampled at {} uniform steps per trajectory.\n",
        study.args.steps
    );
    for meth in Method::ALL {
        let _ = writeln!(s, "### {} ({})\n", meth.title(), meth.seed_figures());
        let _ = writeln!(
            s,
            "![{k} joint 1](figures/{k}_joint1_final_times.png)\n\n![{k} joint 1 torque](figures/{k}_joint1_torque_final_times.png)\n",
            k = meth.key()
        );
        for c in study.cases.iter().filter(|c| c.method == meth) {
            let l = tf_label(c.tf);
            let _ = writeln!(
                s,
                "![{k} {l} s](figures/{k}_{l}s_kinematics.png)\n\n![{k} {l} s torque](figures/{k}_{l}s_torque.png)\n",
                k = meth.key()
            );
        }
    }

    // Kinematic peaks.
    let _ = writeln!(
        s,
        "### Kinematic peaks (exact extremes of the planned polynomials)\n"
    );
    for (title, order, get, lim) in [
        (
            "peak |velocity|",
            1,
            (|c: &Case, i: usize| c.peaks.velocity[i]) as fn(&Case, usize) -> f64,
            (|l: &microrobot_model::JointLimits| l.velocity)
                as fn(&microrobot_model::JointLimits) -> f64,
        ),
        (
            "peak |acceleration|",
            2,
            |c, i| c.peaks.acceleration[i],
            |l| l.acceleration,
        ),
        (
            "peak |jerk| (inside pieces)",
            3,
            |c, i| c.peaks.jerk[i],
            |l| l.jerk,
        ),
    ] {
        let mut head = vec!["method".to_string(), "tf (s)".to_string()];
        head.extend(
            (0..dof).map(|i| format!("j{} ({})", i + 1, Units::of(robot, i).display(order))),
        );
        let mut rows = vec![{
            let mut r = vec!["limit".to_string(), String::new()];
            r.extend((0..dof).map(|i| f(lim(&joints[i].limits) * Units::of(robot, i).scale(), 3)));
            r
        }];
        for c in &study.cases {
            let mut r = vec![c.method.key().to_string(), tf_label(c.tf)];
            r.extend((0..dof).map(|i| {
                let v = get(c, i);
                let over = v > lim(&joints[i].limits) * (1.0 + super::cases::LIMIT_TOL);
                let t = f(v * Units::of(robot, i).scale(), 3);
                if over { format!("**{t}**") } else { t }
            }));
            rows.push(r);
        }
        let _ = writeln!(s, "{title} (bold: above the limit)\n");
        s += &table(&head, &rows);
        s.push('\n');
    }

    // Comparison.
    let _ = writeln!(s, "## 5. Comparison of methods and final times\n");
    let _ = writeln!(
        s,
        "Energy is E = Σᵢ ∫₀^T |τᵢ·q̇ᵢ| dt (trapezoid rule on the samples): the work the actuators put in, counting braking work as spent. Shootings are sign changes of the torque rate dτᵢ/dt (first differences of the sampled torque, ignoring differences below 1e-9 of the joint's largest), summed over joints. Acceleration jump is the largest step in acceleration (from rest at the start, into rest at the end, or between pieces), i.e. where jerk is unbounded. Violations count joint limits exceeded (position range, velocity, acceleration, torque; jerk too for the quintic and soft motion, whose jerk is finite).\n"
    );
    let mut head = vec![
        "method".to_string(),
        "tf (s)".to_string(),
        "duration (s)".to_string(),
    ];
    head.extend(
        (0..dof).map(|i| format!("peak |τ| j{} ({})", i + 1, Units::of(robot, i).effort())),
    );
    let rows: Vec<Vec<String>> = study
        .cases
        .iter()
        .map(|c| {
            let mut r = vec![c.method.key().to_string(), tf_label(c.tf), f(c.duration, 3)];
            r.extend((0..dof).map(|i| f(c.stats.peak_torque[i], 3)));
            r
        })
        .collect();
    s += &table(&head, &rows);
    s.push('\n');
    let mut head = vec!["method".to_string(), "tf (s)".to_string()];
    head.extend((0..dof).map(|i| format!("RMS τ j{} ({})", i + 1, Units::of(robot, i).effort())));
    let rows: Vec<Vec<String>> = study
        .cases
        .iter()
        .map(|c| {
            let mut r = vec![c.method.key().to_string(), tf_label(c.tf)];
            r.extend((0..dof).map(|i| f(c.stats.rms_torque[i], 3)));
            r
        })
        .collect();
    s += &table(&head, &rows);
    s.push('\n');
    let ks = kinds(robot);
    let mut head = vec!["method".to_string(), "tf (s)".to_string()];
    let of = |k: JointKind| {
        if ks.len() > 1 {
            format!(", {}", Units(k).kind_name())
        } else {
            String::new()
        }
    };
    for k in &ks {
        head.push(format!("peak jerk ({}{})", Units(*k).display(3), of(*k)));
    }
    for k in &ks {
        head.push(format!("acc. jump ({}{})", Units(*k).display(2), of(*k)));
    }
    head.extend(["energy (J)", "violations", "shootings"].map(String::from));
    for k in &ks {
        head.push(format!(
            "dominant part (RMS {}{})",
            Units(*k).effort(),
            of(*k)
        ));
    }
    let rows: Vec<Vec<String>> = study
        .cases
        .iter()
        .map(|c| {
            let st = &c.stats;
            let mut r = vec![c.method.key().to_string(), tf_label(c.tf)];
            for k in &ks {
                r.push(f(max_over(robot, *k, &c.peaks.jerk) * Units(*k).scale(), 3));
            }
            for k in &ks {
                r.push(f(max_over(robot, *k, &st.acc_jump) * Units(*k).scale(), 3));
            }
            r.extend([
                f(st.energy, 4),
                st.violations.len().to_string(),
                format!(
                    "{} ({})",
                    st.shootings.iter().sum::<usize>(),
                    joined(st.shootings.iter().map(|n| n.to_string()), "/")
                ),
            ]);
            for k in &ks {
                let p = st.rms_parts[usize::from(*k == JointKind::Prismatic)];
                let d = (0..3).fold(0, |b, i| if p[i] > p[b] { i } else { b });
                r.push(format!("{} ({})", PARTS[d], f(p[d], 3)));
            }
            r
        })
        .collect();
    s += &table(&head, &rows);
    let _ = writeln!(s, "\nLimit violations:\n");
    let mut any = false;
    for c in &study.cases {
        if c.stats.violations.is_empty() {
            continue;
        }
        any = true;
        let list = joined(
            c.stats.violations.iter().map(|v| {
                let ju = Units::of(robot, v.joint);
                let sc = ju.scale();
                let (val, lim, unit) = match v.quantity {
                    "torque" => (v.value, v.limit, ju.effort().to_string()),
                    "position" => (
                        v.value * sc,
                        v.limit * sc,
                        format!("{} beyond the limit", ju.display(0)),
                    ),
                    "velocity" => (v.value * sc, v.limit * sc, ju.display(1)),
                    "acceleration" => (v.value * sc, v.limit * sc, ju.display(2)),
                    _ => (v.value * sc, v.limit * sc, ju.display(3)),
                };
                let quantity = if v.quantity == "torque" {
                    ju.effort_word()
                } else {
                    v.quantity
                };
                if v.quantity == "position" {
                    format!(
                        "j{} position {} {unit} {}",
                        v.joint + 1,
                        f(val, 3),
                        f(lim, 1)
                    )
                } else {
                    format!(
                        "j{} {} {} > {} {unit}",
                        v.joint + 1,
                        quantity,
                        f(val, 3),
                        f(lim, 3)
                    )
                }
            }),
            "; ",
        );
        let _ = writeln!(s, "- {} s: {list}", case_label(c).replace(" | ", " at "));
    }
    if !any {
        let _ = writeln!(s, "- none");
    }

    // Minimum final time.
    let _ = writeln!(
        s,
        "\n## 6. Minimum final time per method (the seed's \"optimal planning\")\n"
    );
    let _ = writeln!(
        s,
        "Shortest final time whose trajectory respects the limits the method can honour — velocity and acceleration for cubic and LSPB (their jerk is unbounded at acceleration jumps), plus jerk for the quintic and soft motion — the position range, and the torque limits. Found by search: start at the library's kinematic minimum (`minimum_duration`), grow by ×1.5 until the check passes, then bisect to 1e-6 relative. The check takes the exact kinematic peaks of the planned polynomials and evaluates the torque by inverse dynamics at {} + 1 uniformly spaced instants.\n",
        study.args.check_samples
    );
    let rows: Vec<Vec<String>> = study
        .mintimes
        .iter()
        .map(|t| {
            vec![
                t.method.key().to_string(),
                if t.method.honours_jerk() {
                    "v, a, jerk, τ"
                } else {
                    "v, a, τ"
                }
                .to_string(),
                t.kinematic.map(|v| f(v, 6)).unwrap_or_else(|| "—".into()),
                t.minimum
                    .map(|v| format!("**{}**", f(v, 6)))
                    .unwrap_or_else(|| "none ≤ 10⁴ s".into()),
                t.binding.clone(),
                t.evaluations.to_string(),
            ]
        })
        .collect();
    s += &table(
        &[
            "method",
            "limits",
            "library kinematic minimum (s)",
            "searched minimum (s)",
            "binding just below",
            "checks",
        ]
        .map(String::from),
        &rows,
    );

    // Verdicts.
    match &study.not_seed {
        None => {
            let _ = writeln!(s, "\n## 7. The seed's conclusions checked\n");
            let _ = writeln!(
                s,
                "This robot is the seed arm (its joints, DH rows, links, rotor inertias, tool and payload equal `config/robots/seed-arm.toml`'s). Each verdict is computed from the numbers above.\n"
            );
        }
        Some(why) => {
            let _ = writeln!(
                s,
                "\n## 7. What was measured on this robot (the seed's conclusions do not apply)\n"
            );
            let _ = writeln!(
                s,
                "This robot is not the seed arm: {why}. The seed's conclusions are claims about the seed arm, so none of them is checked here; for each, what was measured on this robot.\n"
            );
        }
    }
    for v in &study.verdicts {
        match v.status {
            Status::NotApplicable => {
                let _ = writeln!(
                    s,
                    "- **Not checked** — Seed claim: {} Measured on this robot: {} **Does not apply: not the seed arm.** (`{}`)",
                    v.claim, v.finding, v.id
                );
            }
            st => {
                let _ = writeln!(
                    s,
                    "- **{}** — {} Computed: {} **Verdict: {}.** (`{}`)",
                    if st == Status::Confirmed {
                        "Holds"
                    } else {
                        "Does not hold"
                    },
                    v.claim,
                    v.finding,
                    st.label(),
                    v.id
                );
            }
        }
    }

    // Files.
    let _ = writeln!(s, "\n## 8. Files\n");
    for (file, w, h, cap) in &study.figures {
        let _ = writeln!(s, "- `{file}` ({w}×{h} px): {cap}");
    }
    let _ = writeln!(
        s,
        "- `data/comparison.csv`, `data/kinematic_peaks.csv`, `data/min_final_time.csv`, `data/soft_time_optimal.csv`, `data/workspace_points.csv`, `data/jacobian_sweeps.csv`; `data/cases/<method>_<tf>s.csv`: t, q, q̇, q̈, jerk, τ of every joint (SI, in each joint's type's unit, named in the header; at most {} rows, evenly thinned); `summary.json`: every number of the tables and the verdicts (SI).",
        CSV_ROWS + 1
    );
    s
}

fn esc(t: &str) -> String {
    t.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
}

/// Inline markdown: `code`, **bold**, ![alt](src).
fn inline(t: &str) -> String {
    let mut out = String::new();
    let mut rest = t;
    while let Some(i) = rest.find("![") {
        out += &inline_text(&rest[..i]);
        let tail = &rest[i..];
        match (tail.find("]("), tail.find(')')) {
            (Some(a), Some(b)) if a < b => {
                let _ = write!(
                    out,
                    "<img alt=\"{}\" src=\"{}\" style=\"max-width:100%\">",
                    esc(&tail[2..a]),
                    esc(&tail[a + 2..b])
                );
                rest = &tail[b + 1..];
            }
            _ => {
                out += &inline_text(tail);
                rest = "";
            }
        }
    }
    out + &inline_text(rest)
}

fn inline_text(t: &str) -> String {
    let e = esc(t);
    let mut out = String::new();
    let mut bold = false;
    let mut code = false;
    let mut chars = e.chars().peekable();
    while let Some(c) = chars.next() {
        if c == '`' {
            out += if code { "</code>" } else { "<code>" };
            code = !code;
        } else if c == '*' && chars.peek() == Some(&'*') && !code {
            chars.next();
            out += if bold { "</b>" } else { "<b>" };
            bold = !bold;
        } else {
            out.push(c);
        }
    }
    out
}

/// A plain HTML rendering of the report's markdown (headings, tables, lists,
/// images, paragraphs).
fn html(md: &str, title: &str) -> String {
    let mut s = format!(
        "<!DOCTYPE html>\n<html><head><meta charset=\"utf-8\"><title>Study of {}</title>\n<style>body{{font-family:sans-serif;max-width:1400px;margin:auto}}table{{border-collapse:collapse;font-size:90%}}td,th{{border:1px solid #ccc;padding:2px 6px;text-align:right}}</style></head><body>\n",
        esc(title)
    );
    let lines: Vec<&str> = md.lines().collect();
    let mut i = 0;
    while i < lines.len() {
        let l = lines[i];
        if let Some(h) = l.strip_prefix("### ") {
            let _ = writeln!(s, "<h3>{}</h3>", inline(h));
        } else if let Some(h) = l.strip_prefix("## ") {
            let _ = writeln!(s, "<h2>{}</h2>", inline(h));
        } else if let Some(h) = l.strip_prefix("# ") {
            let _ = writeln!(s, "<h1>{}</h1>", inline(h));
        } else if l.starts_with('|') {
            s += "<table>\n";
            let mut first = true;
            while i < lines.len() && lines[i].starts_with('|') {
                let row = lines[i].trim().trim_matches('|');
                if !row.chars().all(|c| c == '-' || c == '|') {
                    let tag = if first { "th" } else { "td" };
                    s += "<tr>";
                    for cell in row.split(" | ") {
                        let _ = write!(s, "<{tag}>{}</{tag}>", inline(cell.trim()));
                    }
                    s += "</tr>\n";
                    first = false;
                }
                i += 1;
            }
            s += "</table>\n";
            continue;
        } else if l.starts_with("- ") {
            s += "<ul>\n";
            while i < lines.len() && lines[i].starts_with("- ") {
                let _ = writeln!(s, "<li>{}</li>", inline(&lines[i][2..]));
                i += 1;
            }
            s += "</ul>\n";
            continue;
        } else if !l.trim().is_empty() {
            let _ = writeln!(s, "<p>{}</p>", inline(l));
        }
        i += 1;
    }
    s + "</body></html>\n"
}
