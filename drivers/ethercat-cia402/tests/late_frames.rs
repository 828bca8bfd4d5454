//! Late frames against the in-process emulator, with the driver process's log filter:
//! ethercrab's ERROR line per late frame stays out of the log, and the driver's own
//! summary names the lost exchanges. One test in its own binary: it installs the
//! process-wide subscriber (and the `log` bridge ethercrab's records take).

use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use microrobot_driver::{ActuatorBackend, JointVector};
use microrobot_ethercat_cia402::backend::EthercatBackend;
use microrobot_ethercat_cia402::drive_file::DriveFile;
use microrobot_ethercat_cia402::master::{Transport, pdu_loop};
use microrobot_ethercat_cia402::report::{ETHERCRAB_LATE_FRAME_TARGET, QUIET};
use microrobot_ethercat_emulator::{ChainConfig, Emulator, Fault as Inject, InProcessLink};

mod common;
use tracing_subscriber::Layer;
use tracing_subscriber::layer::SubscriberExt;
use tracing_subscriber::util::SubscriberInitExt;

/// (level, target, message, when) of every event a layer sees.
type Lines = Arc<Mutex<Vec<(tracing::Level, String, String, Instant)>>>;

struct Capture(Lines);

struct Message<'a>(&'a mut String);

impl tracing::field::Visit for Message<'_> {
    fn record_debug(&mut self, field: &tracing::field::Field, value: &dyn std::fmt::Debug) {
        if field.name() == "message" {
            *self.0 = format!("{value:?}");
        }
    }
}

impl<S: tracing::Subscriber> Layer<S> for Capture {
    fn on_event(&self, e: &tracing::Event<'_>, _: tracing_subscriber::layer::Context<'_, S>) {
        use tracing_log::NormalizeEvent as _;
        let mut message = String::new();
        e.record(&mut Message(&mut message));
        // A `log` record's own target (the bridge's callsite says "log").
        let meta = e.normalized_metadata();
        let meta = meta.as_ref().unwrap_or_else(|| e.metadata());
        if let Ok(mut l) = self.0.lock() {
            l.push((
                *meta.level(),
                meta.target().to_string(),
                message,
                Instant::now(),
            ));
        }
    }
}

/// The example drive file's first two axes (the drives' watchdog at 1 s).
fn drive_file() -> DriveFile {
    common::drive_file(2, 1.27)
}

/// Cycles for `d` (the late answers arrive meanwhile).
fn cycle_for(b: &mut EthercatBackend, d: Duration) {
    let tau = JointVector::zeros();
    let end = Instant::now() + d;
    while Instant::now() < end {
        b.write(0, 1e-3, &tau).expect("write");
        b.read(0).expect("a late frame is ridden out");
        std::thread::sleep(Duration::from_millis(1));
    }
}

/// The driver's summary lines: (lost since the last line, lost since start, when).
fn summaries(lines: &Lines) -> Vec<(u64, u64, Instant)> {
    let number = |s: &str| s.parse::<u64>().expect("a count");
    lines
        .lock()
        .expect("lines")
        .iter()
        .filter_map(|(_, _, m, t)| {
            let rest = m.strip_prefix("EtherCAT: ")?;
            let (n, rest) = rest.split_once(" exchanges lost in the last ")?;
            let (_, rest) = rest.split_once(" s, ")?;
            let (total, _) = rest.split_once(" since start")?;
            Some((number(n), number(total), *t))
        })
        .collect()
}

#[test]
fn late_frames_are_summarised_by_the_driver_not_logged_per_frame() {
    // Every event (to show ethercrab did log per late frame), and what the driver
    // process's log shows (the same filter as its binary: `report::QUIET`).
    let all: Lines = Arc::default();
    let shown: Lines = Arc::default();
    tracing_subscriber::registry()
        .with(Capture(Arc::clone(&all)))
        .with(Capture(Arc::clone(&shown)).with_filter(QUIET))
        .try_init()
        .expect("the only subscriber of this test binary");

    let e = Emulator::new(&ChainConfig::inertia_chain(2)).expect("chain");
    let emulator = e.clone();
    let connect = Box::new(move || {
        let (tx, rx, pdu_loop) = pdu_loop()?;
        let link = InProcessLink::spawn(emulator.clone(), tx, rx).expect("link thread");
        Ok(Transport::new(pdu_loop, move || link.stop()))
    });
    let period = Duration::from_millis(200);
    let mut b = EthercatBackend::new(drive_file(), &["j1", "j2"], connect)
        .expect("backend")
        .with_exchange_timeout(Duration::from_millis(20))
        .with_loss_report_period(period);
    b.on_configure().expect("configure");
    b.on_activate().expect("activate");
    let lost_before = b.exchange_stats().lost;

    // Three late frames (max_lost_cycles = 3: ridden out), answered 60 ms late.
    e.inject(Inject::DelayFrames {
        delay: Duration::from_millis(60),
        count: 3,
    })
    .expect("inject");
    cycle_for(&mut b, period * 2);
    assert!(b.exchange_stats().lost >= lost_before + 3);
    // Then two more, after the first summary.
    let deadline = Instant::now() + Duration::from_secs(10);
    while summaries(&shown).is_empty() && Instant::now() < deadline {
        cycle_for(&mut b, Duration::from_millis(20));
    }
    e.inject(Inject::DelayFrames {
        delay: Duration::from_millis(60),
        count: 2,
    })
    .expect("inject");
    cycle_for(&mut b, period * 2);
    let lost = b.exchange_stats().lost;
    assert!(lost >= lost_before + 5, "{lost}");
    b.on_shutdown();
    let periodic = summaries(&shown).len();
    drop(b); // a last summary, if a loss was not reported yet

    let per_frame = |lines: &Lines| {
        lines
            .lock()
            .expect("lines")
            .iter()
            .filter(|(l, t, _, _)| *l == tracing::Level::ERROR && t == ETHERCRAB_LATE_FRAME_TARGET)
            .count()
    };
    assert!(
        per_frame(&all) >= 1,
        "ethercrab logs a late frame it cannot match: {:?}",
        all.lock().expect("lines")
    );
    assert_eq!(per_frame(&shown), 0, "no per-frame ERROR line in the log");
    // The summaries add up to every lost exchange, each line's total is the one before
    // plus its count, and the periodic lines are at least a period apart.
    let s = summaries(&shown);
    assert!(s.len() >= 2, "a line after each burst: {s:?}");
    let mut total = 0;
    for (n, t, _) in &s {
        assert!(*n > 0, "no line without a loss: {s:?}");
        total += n;
        assert_eq!(*t, total, "{s:?}");
    }
    assert_eq!(total, lost, "{s:?}");
    for w in s[..periodic].windows(2) {
        assert!(w[1].2 - w[0].2 >= period, "rate-limited: {s:?}");
    }
    let text: Vec<String> = shown
        .lock()
        .expect("lines")
        .iter()
        .filter(|(_, _, m, _)| m.starts_with("EtherCAT: "))
        .map(|(l, _, m, _)| format!("{l} {m}"))
        .collect();
    assert!(
        text.iter().all(|m| m.starts_with("WARN ")
            && m.contains("20000 µs deadline")
            && m.contains("max_lost_cycles = 3")),
        "{text:?}"
    );
}
