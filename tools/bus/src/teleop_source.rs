//! `microrobot teleop-source`: a stand-in for a master device (a haptic stylus). It
//! publishes `MasterPose` at a fixed rate on the instance's `master` stream, either a
//! synthetic hand motion — voluntary motion below 2 Hz plus physiological tremor
//! (8–12 Hz, 0.1–0.5 mm) with a clutch schedule — or a recorded one replayed from CSV.
//! A real device driver publishes the same message (messages/README.md).

use std::path::PathBuf;
use std::time::Duration;

use anyhow::{Context, bail, ensure};
use iceoryx2::prelude::*;
use microrobot_messages::{
    MasterPose, ServiceKind, monotonic_ns, open_event, open_publish_subscribe,
};
use microrobot_runtime::Shutdown;

/// Options of `microrobot teleop-source`.
#[derive(Debug, Clone, clap::Args)]
pub struct TeleopSourceArgs {
    /// Instance name of the running pipeline.
    #[arg(long, default_value = "default", value_name = "NAME")]
    pub instance: String,
    /// Publishing rate (Hz), like a haptic device's 500 Hz–1 kHz.
    #[arg(long, default_value_t = 1000.0, value_name = "HZ")]
    pub rate_hz: f64,
    /// Run time (s); default: the CSV's length, or until Ctrl-C for synthetic motion.
    #[arg(long, value_name = "DURATION", value_parser = microrobot_command_line::duration::parse)]
    pub duration: Option<f64>,
    /// Replay a recorded hand motion: CSV lines `t_s,x_m,y_m,z_m,qw,qx,qy,qz[,clutch[,grip]]`
    /// (a header line is skipped), sampled with linear interpolation.
    #[arg(long, value_name = "FILE", conflicts_with_all = ["voluntary_mm", "tremor_mm", "ramp_mm"])]
    pub csv: Option<PathBuf>,
    /// Voluntary motion amplitude per axis x,y,z (mm): a sine that starts at 0.
    #[arg(
        long,
        value_name = "X,Y,Z",
        default_value = "3,0,0",
        allow_hyphen_values = true
    )]
    pub voluntary_mm: String,
    /// Voluntary motion frequency (Hz), below 2 Hz.
    #[arg(long, default_value_t = 1.0, value_name = "HZ")]
    pub voluntary_hz: f64,
    /// Tremor amplitude (mm) on every axis (physiological: 0.1–0.5 mm).
    #[arg(long, default_value_t = 0.3, value_name = "MM")]
    pub tremor_mm: f64,
    /// Tremor frequency (Hz), physiological 8–12 Hz.
    #[arg(long, default_value_t = 10.0, value_name = "HZ")]
    pub tremor_hz: f64,
    /// A slow displacement added to the motion, x,y,z (mm), reached by a smooth (cosine)
    /// ramp over --ramp-s and then held (e.g. to drive the hand far out of the workspace).
    #[arg(long, value_name = "X,Y,Z", allow_hyphen_values = true)]
    pub ramp_mm: Option<String>,
    /// Duration of the --ramp-mm ramp (s).
    #[arg(long, default_value_t = 2.0, value_name = "DURATION", value_parser = microrobot_command_line::duration::parse)]
    pub ramp_s: f64,
    /// Clutch released during these intervals, e.g. `3-5,8-9` (s); engaged otherwise.
    #[arg(long, value_name = "A-B,...")]
    pub clutch_open: Option<String>,
    /// Publish NaN positions during these intervals (s), e.g. `4-4.05`: a broken device.
    #[arg(long, value_name = "A-B,...")]
    pub nan: Option<String>,
    /// Silence (publish nothing) during these intervals (s): a device that stalls.
    #[arg(long, value_name = "A-B,...")]
    pub silent: Option<String>,
}

/// A recorded hand motion: times and samples.
#[derive(Debug, Clone, PartialEq)]
pub struct Recording {
    t: Vec<f64>,
    pose: Vec<[f64; 7]>,
    clutch: Vec<u32>,
    grip: Vec<f64>,
}

impl Recording {
    /// Parses CSV text (`origin` names it in errors).
    pub fn parse(text: &str, origin: &str) -> anyhow::Result<Self> {
        let mut r = Recording {
            t: Vec::new(),
            pose: Vec::new(),
            clutch: Vec::new(),
            grip: Vec::new(),
        };
        for (n, line) in text.lines().enumerate() {
            let line = line.trim();
            if line.is_empty() || line.starts_with('#') {
                continue;
            }
            let cols: Vec<&str> = line.split(',').map(str::trim).collect();
            let parsed: Result<Vec<f64>, _> = cols.iter().map(|c| c.parse::<f64>()).collect();
            let Ok(v) = parsed else {
                if r.t.is_empty() && n == 0 {
                    continue; // header
                }
                bail!("{origin}:{}: not numbers: `{line}`", n + 1);
            };
            ensure!(
                (8..=10).contains(&v.len()),
                "{origin}:{}: expected t_s,x_m,y_m,z_m,qw,qx,qy,qz[,clutch[,grip]], got {} columns",
                n + 1,
                v.len()
            );
            ensure!(
                v.iter().all(|x| x.is_finite()),
                "{origin}:{}: a value is not finite",
                n + 1
            );
            if let Some(last) = r.t.last() {
                ensure!(v[0] > *last, "{origin}:{}: time must increase", n + 1);
            }
            let q = &v[4..8];
            let norm = q.iter().map(|x| x * x).sum::<f64>().sqrt();
            ensure!(
                (norm - 1.0).abs() < 1e-3,
                "{origin}:{}: the quaternion is not unit length ({norm})",
                n + 1
            );
            let clutch = v.get(8).copied().unwrap_or(1.0);
            ensure!(
                clutch == 0.0 || clutch == 1.0,
                "{origin}:{}: clutch must be 0 or 1",
                n + 1
            );
            r.t.push(v[0]);
            r.pose.push([v[1], v[2], v[3], v[4], v[5], v[6], v[7]]);
            r.clutch.push(clutch as u32);
            r.grip.push(v.get(9).copied().unwrap_or(0.0));
        }
        ensure!(r.t.len() >= 2, "{origin}: needs at least two samples");
        Ok(r)
    }

    /// Duration from the first to the last sample (s).
    pub fn duration(&self) -> f64 {
        self.t[self.t.len() - 1] - self.t[0]
    }

    /// Position, orientation, clutch and grip at `t` s after the first sample
    /// (positions interpolated linearly, orientation normalised, buttons held).
    pub fn at(&self, t: f64) -> ([f64; 3], [f64; 4], u32, f64) {
        let t = self.t[0] + t.clamp(0.0, self.duration());
        let i = self
            .t
            .partition_point(|x| *x <= t)
            .clamp(1, self.t.len() - 1);
        let (t0, t1) = (self.t[i - 1], self.t[i]);
        let u = ((t - t0) / (t1 - t0)).clamp(0.0, 1.0);
        let (a, b) = (&self.pose[i - 1], &self.pose[i]);
        let mut p = [0.0; 7];
        for ((pk, ak), bk) in p.iter_mut().zip(a).zip(b) {
            *pk = ak + u * (bk - ak);
        }
        let n = (p[3] * p[3] + p[4] * p[4] + p[5] * p[5] + p[6] * p[6]).sqrt();
        (
            [p[0], p[1], p[2]],
            [p[3] / n, p[4] / n, p[5] / n, p[6] / n],
            self.clutch[i - 1],
            self.grip[i - 1],
        )
    }
}

/// Parses `A-B,C-D` into intervals (s).
pub fn parse_intervals(text: &str, what: &str) -> anyhow::Result<Vec<(f64, f64)>> {
    text.split(',')
        .map(|part| {
            let (a, b) = part
                .split_once('-')
                .with_context(|| format!("{what}: `{part}` is not START-END (s)"))?;
            let a: f64 = a.trim().parse().with_context(|| format!("{what}: `{a}`"))?;
            let b: f64 = b.trim().parse().with_context(|| format!("{what}: `{b}`"))?;
            ensure!(
                a.is_finite() && b.is_finite() && a >= 0.0 && b > a,
                "{what}: `{part}` must have 0 <= START < END"
            );
            Ok((a, b))
        })
        .collect()
}

fn parse_xyz(text: &str, what: &str) -> anyhow::Result<[f64; 3]> {
    let v: Vec<f64> = text
        .split(',')
        .map(|s| {
            s.trim()
                .parse::<f64>()
                .with_context(|| format!("{what}: `{s}`"))
        })
        .collect::<anyhow::Result<_>>()?;
    ensure!(
        v.len() == 3 && v.iter().all(|x| x.is_finite()),
        "{what}: expected three finite numbers x,y,z"
    );
    Ok([v[0], v[1], v[2]])
}

fn inside(intervals: &[(f64, f64)], t: f64) -> bool {
    intervals.iter().any(|(a, b)| t >= *a && t < *b)
}

/// The synthetic hand motion of `args`.
#[derive(Debug, Clone, PartialEq)]
pub struct Synthetic {
    voluntary_m: [f64; 3],
    voluntary_hz: f64,
    tremor_m: f64,
    tremor_hz: f64,
    ramp_m: [f64; 3],
    ramp_s: f64,
}

impl Synthetic {
    /// From the command line; refuses frequencies outside what the options say.
    pub fn from_args(a: &TeleopSourceArgs) -> anyhow::Result<Self> {
        let v = parse_xyz(&a.voluntary_mm, "--voluntary-mm")?;
        ensure!(
            a.voluntary_hz > 0.0 && a.voluntary_hz < 2.0,
            "--voluntary-hz {}: voluntary motion is below 2 Hz",
            a.voluntary_hz
        );
        ensure!(
            a.tremor_hz > 0.0 && a.tremor_hz.is_finite() && a.tremor_hz < a.rate_hz / 2.0,
            "--tremor-hz {}: must be > 0 and below half the rate",
            a.tremor_hz
        );
        if !(8.0..=12.0).contains(&a.tremor_hz) || !(0.1..=0.5).contains(&a.tremor_mm) {
            tracing::warn!(
                "teleop-source: tremor {} mm at {} Hz is outside physiological tremor (0.1-0.5 mm, 8-12 Hz)",
                a.tremor_mm,
                a.tremor_hz
            );
        }
        ensure!(
            a.tremor_mm >= 0.0 && a.tremor_mm.is_finite(),
            "--tremor-mm {}: must be >= 0",
            a.tremor_mm
        );
        let ramp = match &a.ramp_mm {
            Some(r) => parse_xyz(r, "--ramp-mm")?,
            None => [0.0; 3],
        };
        ensure!(
            a.ramp_s > 0.0 && a.ramp_s.is_finite(),
            "--ramp-s {}: must be > 0",
            a.ramp_s
        );
        Ok(Self {
            voluntary_m: v.map(|x| x * 1e-3),
            voluntary_hz: a.voluntary_hz,
            tremor_m: a.tremor_mm * 1e-3,
            tremor_hz: a.tremor_hz,
            ramp_m: ramp.map(|x| x * 1e-3),
            ramp_s: a.ramp_s,
        })
    }

    /// Hand position at `t` (m): voluntary sine + tremor (phase-shifted per axis) + ramp.
    pub fn at(&self, t: f64) -> [f64; 3] {
        let w = 2.0 * std::f64::consts::PI;
        let r = if t >= self.ramp_s {
            1.0
        } else {
            0.5 - 0.5 * (std::f64::consts::PI * t / self.ramp_s).cos()
        };
        let mut p = [0.0; 3];
        for (k, pk) in p.iter_mut().enumerate() {
            *pk = self.voluntary_m[k] * (w * self.voluntary_hz * t).sin()
                + self.tremor_m * (w * self.tremor_hz * t + k as f64 * 2.0).sin()
                + self.ramp_m[k] * r;
        }
        p
    }
}

/// Publishes the hand motion until the duration ends or Ctrl-C.
pub fn main(args: TeleopSourceArgs) -> anyhow::Result<()> {
    ensure!(
        args.rate_hz.is_finite() && (1.0..=10_000.0).contains(&args.rate_hz),
        "--rate-hz {}: must be in [1, 10000]",
        args.rate_hz
    );
    if let Some(d) = args.duration {
        ensure!(d.is_finite() && d > 0.0, "--duration {d}: must be > 0 s");
    }
    let recording = match &args.csv {
        Some(p) => {
            let text = std::fs::read_to_string(p)
                .with_context(|| format!("cannot read {}", p.display()))?;
            Some(Recording::parse(&text, &p.display().to_string())?)
        }
        None => None,
    };
    let synthetic = Synthetic::from_args(&args)?;
    let clutch_open = match &args.clutch_open {
        Some(s) => parse_intervals(s, "--clutch-open")?,
        None => Vec::new(),
    };
    let nan = match &args.nan {
        Some(s) => parse_intervals(s, "--nan")?,
        None => Vec::new(),
    };
    let silent = match &args.silent {
        Some(s) => parse_intervals(s, "--silent")?,
        None => Vec::new(),
    };
    let duration = args
        .duration
        .or(recording.as_ref().map(Recording::duration));

    set_log_level_from_env_or(LogLevel::Error);
    let shutdown = Shutdown::new().context("cannot create the shutdown eventfd")?;
    shutdown
        .install_signal_handler()
        .context("cannot install the SIGINT/SIGTERM handler")?;
    let inst = args.instance.as_str();
    let node_name = format!("microrobot-teleop-source.{inst}.{}", std::process::id());
    let node = microrobot_runtime::node::named_node(&node_name)?;
    let publisher = open_publish_subscribe::<MasterPose>(&node, inst, ServiceKind::Master)?
        .publisher_builder()
        .create()
        .map_err(|e| anyhow::anyhow!("master publisher: {e:?}"))?;
    let notifier = open_event(&node, inst, ServiceKind::Master)?
        .notifier_builder()
        .create()
        .map_err(|e| anyhow::anyhow!("master notifier: {e:?}"))?;

    let period_ns = (1e9 / args.rate_hz).round() as u64;
    let start = monotonic_ns();
    let mut seq = 0u64;
    tracing::info!(
        "teleop-source: publishing MasterPose on `{inst}` at {} Hz",
        args.rate_hz
    );
    loop {
        if shutdown.is_requested() {
            break;
        }
        let deadline = start + seq * period_ns;
        let now = monotonic_ns();
        if deadline > now {
            std::thread::sleep(Duration::from_nanos(deadline - now));
        }
        let t = (seq * period_ns) as f64 * 1e-9;
        if duration.is_some_and(|d| t > d) {
            break;
        }
        seq += 1;
        if inside(&silent, t) {
            continue;
        }
        let (mut position, orientation, mut clutch, grip) = match &recording {
            Some(r) => r.at(t),
            None => (synthetic.at(t), [1.0, 0.0, 0.0, 0.0], 1, 0.0),
        };
        if inside(&clutch_open, t) {
            clutch = 0;
        }
        if inside(&nan, t) {
            position = [f64::NAN; 3];
        }
        let stamp = monotonic_ns();
        let m = MasterPose {
            seq,
            stamp_ns: stamp,
            device_stamp_ns: stamp - start,
            position,
            orientation,
            grip,
            clutch,
            reserved: 0,
        };
        if publisher.send_copy(m).is_ok() {
            let _ = notifier.notify();
        }
    }
    tracing::info!("teleop-source: {seq} samples published");
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn csv_replay_interpolates_and_refuses_bad_lines() {
        let text = "t_s,x,y,z,qw,qx,qy,qz,clutch\n0,0,0,0,1,0,0,0,1\n1,0.01,0,-0.02,1,0,0,0,0\n";
        let r = Recording::parse(text, "hand.csv").expect("parses");
        let (p, q, c, _) = r.at(0.5);
        assert!((p[0] - 0.005).abs() < 1e-15 && (p[2] + 0.01).abs() < 1e-15);
        assert_eq!(q, [1.0, 0.0, 0.0, 0.0]);
        assert_eq!(c, 1);
        assert_eq!(r.at(2.0).0, [0.01, 0.0, -0.02]);
        let e = Recording::parse("0,0,0,0,1,0,0,0\n0,0,0,0,1,0,0,0\n", "h.csv").unwrap_err();
        assert!(e.to_string().contains("h.csv:2: time must increase"), "{e}");
        let e = Recording::parse("0,0,0,0,2,0,0,0\n1,0,0,0,1,0,0,0\n", "h.csv").unwrap_err();
        assert!(e.to_string().contains("not unit"), "{e}");
        let e = Recording::parse("0,0,0,0,1,0,0\n", "h.csv").unwrap_err();
        assert!(e.to_string().contains("columns"), "{e}");
    }

    #[test]
    fn intervals_parse_and_refuse_reversed_ones() {
        assert_eq!(
            parse_intervals("1-2,3.5-4", "x").expect("ok"),
            vec![(1.0, 2.0), (3.5, 4.0)]
        );
        assert!(parse_intervals("2-1", "x").is_err());
        assert!(parse_intervals("a-1", "x").is_err());
    }
}
