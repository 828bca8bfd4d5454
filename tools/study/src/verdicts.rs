//! The seed's conclusions checked against the computed numbers. Every verdict is
//! derived from the cases, the searches and the Jacobian; nothing is written in.
//! The claims are about the seed arm: they are checked only when the robot is the
//! seed arm ([`super::units::seed_arm_difference`]); on any other robot each one
//! reports what was measured and that the claim does not apply.

use microrobot_model::{JointKind, Robot};
use serde::Serialize;

use super::units::Units;

use super::cases::{Case, Method, PARTS};
use super::kinematics::{Sweep, max_jacobian_element};
use super::mintime::{MinTime, check};
use super::motion::StudyMotion;

/// One claim of the seed and what the numbers say about it.
#[derive(Debug, Clone, Serialize)]
pub struct Verdict {
    /// Stable identifier (tests look verdicts up by it).
    pub id: &'static str,
    /// The seed's claim, with its section.
    pub claim: String,
    /// What was computed (on this robot).
    pub finding: String,
    /// Whether the numbers support the claim; `None` when it was not checked (the
    /// robot is not the seed arm).
    pub holds: Option<bool>,
    /// The outcome.
    pub status: Status,
    /// The computed value the verdict turns on (e.g. a joint number), for machines.
    pub value: String,
}

/// What became of a seed claim.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Status {
    /// Checked on the seed arm; the numbers support it.
    Confirmed,
    /// Checked on the seed arm; the numbers contradict it.
    Refuted,
    /// Not checked: the robot is not the seed arm.
    NotApplicable,
}

impl Status {
    /// Words for the report.
    pub fn label(self) -> &'static str {
        match self {
            Status::Confirmed => "confirmed",
            Status::Refuted => "refuted",
            Status::NotApplicable => "not checked (not the seed arm)",
        }
    }
}

/// A claim and what the numbers say, before deciding whether it was checked.
struct Measured {
    id: &'static str,
    claim: String,
    finding: String,
    holds: bool,
    value: String,
}

/// A peak effort of joint `i` with its unit ("12.000 N·m", "3.000 N").
fn effort(robot: &Robot, i: usize, v: f64) -> String {
    format!("{v:.3} {}", Units::of(robot, i).effort())
}

/// Peak |τ| of each joint over all cases.
fn joint_peaks(cases: &[Case], dof: usize) -> Vec<f64> {
    (0..dof)
        .map(|i| {
            cases
                .iter()
                .fold(0.0f64, |m, c| m.max(c.stats.peak_torque[i]))
        })
        .collect()
}

/// Joints among `among` whose value equals the extreme (`highest` or lowest)
/// within 1e-9 relative: ties are reported, not broken by index.
fn extreme_joints(peaks: &[f64], among: &[usize], highest: bool) -> (Vec<usize>, f64) {
    let vals = among.iter().map(|&i| peaks[i]);
    let ext = if highest {
        vals.fold(f64::NEG_INFINITY, f64::max)
    } else {
        vals.fold(f64::INFINITY, f64::min)
    };
    let tol = 1e-9 * ext.abs().max(1e-12);
    let set = among
        .iter()
        .copied()
        .filter(|&i| (peaks[i] - ext).abs() <= tol)
        .collect();
    (set, ext)
}

/// The joints whose effort is compared: the revolute ones (the seed's claims are
/// about torques), or all when there are none.
fn compared_joints(robot: &Robot) -> Vec<usize> {
    let rev: Vec<usize> = (0..robot.dof())
        .filter(|&i| robot.joints()[i].kind == JointKind::Revolute)
        .collect();
    if rev.is_empty() {
        (0..robot.dof()).collect()
    } else {
        rev
    }
}

/// Index into [`super::cases::CaseStats::rms_parts`] of the compared joints.
fn parts_kind(robot: &Robot) -> usize {
    usize::from(!robot.joints().iter().any(|j| j.kind == JointKind::Revolute))
}

/// Largest peak effort per joint type present: "1.234 N·m and 5.678 N".
fn peak_by_kind(robot: &Robot, v: &microrobot_model::JointVector) -> String {
    super::units::kinds(robot)
        .into_iter()
        .map(|k| {
            format!(
                "{:.3} {}",
                super::units::max_over(robot, k, v),
                Units(k).effort()
            )
        })
        .collect::<Vec<_>>()
        .join(" and ")
}

fn joint_list(set: &[usize]) -> String {
    let names: Vec<String> = set.iter().map(|i| format!("{}", i + 1)).collect();
    match names.len() {
        1 => format!("Joint {}", names[0]),
        _ => format!("Joints {} (tied)", names.join(" and ")),
    }
}

/// 1-based joint numbers, comma separated.
fn joined(set: &[usize]) -> String {
    set.iter()
        .map(|i| (i + 1).to_string())
        .collect::<Vec<_>>()
        .join(",")
}

fn dominant(c: &Case, kind: usize) -> usize {
    let p = c.stats.rms_parts[kind];
    (0..3).fold(0, |b, i| if p[i] > p[b] { i } else { b })
}

/// Computes every verdict. `cases` holds each method at each of `final_times`;
/// `not_seed` is how the robot differs from the seed arm (`None`: it is the seed
/// arm, and every claim is checked).
#[allow(clippy::too_many_arguments)]
pub fn compute(
    robot: &Robot,
    not_seed: Option<&str>,
    motion: &StudyMotion,
    cases: &[Case],
    mintimes: &[MinTime],
    sweeps: &[Sweep],
    final_times: &[f64],
    check_samples: usize,
) -> Vec<Verdict> {
    let dof = robot.dof();
    let mut out = Vec::new();
    let case = |m: Method, tf: f64| cases.iter().find(|c| c.method == m && c.tf == tf);
    let t_short = final_times.iter().copied().fold(f64::INFINITY, f64::min);
    let t_long = final_times
        .iter()
        .copied()
        .fold(f64::NEG_INFINITY, f64::max);

    // 1. Highest torque at joint 1.
    let peaks = joint_peaks(cases, dof);
    let among = compared_joints(robot);
    let pk = parts_kind(robot);
    let (hi_set, hi_v) = extreme_joints(&peaks, &among, true);
    let wins: Vec<String> = (0..dof)
        .map(|i| {
            let n = cases
                .iter()
                .filter(|c| {
                    (0..dof)
                        .all(|k| c.stats.peak_torque[i] >= c.stats.peak_torque[k] * (1.0 - 1e-9))
                })
                .count();
            format!("j{}: {n}", i + 1)
        })
        .collect();
    let grav = robot.gravity();
    out.push(Measured {
        id: "highest_torque_joint",
        claim: "The highest hub torque is at joint 1 (sections 5.2.1-5.2.4, 5.3, 6).".into(),
        finding: format!(
            "{} carries the highest peak {}, {} over all {} cases (cases in which each joint is highest, ties counted for each: {}). Gravity is ({:.2}, {:.2}, {:.2}) m/s² in the base frame.",
            joint_list(&hi_set),
            Units::of(robot, hi_set.first().copied().unwrap_or(0)).effort_word(),
            effort(robot, hi_set.first().copied().unwrap_or(0), hi_v),
            cases.len(),
            wins.join(", "),
            grav.x,
            grav.y,
            grav.z
        ),
        holds: hi_set.contains(&0),
        value: joined(&hi_set),
    });

    // 2. Lowest torque at joint 6 (the last joint).
    let (lo_set, lo_v) = extreme_joints(&peaks, &among, false);
    out.push(Measured {
        id: "lowest_torque_joint",
        claim: "The actuator torque of joint 6, the last, is the lowest (sections 5.2, 5.3, 6)."
            .into(),
        finding: format!(
            "{} has the lowest peak {}, {} over all cases.",
            joint_list(&lo_set),
            Units::of(robot, lo_set.first().copied().unwrap_or(0)).effort_word(),
            effort(robot, lo_set.first().copied().unwrap_or(0), lo_v)
        ),
        holds: lo_set.contains(&(dof - 1)),
        value: joined(&lo_set),
    });

    // 3. Peak torque grows with the final time.
    let mut grows = Vec::new();
    let mut all_grow = true;
    for m in Method::ALL {
        if let (Some(a), Some(b)) = (case(m, t_short), case(m, t_long)) {
            let max = |c: &Case| {
                among
                    .iter()
                    .fold(0.0f64, |x, &i| x.max(c.stats.peak_torque[i]))
            };
            all_grow &= max(b) > max(a);
            grows.push(format!(
                "{}: {} → {}",
                m.key(),
                peak_by_kind(robot, &a.stats.peak_torque),
                peak_by_kind(robot, &b.stats.peak_torque)
            ));
        }
    }
    out.push(Measured {
        id: "torque_grows_with_final_time",
        claim: "Increasing the final time dramatically increases the peak joint torque (sections 5.2.2, 5.2.4).".into(),
        finding: format!(
            "Largest peak torque over joints at tf = {t_short} s → {t_long} s: {}.",
            grows.join("; ")
        ),
        holds: all_grow,
        value: format!("{all_grow}"),
    });

    // 4. Dominant torque term: inertia at short tf, Coriolis/centrifugal at long tf.
    let mut dom = Vec::new();
    let mut seed_pattern = true;
    for m in Method::ALL {
        if let (Some(a), Some(b)) = (case(m, t_short), case(m, t_long)) {
            let (da, db) = (dominant(a, pk), dominant(b, pk));
            seed_pattern &= da == 0 && db == 1;
            let u = if pk == 0 { "N·m" } else { "N" };
            dom.push(format!(
                "{}: {} ({:.3} {u} RMS) at {t_short} s, {} ({:.3} {u} RMS) at {t_long} s",
                m.key(),
                PARTS[da],
                a.stats.rms_parts[pk][da],
                PARTS[db],
                b.stats.rms_parts[pk][db]
            ));
        }
    }
    out.push(Measured {
        id: "dominant_torque_term",
        claim: "At tf = 5 s the inertia term dominates the torque; longer final times shift the dominant term to the Coriolis and centrifugal terms (sections 5.2.2, 5.2.4).".into(),
        finding: format!(
            "Dominant part by RMS over time (over the {} joints): {}.",
            if pk == 0 { "revolute" } else { "prismatic" },
            dom.join("; ")
        ),
        holds: seed_pattern,
        value: format!("{seed_pattern}"),
    });

    // 5. Soft motion has the fewest shootings.
    let totals: Vec<(Method, usize)> = Method::ALL
        .iter()
        .map(|&m| {
            (
                m,
                cases
                    .iter()
                    .filter(|c| c.method == m)
                    .map(|c| c.stats.shootings.iter().sum::<usize>())
                    .sum(),
            )
        })
        .collect();
    let fewest = totals.iter().map(|t| t.1).min().unwrap_or(0);
    let soft_total = totals
        .iter()
        .find(|t| t.0 == Method::Soft)
        .map(|t| t.1)
        .unwrap_or(usize::MAX);
    let fewest_methods: Vec<&str> = totals
        .iter()
        .filter(|t| t.1 == fewest)
        .map(|t| t.0.key())
        .collect();
    out.push(Measured {
        id: "soft_fewest_shootings",
        claim:
            "Soft motion gives the torque history with the lowest number of shootings (section 6)."
                .into(),
        finding: format!(
            "Torque-rate sign changes summed over joints and final times: {}. Fewest: {}.",
            totals
                .iter()
                .map(|(m, n)| format!("{} {n}", m.key()))
                .collect::<Vec<_>>()
                .join(", "),
            fewest_methods.join(", ")
        ),
        holds: soft_total == fewest,
        value: fewest_methods.join(","),
    });

    // 6. The single-segment cubic exceeds the acceleration limit at the program's tf.
    let tf_prog = motion.duration.unwrap_or(t_short);
    if let Some(c) = case(Method::Cubic, tf_prog).or_else(|| case(Method::Cubic, t_short)) {
        let over: Vec<String> = (0..dof)
            .filter(|&i| {
                c.peaks.acceleration[i]
                    > robot.joints()[i].limits.acceleration * (1.0 + super::cases::LIMIT_TOL)
            })
            .map(|i| {
                let u = Units::of(robot, i);
                format!(
                    "j{} {:.3} > {:.3} {}",
                    i + 1,
                    c.peaks.acceleration[i] * u.scale(),
                    robot.joints()[i].limits.acceleration * u.scale(),
                    u.display(2)
                )
            })
            .collect();
        out.push(Measured {
            id: "cubic_exceeds_acceleration",
            claim: format!(
                "In one segment the cubic needs more acceleration than the joints allow (section 5.2.1, eq. 21; the seed prints 0.62 against 0.6 deg/s²), at tf = {} s.",
                c.tf
            ),
            finding: if over.is_empty() {
                format!("At tf = {} s the cubic stays within every acceleration limit (peak 6|θf−θi|/tf²).", c.tf)
            } else {
                format!(
                    "At tf = {} s the cubic's peak 6|θf−θi|/tf² exceeds the limit on {}.",
                    c.tf,
                    over.join(", ")
                )
            },
            holds: !over.is_empty(),
            value: format!("{}", over.len()),
        });
    }

    // 7. Joints 1 and 2 do not move the tool along z; 8. joint 6 does not move it.
    let z: Vec<f64> = (0..dof.min(2))
        .map(|j| max_jacobian_element(robot, sweeps, j, 2))
        .collect();
    let scale = robot
        .joints()
        .iter()
        .map(|j| j.dh.a.abs() + j.dh.d.abs())
        .sum::<f64>()
        .max(1e-3);
    let z_holds = z.iter().all(|v| *v <= 1e-9 * scale);
    out.push(Measured {
        id: "z_unaffected_by_joints_1_2",
        claim: "The end-effector's differential translation along Z does not depend on joints 1 and 2 (section 2.4.4, Figure 12 a-b).".into(),
        finding: format!(
            "max |∂Pz/∂q| over the sweeps and 2000 random configurations: {}.",
            z.iter()
                .enumerate()
                .map(|(j, v)| {
                    let u = Units::of(robot, j);
                    format!("joint {} {:.3e} {}", j + 1, v * u.jacobian_scale(), u.jacobian())
                })
                .collect::<Vec<_>>()
                .join(", ")
        ),
        holds: z_holds,
        value: format!("{z_holds}"),
    });
    let last = dof - 1;
    let lin: f64 = (0..3)
        .map(|a| max_jacobian_element(robot, sweeps, last, a))
        .fold(0.0, f64::max);
    let lin_holds = lin <= 1e-9 * scale;
    out.push(Measured {
        id: "last_joint_does_not_translate_tool",
        claim: "Joint 6, the last, does not move the end effector in X, Y or Z (section 2.4.4: its frame is aligned with the tool frame).".into(),
        finding: format!(
            "max |∂P/∂q{dof}| over the sweeps and 2000 random configurations: {:.3e} {}.",
            lin * Units::of(robot, last).jacobian_scale(),
            Units::of(robot, last).jacobian()
        ),
        holds: lin_holds,
        value: format!("{lin_holds}"),
    });

    // 9. The quintic at the longest tf goes back and forth.
    if let Some(c) = case(Method::Quintic, t_long) {
        let rev = c.stats.reversals.first().copied().unwrap_or(0);
        let u = Units::of(robot, 0);
        let (sc, pu) = (u.scale(), u.display(0));
        // Joint 1's turning points: where its sampled velocity changes sign.
        let turns: Vec<String> =
            c.qd.windows(2)
                .zip(c.q.iter().skip(1))
                .filter(|(w, _)| w[0][0] * w[1][0] < 0.0)
                .map(|(_, q)| format!("{:.1} {pu}", q[0] * sc))
                .collect();
        out.push(Measured {
            id: "quintic_long_time_reverses",
            claim: format!(
                "With the quintic at tf = {t_long} s joint 1 does not move monotonically: it rises to 40°, falls to −40°, then reaches θf (section 5.2.2)."
            ),
            finding: format!(
                "Joint 1's velocity changes sign {rev} times (turning at {}); its position spans [{:.2}, {:.2}] {pu} (θi = {:.2}, θf = {:.2} {pu}).",
                if turns.is_empty() { "no point".to_string() } else { turns.join(", ") },
                c.peaks.position_min[0] * sc,
                c.peaks.position_max[0] * sc,
                motion.start[0] * sc,
                motion.target[0] * sc
            ),
            holds: rev > 0,
            value: format!("{rev}"),
        });
    }

    // 10. The final times the seed selects respect the limits.
    let selected = [
        (Method::Cubic, 60.0),
        (Method::Quintic, 5.0),
        (Method::Lspb, 60.0),
        (Method::Soft, 5.0),
    ];
    let mut parts = Vec::new();
    let mut all_ok = true;
    for (m, tf) in selected {
        let why = check(robot, motion, m, tf, check_samples);
        let min = mintimes
            .iter()
            .find(|t| t.method == m)
            .and_then(|t| t.minimum)
            .map(|v| format!("{v:.3} s"))
            .unwrap_or_else(|| "none".into());
        all_ok &= why.is_none();
        parts.push(format!(
            "{} at {tf} s: {} (searched minimum {min})",
            m.key(),
            why.map(|w| format!("breaks {w}"))
                .unwrap_or_else(|| "within limits".into())
        ));
    }
    out.push(Measured {
        id: "selected_final_times_feasible",
        claim: "The final times the seed selects by inspection (cubic 60 s, quintic 5 s, LSPB 60 s, soft motion 5 s) are suitable (sections 5.2.1-5.2.4).".into(),
        finding: format!("{}.", parts.join("; ")),
        holds: all_ok,
        value: format!("{all_ok}"),
    });
    out.into_iter()
        .map(|m| Verdict {
            id: m.id,
            claim: m.claim,
            finding: m.finding,
            holds: not_seed.is_none().then_some(m.holds),
            status: match (not_seed, m.holds) {
                (Some(_), _) => Status::NotApplicable,
                (None, true) => Status::Confirmed,
                (None, false) => Status::Refuted,
            },
            value: m.value,
        })
        .collect()
}
