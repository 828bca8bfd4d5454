//! The planner's teleop mode: the newest valid `MasterPose` drives the arm through the
//! teleop controller (tremor filter, scaling, clutch, Cartesian limits, IK, jerk-limited
//! joint tracking; `services/teleop`). Master input older than
//! `teleop.master_timeout_ms` brings the tool to rest and holds it
//! (`TELEOP_MASTER_STALE`); invalid samples are refused and counted
//! (`TELEOP_INPUT_REFUSED`). Nothing here allocates per cycle.

use microrobot_messages::{MasterPose, setpoint_flags};
use microrobot_model::Robot;
use microrobot_runtime::config::{OwnedSection as _, PipelineConfig, ms_to_ns};

use crate::config::TeleopConfig;
use microrobot_runtime::stats::LatencyHistogram;
use microrobot_runtime::validate::StreamOwner;
use microrobot_teleop::{Hand, TeleopController, TeleopSettings, flags};
use microrobot_trajectory::{KinematicLimits, Sample};
use nalgebra::{Rotation3, Vector3};

/// Counters of teleop mode (cumulative).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct TeleopCounters {
    /// Master samples accepted.
    pub samples: u64,
    /// Master samples refused (not finite, quaternion not unit, clutch not 0/1,
    /// stamp from the future, or from a second device).
    pub refused: u64,
    /// Of those, samples from a second device while the followed one was live.
    pub second_device: u64,
    /// Teleop cycles without a fresh master sample.
    pub stale_cycles: u64,
    /// Cycles with an IK solution refused as a configuration flip.
    pub flips_refused: u64,
    /// Cycles stopped at the workspace edge.
    pub edge_cycles: u64,
}

/// Teleop mode: master input handling around the teleop controller.
pub struct TeleopMode {
    controller: Result<TeleopController, String>,
    timeout_ns: u64,
    /// The device followed (its iceoryx2 publisher); another takes over after
    /// `master_timeout_ms` of silence.
    device: StreamOwner,
    latest: Option<MasterPose>,
    used_seq: Option<u64>,
    refused_since_tick: bool,
    /// Counters for the status and the final log line.
    pub counters: TeleopCounters,
    /// Latency from a master sample's `stamp_ns` to the first setpoint that uses it.
    pub latency: LatencyHistogram,
}

/// The controller settings of `[teleop]` (SI already).
pub fn settings(t: &TeleopConfig) -> TeleopSettings {
    TeleopSettings {
        ratio: t.ratio,
        frame: Rotation3::from_euler_angles(t.frame_rpy[0], t.frame_rpy[1], t.frame_rpy[2]),
        filter_order: t.filter_order as usize,
        filter_cutoff_hz: t.filter_cutoff_hz,
        max_tool_velocity: t.max_tool_velocity,
        max_tool_acceleration: t.max_tool_acceleration,
        singularity_sigma_m: t.singularity_sigma,
        flip_threshold_rad: t.flip_threshold,
        workspace_tolerance_m: t.workspace_tolerance,
    }
}

/// Maps the controller's flags onto the setpoint's.
fn setpoint_bits(f: u32) -> u32 {
    let map = [
        (flags::CLUTCH_OPEN, setpoint_flags::TELEOP_CLUTCH_OPEN),
        (flags::MASTER_STALE, setpoint_flags::TELEOP_MASTER_STALE),
        (flags::WORKSPACE_EDGE, setpoint_flags::TELEOP_WORKSPACE_EDGE),
        (flags::SINGULARITY, setpoint_flags::TELEOP_SINGULARITY),
        (flags::FLIP_REFUSED, setpoint_flags::TELEOP_FLIP_REFUSED),
        (flags::INPUT_REFUSED, setpoint_flags::TELEOP_INPUT_REFUSED),
        (flags::LIMITED, setpoint_flags::TELEOP_LIMITED),
    ];
    map.iter()
        .filter(|(from, _)| f & from != 0)
        .fold(setpoint_flags::TELEOP, |acc, (_, to)| acc | to)
}

impl TeleopMode {
    /// Teleop for `robot` with `cfg`'s `[teleop]`, joints within `limits`. A section or
    /// controller that cannot be built is kept as its error: entering teleop is then
    /// refused.
    pub fn new(robot: &Robot, cfg: &PipelineConfig, limits: &KinematicLimits) -> Self {
        let teleop = TeleopConfig::from_pipeline(cfg).map_err(|e| e.to_string());
        let controller = teleop.as_ref().map_err(Clone::clone).and_then(|t| {
            TeleopController::new(
                robot,
                settings(t),
                limits,
                1.0 / cfg.rate_hz,
                Sample::default(),
            )
            .map_err(|e| e.to_string())
        });
        let master_timeout_ms = teleop
            .as_ref()
            .map_or(TeleopConfig::default().master_timeout_ms, |t| {
                t.master_timeout_ms
            });
        let timeout_ns = ms_to_ns(master_timeout_ms);
        Self {
            controller,
            timeout_ns,
            device: StreamOwner::new(timeout_ns),
            latest: None,
            used_seq: None,
            refused_since_tick: false,
            counters: TeleopCounters::default(),
            latency: LatencyHistogram::new(),
        }
    }

    /// Why teleop cannot be entered, if it cannot.
    pub fn unavailable(&self) -> Option<&str> {
        self.controller.as_ref().err().map(String::as_str)
    }

    /// Takes a master sample from `publisher` received at `now_ns`; returns whether it
    /// was accepted. One device drives the arm: samples of another publisher are refused
    /// while the followed one is live (a sample within `master_timeout_ms`); after that
    /// long a silence (the master is stale and the tool already holds) the next device
    /// takes over, from its own samples only.
    pub fn on_master(&mut self, m: &MasterPose, publisher: u128, now_ns: u64) -> bool {
        let admitted = self.device.admits(publisher, now_ns);
        let second = admitted.is_err();
        if second || !m.is_valid() || m.stamp_ns > now_ns.saturating_add(1_000_000_000) {
            self.counters.refused += 1;
            self.counters.second_device += u64::from(second);
            self.refused_since_tick = true;
            return false;
        }
        if admitted == Ok(true) {
            // A new device: nothing of the previous one's is used.
            self.latest = None;
        }
        self.device.accepted(publisher, now_ns);
        if self.latest.is_none_or(|l| l.stamp_ns <= m.stamp_ns) {
            self.latest = Some(*m);
        }
        self.counters.samples += 1;
        true
    }

    /// Enters teleop from setpoint `current` (the tool holds until the clutch engages).
    pub fn enter(&mut self, current: &Sample) -> Result<(), String> {
        match &mut self.controller {
            Ok(c) => {
                c.restart(*current);
                Ok(())
            }
            Err(e) => Err(e.clone()),
        }
    }

    /// One cycle at `now_ns`: the new setpoint and its flags (TELEOP and the rest).
    /// `hold` (the measured state is stale) brings the tool to rest as a stale master
    /// does; teleop continues once it is fresh again.
    pub fn step(&mut self, now_ns: u64, hold: bool) -> Option<(Sample, u32)> {
        let c = self.controller.as_mut().ok()?;
        let fresh = self
            .latest
            .filter(|m| !hold && now_ns.saturating_sub(m.stamp_ns) <= self.timeout_ns);
        let hand = fresh.map(|m| Hand {
            position: Vector3::from(m.position),
            clutch: m.clutch == 1,
        });
        let out = c.step(hand.as_ref());
        if let Some(m) = fresh
            && self.used_seq != Some(m.seq)
        {
            self.used_seq = Some(m.seq);
            self.latency.record(now_ns.saturating_sub(m.stamp_ns));
        }
        let mut bits = setpoint_bits(out.flags);
        if self.refused_since_tick {
            bits |= setpoint_flags::TELEOP_INPUT_REFUSED;
            self.refused_since_tick = false;
        }
        if out.flags & flags::MASTER_STALE != 0 {
            self.counters.stale_cycles += 1;
        }
        if out.flags & flags::FLIP_REFUSED != 0 {
            self.counters.flips_refused += 1;
        }
        if out.flags & flags::WORKSPACE_EDGE != 0 {
            self.counters.edge_cycles += 1;
        }
        Some((out.sample, bits))
    }
}
