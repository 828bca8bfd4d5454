//! `microrobot plot FILE.mcap --out DIR`: PNG figures of a recording over wall time
//! (s since the first setpoint): `torque.png` (τ per joint), `tracking_error.png`
//! (measured q − setpoint q at the same tick, per joint) and `latency.png` (setpoint
//! stamp → torque stamp and → state stamp, µs). Drawn with the study's plot helpers.
//! Malformed messages are left out and counted per topic (a warning on stderr).

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use anyhow::{Context as _, Result, bail};

use super::{Recording, setpoint_from, state_from, torque_from};

use microrobot_study::plot::{Panel, Series, draw, thin};

/// Options of `microrobot plot`.
#[derive(Debug, Clone, clap::Args)]
pub struct PlotArgs {
    /// Recording made by `microrobot record`.
    #[arg(value_name = "FILE.mcap")]
    pub file: PathBuf,
    /// Directory for the PNGs (created if missing).
    #[arg(long, value_name = "DIR")]
    pub out: PathBuf,
}

fn grid(n: usize) -> (usize, usize) {
    let cols = if n > 1 { 2 } else { 1 };
    (n.div_ceil(cols).max(1), cols)
}

fn size(rows: usize) -> (u32, u32) {
    (1400, 80 + 320 * rows as u32)
}

/// Draws the figures; returns the files written.
pub fn plot(file: &Path, out: &Path) -> Result<Vec<PathBuf>> {
    let mut rec = Recording::read_skipping_malformed(file)?;
    let setpoints = rec.parse_skipping("setpoint", setpoint_from);
    let torques = rec.parse_skipping("torque", torque_from);
    let states = rec.parse_skipping("state", state_from);
    for line in rec.malformed_report(file) {
        eprintln!("warning: {line}");
    }
    if setpoints.is_empty() || torques.is_empty() {
        bail!(
            "{}: no setpoints or no torques recorded ({} setpoints, {} torques): nothing to plot",
            file.display(),
            setpoints.len(),
            torques.len()
        );
    }
    std::fs::create_dir_all(out).with_context(|| format!("cannot create {}", out.display()))?;
    let t0 = setpoints[0].header.stamp_ns;
    let secs = |ns: u64| (ns as f64 - t0 as f64) / 1e9;
    let dof = (setpoints[0].dof as usize).min(microrobot_messages::MAX_JOINTS);
    let mut written = Vec::new();

    // Torque per joint.
    let panels: Vec<Panel> = (0..dof)
        .map(|j| Panel {
            title: format!("joint {}", j + 1),
            x_label: "time (s)".into(),
            y_label: "τ (N·m)".into(),
            series: vec![Series {
                label: String::new(),
                color: j,
                points: thin(
                    torques
                        .iter()
                        .map(|t| (secs(t.header.stamp_ns), t.tau[j]))
                        .collect(),
                ),
            }],
            scatter: false,
            equal_axes: false,
        })
        .collect();
    let (rows, cols) = grid(dof);
    let path = out.join("torque.png");
    draw(&path, size(rows), (rows, cols), "Commanded torque", &panels)?;
    written.push(path);

    // Tracking error per joint: the state of tick k against setpoint k.
    let by_tick: HashMap<u64, &microrobot_messages::JointSetpoint> =
        setpoints.iter().map(|s| (s.header.tick, s)).collect();
    let panels: Vec<Panel> = (0..dof)
        .map(|j| Panel {
            title: format!("joint {}", j + 1),
            x_label: "time (s)".into(),
            y_label: "q − q_d (rad)".into(),
            series: vec![Series {
                label: String::new(),
                color: j,
                points: thin(
                    states
                        .iter()
                        .filter(|s| s.torque_seq != u64::MAX)
                        .filter_map(|s| {
                            by_tick
                                .get(&s.header.tick)
                                .map(|sp| (secs(s.header.stamp_ns), s.q[j] - sp.q[j]))
                        })
                        .collect(),
                ),
            }],
            scatter: false,
            equal_axes: false,
        })
        .collect();
    let path = out.join("tracking_error.png");
    draw(&path, size(rows), (rows, cols), "Tracking error", &panels)?;
    written.push(path);

    // Latency from the setpoint's publish time.
    let us = |a: u64, b: u64| (a as f64 - b as f64) / 1000.0;
    let panels = vec![Panel {
        title: "from setpoint publish".into(),
        x_label: "time (s)".into(),
        y_label: "latency (µs)".into(),
        series: vec![
            Series {
                label: "→ torque".into(),
                color: 0,
                points: thin(
                    torques
                        .iter()
                        .map(|t| {
                            let h = &t.header;
                            (secs(h.stamp_ns), us(h.stamp_ns, h.source_stamp_ns))
                        })
                        .collect(),
                ),
            },
            Series {
                label: "→ state".into(),
                color: 1,
                points: thin(
                    states
                        .iter()
                        .filter(|s| s.torque_seq != u64::MAX && s.header.source_stamp_ns > 0)
                        .map(|s| {
                            let h = &s.header;
                            (secs(h.stamp_ns), us(h.stamp_ns, h.source_stamp_ns))
                        })
                        .collect(),
                ),
            },
        ],
        scatter: false,
        equal_axes: false,
    }];
    let path = out.join("latency.png");
    draw(&path, (1400, 600), (1, 1), "Latency", &panels)?;
    written.push(path);
    Ok(written)
}

/// Runs `microrobot plot`.
pub fn main(args: PlotArgs) -> Result<()> {
    for p in plot(&args.file, &args.out)? {
        eprintln!("wrote {}", p.display());
    }
    Ok(())
}
