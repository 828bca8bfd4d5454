//! The actuator backend: one EtherCAT bus of CiA 402 drives in cyclic synchronous torque
//! mode (CST, 0x6060 = 10) behind the pipeline's [`ActuatorBackend`].
//!
//! | hook | on the bus |
//! |---|---|
//! | `on_configure` | [`Bus::bring_up`]: identities checked, SDO configuration, OP |
//! | `on_activate` | every axis walked to Operation enabled by [`Axis`], target torque 0 until enabled |
//! | `write` | target torque 0x6071 per axis from the joint torque ([`crate::scaling`]) |
//! | `read` | the cycle's one exchange; position 0x6064, velocity 0x606C to joint SI, `tau_applied` the target torque 0x6071 sent in it (clamped, quantised); a drive fault (statusword bit 3) as `Fault::joint(joint, 0x603F)` |
//! | `on_deactivate` | every axis walked to Switch on disabled (Disable operation first) |
//! | `on_error` | the other axes to Quick stop |
//! | `on_reset` | a drive fault: one rising edge of controlword bit 7 per faulted axis; a bus fault: the bus brought up again |
//! | `on_shutdown` | axes disabled, bus to SAFE-OP, PRE-OP, INIT |
//!
//! `write` only fills the output image; `read` sends it and receives the inputs in one
//! logical read-write, so a target torque goes out in the cycle it was written. `read`
//! runs every cycle in every lifecycle state, so the drives' watchdogs stay fed.

use std::time::{Duration, Instant};

use microrobot_driver::{ActuatorBackend, Fault, JointVector, Measured};

use crate::cia402::{Axis, AxisFault, DriveState, Statusword, Target};
use crate::drive_file::{DriveFile, Mode};
use crate::master::{BringUpError, BringUpOptions, Bus, CycleError, LostCycles, Transport, codes};
use crate::pdo::Outputs;
use crate::report::{LossReport, REPORT_PERIOD};

/// How long the enable sequence may take before it is a fault.
pub const ENABLE_TIMEOUT: Duration = Duration::from_secs(2);
/// How long disabling or a fault reset may take before it is a fault.
pub const DISABLE_TIMEOUT: Duration = Duration::from_secs(1);

/// Opens the transport a bus is brought up on (a raw socket, or an in-process link in
/// tests); called by every bring-up.
pub type Connect = Box<dyn FnMut() -> Result<Transport, BringUpError>>;

/// Timing of the cyclic exchanges since the backend was made.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct ExchangeStats {
    /// Exchanges done.
    pub count: u64,
    /// Exchanges lost (timed out).
    pub lost: u64,
    /// Longest exchange (s).
    pub max_s: f64,
    /// Sum of exchange times (s).
    pub total_s: f64,
}

impl ExchangeStats {
    /// Mean exchange time (s).
    pub fn mean_s(&self) -> f64 {
        if self.count == 0 {
            0.0
        } else {
            self.total_s / self.count as f64
        }
    }
}

/// The EtherCAT CiA 402 backend.
pub struct EthercatBackend {
    file: DriveFile,
    /// Robot joint of each axis (bus order).
    joint_of_axis: Vec<usize>,
    dof: usize,
    connect: Connect,
    bus: Option<Bus>,
    axes: Vec<Axis>,
    outputs: Vec<Outputs>,
    lost: LostCycles,
    measured: Measured,
    saturated: bool,
    period: Duration,
    exchange_timeout: Duration,
    /// With DC: SYNC0 this long after the frame reaches the drives (`None`: the
    /// master's default).
    sync0_margin: Option<Duration>,
    /// The last fault was the bus's, not a drive's: a reset brings the bus up again.
    bus_fault: bool,
    stats: ExchangeStats,
    /// Lost exchanges, counted here and logged outside the cycle; its thread starts
    /// with the first bring-up, once the settings it names are final.
    loss_report: Option<LossReport>,
    /// At most one lost-exchange line per this.
    loss_report_period: Duration,
}

/// The end of each lost-exchange log line.
fn loss_context(deadline: Duration, max_lost_cycles: u32) -> String {
    format!(
        "frames not back within the {} µs deadline; up to max_lost_cycles = {max_lost_cycles} in a row are ridden out",
        deadline.as_micros()
    )
}

/// A fault with an owned text (not in the cycle).
fn fault(joint: Option<usize>, code: u32, text: String) -> Fault {
    Fault {
        joint,
        code,
        text: text.into(),
    }
}

impl EthercatBackend {
    /// A backend for the drives in `file` moving the robot joints `joints` (names in
    /// robot order). Every robot joint needs exactly one axis; CSP axes are refused
    /// (the pipeline sends joint torques). `connect` opens the transport at configure.
    /// The cyclic exchange is bounded by half the bus cycle.
    pub fn new(file: DriveFile, joints: &[&str], connect: Connect) -> Result<Self, String> {
        let mut joint_of_axis = Vec::with_capacity(file.axes.len());
        for (i, a) in file.axes.iter().enumerate() {
            if a.mode == Mode::Csp {
                return Err(format!(
                    "axis[{i}] (joint {}): mode \"csp\" is not supported by this driver, which applies the pipeline's joint torques (use \"cst\")",
                    a.joint
                ));
            }
            let j = joints.iter().position(|n| *n == a.joint).ok_or_else(|| {
                format!(
                    "axis[{i}]: joint \"{}\" is not a joint of the robot ({})",
                    a.joint,
                    joints.join(", ")
                )
            })?;
            joint_of_axis.push(j);
        }
        if let Some(missing) = joints
            .iter()
            .enumerate()
            .find(|(j, _)| !joint_of_axis.contains(j))
        {
            return Err(format!(
                "robot joint \"{}\" has no [[axis]] in the drive file",
                missing.1
            ));
        }
        let n = file.axes.len();
        let period = Duration::from_micros(u64::from(file.bus.cycle_us));
        let exchange_timeout = period / 2;
        Ok(EthercatBackend {
            lost: LostCycles::new(file.bus.max_lost_cycles),
            file,
            joint_of_axis,
            dof: joints.len(),
            connect,
            bus: None,
            axes: vec![Axis::new(); n],
            outputs: vec![Outputs::default(); n],
            measured: Measured::default(),
            saturated: false,
            period,
            exchange_timeout,
            sync0_margin: None,
            bus_fault: false,
            stats: ExchangeStats::default(),
            loss_report: None,
            loss_report_period: REPORT_PERIOD,
        })
    }

    /// Bounds each exchange by `timeout` instead of half the cycle.
    pub fn with_exchange_timeout(mut self, timeout: Duration) -> Self {
        self.exchange_timeout = timeout;
        self
    }

    /// Writes the lost-exchange summary at most once per `period` instead of once per
    /// [`REPORT_PERIOD`].
    pub fn with_loss_report_period(mut self, period: Duration) -> Self {
        self.loss_report_period = period;
        self
    }

    /// With distributed clocks, puts SYNC0 `margin` after the frame's arrival at the
    /// drives instead of the default (the exchange timeout, at most half the cycle).
    pub fn with_sync0_margin(mut self, margin: Duration) -> Self {
        self.sync0_margin = Some(margin);
        self
    }

    /// Timing of the exchanges so far.
    pub fn exchange_stats(&self) -> ExchangeStats {
        self.stats
    }

    /// The per-axis CiA 402 drivers, bus order.
    pub fn axes(&self) -> &[Axis] {
        &self.axes
    }

    /// The bus, once configured.
    pub fn bus(&self) -> Option<&Bus> {
        self.bus.as_ref()
    }

    fn bring_up(&mut self) -> Result<(), Fault> {
        if self.loss_report.is_none() {
            let context = loss_context(self.exchange_timeout, self.file.bus.max_lost_cycles);
            let report = LossReport::spawn(self.loss_report_period, context).map_err(|e| {
                fault(
                    None,
                    codes::BRING_UP,
                    format!("cannot start the lost-exchange report thread: {e}"),
                )
            })?;
            self.loss_report = Some(report);
        }
        let up = (self.connect)()
            .and_then(|t| {
                let options = BringUpOptions {
                    exchange_timeout: self.exchange_timeout,
                    sync0_margin: self.sync0_margin,
                };
                Bus::bring_up_with(t, &self.file, options)
            })
            .map_err(|e| {
                let joint = e.axis().and_then(|a| self.joint_of_axis.get(a).copied());
                fault(joint, e.code(), e.to_string())
            })?;
        self.bus = Some(up);
        self.axes.iter_mut().for_each(|a| *a = Axis::new());
        self.outputs.fill(Outputs::default());
        self.lost = LostCycles::new(self.file.bus.max_lost_cycles);
        self.bus_fault = false;
        Ok(())
    }

    /// One cycle: outputs out, inputs in, every axis stepped. The outer error is the
    /// bus's, the inner one the first axis fault.
    fn cycle(&mut self) -> Result<Option<Fault>, Fault> {
        let Some(bus) = self.bus.as_mut() else {
            return Err(Fault::drive(codes::BUS_ERROR, "the bus is not configured"));
        };
        for (i, out) in self.outputs.iter_mut().enumerate() {
            if !self.axes[i].is_enabled() {
                out.target_torque = 0;
            }
            bus.set_outputs(i, out);
            // The torque applied is the one this exchange commands, as the drive
            // receives it (target torque 0x6071 after the clamp and the per-mille
            // quantisation), so a state names the torque of the command it answers
            // (also when the exchange is lost: the frame may have reached the drive);
            // the drive's torque actual 0x6077 lags an exchange behind it.
            self.measured.tau_applied[self.joint_of_axis[i]] = self.file.axes[i]
                .scaling
                .effort_from_torque_actual(out.target_torque);
        }
        let t0 = Instant::now();
        let r = bus.exchange();
        let dt = t0.elapsed().as_secs_f64();
        self.stats.count += 1;
        self.stats.total_s += dt;
        self.stats.max_s = self.stats.max_s.max(dt);
        match r {
            Ok(()) => self.lost.ok(),
            Err(CycleError::Lost) => {
                self.stats.lost += 1;
                if let Some(r) = &self.loss_report {
                    r.lost();
                }
                if self.lost.lost() {
                    self.bus_fault = true;
                    return Err(Fault::drive(
                        codes::BUS_LOST,
                        "EtherCAT: more than max_lost_cycles exchanges in a row lost",
                    ));
                }
                return Ok(None);
            }
            Err(CycleError::LeftOp {
                position,
                al_status_code,
            }) => {
                self.bus_fault = true;
                return Err(Fault::joint(
                    self.joint_of_axis[position],
                    codes::left_op(al_status_code),
                    "EtherCAT: drive left OP (code: AL status code in the low 16 bits)",
                ));
            }
            Err(CycleError::WorkingCounter { .. }) => {
                self.bus_fault = true;
                return Err(Fault::drive(
                    codes::WORKING_COUNTER,
                    "EtherCAT: wrong working counter (a drive not exchanging process data)",
                ));
            }
            Err(CycleError::Bus) => {
                self.bus_fault = true;
                return Err(Fault::drive(codes::BUS_ERROR, "EtherCAT: exchange failed"));
            }
        }
        let mut first = None;
        for i in 0..self.axes.len() {
            let j = self.joint_of_axis[i];
            let Some(inp) = bus.inputs(i) else {
                first.get_or_insert(Fault::joint(
                    j,
                    codes::BUS_ERROR,
                    "EtherCAT: no process image",
                ));
                continue;
            };
            let s = &self.file.axes[i].scaling;
            self.measured.q[j] = s.position_from_counts(inp.position);
            self.measured.qd[j] = s.velocity_from_counts(inp.velocity);
            let Ok(state) = Statusword(inp.statusword).state() else {
                first.get_or_insert(Fault::joint(
                    j,
                    codes::UNDEFINED_STATUSWORD,
                    "statusword 0x6041 matches no CiA 402 state",
                ));
                continue;
            };
            let step = self.axes[i].step(state, inp.error_code);
            self.outputs[i].controlword = step.controlword.bits();
            match step.fault {
                Some(AxisFault::Drive { error_code, .. }) => {
                    first.get_or_insert(Fault::joint(
                        j,
                        u32::from(error_code),
                        "drive fault (statusword bit 3; code from 0x603F)",
                    ));
                }
                Some(AxisFault::IllegalTransition { .. }) => {
                    first.get_or_insert(Fault::joint(
                        j,
                        codes::ILLEGAL_TRANSITION,
                        "illegal CiA 402 state transition",
                    ));
                }
                None => {}
            }
        }
        Ok(first)
    }

    /// Runs paced cycles until `done` or `limit`; an axis fault ends it unless
    /// `tolerate_axis_faults`. Ok(true) when done.
    fn run_until(
        &mut self,
        limit: Duration,
        tolerate_axis_faults: bool,
        done: impl Fn(&[Axis]) -> bool,
    ) -> Result<bool, Fault> {
        let start = Instant::now();
        let mut next = start;
        loop {
            match self.cycle()? {
                Some(f) if !tolerate_axis_faults => return Err(f),
                _ => {}
            }
            if done(&self.axes) {
                return Ok(true);
            }
            if start.elapsed() > limit {
                return Ok(false);
            }
            next += self.period;
            if let Some(wait) = next.checked_duration_since(Instant::now()) {
                std::thread::sleep(wait);
            }
        }
    }

    fn set_targets(&mut self, t: Target) {
        self.axes.iter_mut().for_each(|a| a.set_target(t));
    }

    fn first_not(&self, pred: impl Fn(&Axis) -> bool) -> Option<usize> {
        self.axes
            .iter()
            .position(|a| !pred(a))
            .map(|i| self.joint_of_axis[i])
    }
}

/// With DC: the phase of the exchanges against SYNC0 and each drive's SM-event missed
/// counter and sync error (0x1C32:0B, 0x1C32:20, read over SDO), into the log.
fn log_sync(bus: &Bus, file: &DriveFile) {
    let Some(p) = bus.phase() else {
        return;
    };
    tracing::info!(
        "EtherCAT DC: {} exchanges measured; margin to SYNC0 (target {} µs) last {} µs, {}; {} reached the drives after their SYNC0; {} phase corrections ({} acquisitions), {} µs in all",
        p.samples,
        p.target_margin_ns / 1000,
        p.last_margin_ns / 1000,
        match (
            p.margin_quantile_ns(0.01),
            p.margin_quantile_ns(0.5),
            p.margin_quantile_ns(0.99),
        ) {
            (Some(p1), Some(p50), Some(p99)) => format!(
                "since the last acquisition {}..{} µs (p1 {} / p50 {} / p99 {} µs, to {} µs)",
                p.min_margin_ns / 1000,
                p.max_margin_ns / 1000,
                p1 / 1000,
                p50 / 1000,
                p99 / 1000,
                p.period_ns / 1000 / crate::dc::MARGIN_BUCKETS as u64
            ),
            _ => "no window completed".to_string(),
        },
        p.late,
        p.corrections,
        p.acquisitions,
        p.shifted_ns / 1000,
    );
    for (i, c) in bus.sync_counters().iter().enumerate() {
        let joint = file.axes.get(i).map_or("?", |a| a.joint.as_str());
        match c {
            Some(c) if c.sm_event_missed > 0 || c.sync_error => tracing::warn!(
                "axis {i} (joint {joint}): SM-event missed 0x1C32:0B = {}, sync error 0x1C32:20 = {}",
                c.sm_event_missed,
                c.sync_error
            ),
            Some(_) => {}
            None => tracing::info!("axis {i} (joint {joint}): 0x1C32:0B/20 not readable"),
        }
    }
}

fn disabled(a: &Axis) -> bool {
    matches!(
        a.state(),
        Some(DriveState::SwitchOnDisabled | DriveState::NotReadyToSwitchOn)
    )
}

impl ActuatorBackend for EthercatBackend {
    fn dof(&self) -> usize {
        self.dof
    }

    fn on_configure(&mut self) -> Result<(), Fault> {
        self.bring_up()?;
        // The first exchange, so the first read has a measured state.
        self.cycle()?.map_or(Ok(()), Err)
    }

    fn on_activate(&mut self) -> Result<(), Fault> {
        self.outputs.iter_mut().for_each(|o| o.target_torque = 0);
        self.set_targets(Target::Enabled);
        if self.run_until(ENABLE_TIMEOUT, false, |a| a.iter().all(Axis::is_enabled))? {
            return Ok(());
        }
        let j = self.first_not(Axis::is_enabled);
        self.set_targets(Target::Disabled);
        Err(Fault {
            joint: j,
            code: codes::STATE_TIMEOUT,
            text: "drive not in Operation enabled within 2 s".into(),
        })
    }

    fn on_deactivate(&mut self) -> Result<(), Fault> {
        self.outputs.iter_mut().for_each(|o| o.target_torque = 0);
        self.set_targets(Target::Disabled);
        if self.run_until(DISABLE_TIMEOUT, false, |a| a.iter().all(disabled))? {
            return Ok(());
        }
        Err(Fault {
            joint: self.first_not(disabled),
            code: codes::STATE_TIMEOUT,
            text: "drive not in Switch on disabled within 1 s".into(),
        })
    }

    fn on_error(&mut self, _fault: &Fault) {
        self.outputs.iter_mut().for_each(|o| o.target_torque = 0);
        self.set_targets(Target::QuickStop);
    }

    fn on_reset(&mut self) -> Result<(), Fault> {
        self.outputs.iter_mut().for_each(|o| o.target_torque = 0);
        self.set_targets(Target::Disabled);
        if self.bus_fault {
            // The old transport goes first (an in-process link stops, a socket closes).
            self.bus = None;
            self.bring_up()?;
        }
        self.axes.iter_mut().for_each(Axis::reset);
        let clear = |a: &[Axis]| {
            a.iter()
                .all(|x| x.latched_fault().is_none() && x.state().is_some_and(|s| !s.is_fault()))
        };
        if self.run_until(DISABLE_TIMEOUT, true, clear)? {
            return Ok(());
        }
        let j = self.first_not(|x| x.state().is_some_and(|s| !s.is_fault()));
        Err(Fault {
            joint: j,
            code: codes::STATE_TIMEOUT,
            text: "fault reset did not clear the drive fault within 1 s".into(),
        })
    }

    fn on_shutdown(&mut self) {
        if self.bus.is_none() {
            return;
        }
        self.outputs.iter_mut().for_each(|o| o.target_torque = 0);
        self.set_targets(Target::Disabled);
        let _ = self.run_until(DISABLE_TIMEOUT, true, |a| a.iter().all(disabled));
        if let Some(mut bus) = self.bus.take() {
            if !self.bus_fault {
                log_sync(&bus, &self.file);
            }
            bus.shut_down();
        }
    }

    fn write(&mut self, _now_ns: u64, _period_s: f64, tau: &JointVector) -> Result<(), Fault> {
        let mut saturated = false;
        for (i, out) in self.outputs.iter_mut().enumerate() {
            let t = self.file.axes[i]
                .scaling
                .effort_to_target_torque(tau[self.joint_of_axis[i]]);
            saturated |= t.saturated;
            out.target_torque = if self.axes[i].is_enabled() {
                t.per_mille
            } else {
                0
            };
        }
        self.saturated = saturated;
        Ok(())
    }

    fn read(&mut self, _now_ns: u64) -> Result<Measured, Fault> {
        if let Some(f) = self.cycle()? {
            return Err(f);
        }
        self.measured.saturated = self.saturated;
        Ok(self.measured)
    }
}
