//! Debug probe for a running pipeline: prints every service's status for a while and,
//! optionally, sends one motion command first.
//!
//! `cargo run -p microrobot-runtime --example probe -- INSTANCE SECONDS [move q1,q2,..|stop|estop|reset]`

use iceoryx2::prelude::*;
use microrobot_messages::*;

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().collect();
    if args.get(1).map(String::as_str) == Some("floor") {
        // `probe floor RATE_HZ SECONDS`: the bare timer loop with the default RT settings.
        let rate: f64 = args.get(2).and_then(|s| s.parse().ok()).unwrap_or(1000.0);
        let secs: f64 = args.get(3).and_then(|s| s.parse().ok()).unwrap_or(10.0);
        let cfg = microrobot_runtime::PipelineConfig::default();
        let _rt = microrobot_runtime::rt::apply(&cfg.realtime);
        let r = microrobot_runtime::timer::floor_probe(
            (1e9 / rate) as u64,
            (secs * 1e9) as u64,
            cfg.realtime.overrun,
        )?;
        println!(
            "floor {rate} Hz {secs} s: ticks {} misses {} lateness p50/p99/p99.9/max = {}/{}/{}/{} us",
            r.ticks,
            r.deadline_misses,
            r.lateness.p50_ns / 1000,
            r.lateness.p99_ns / 1000,
            r.lateness.p999_ns / 1000,
            r.lateness.max_ns / 1000
        );
        return Ok(());
    }
    let inst = args.get(1).cloned().unwrap_or_else(|| "default".into());
    let secs: f64 = args.get(2).and_then(|s| s.parse().ok()).unwrap_or(2.0);
    let node = NodeBuilder::new()
        .signal_handling_mode(SignalHandlingMode::Disabled)
        .create::<ipc::Service>()?;
    let status = open_publish_subscribe::<ServiceStatus>(&node, &inst, ServiceKind::Status)?
        .subscriber_builder()
        .create()
        .map_err(|e| anyhow::anyhow!("{e:?}"))?;
    if let Some(cmd) = args.get(3) {
        let publisher =
            open_publish_subscribe::<MotionCommand>(&node, &inst, ServiceKind::Command)?
                .publisher_builder()
                .create()
                .map_err(|e| anyhow::anyhow!("{e:?}"))?;
        let notifier = open_event(&node, &inst, ServiceKind::Command)?
            .notifier_builder()
            .create()
            .map_err(|e| anyhow::anyhow!("{e:?}"))?;
        let mut c = MotionCommand {
            seq: 1,
            stamp_ns: monotonic_ns(),
            ..Default::default()
        };
        match cmd.as_str() {
            "move" => {
                c.kind = CommandKind::Move as u32;
                c.profile = ProfileKind::Soft as u32;
                c.space = TargetSpace::Joint as u32;
                let q: Vec<f64> = args[4].split(',').map(|v| v.parse().unwrap()).collect();
                c.dof = q.len() as u32;
                c.target[..q.len()].copy_from_slice(&q);
            }
            "stop" => c.kind = CommandKind::Stop as u32,
            "estop" => c.kind = CommandKind::EStop as u32,
            "reset" => c.kind = CommandKind::Reset as u32,
            other => anyhow::bail!("unknown command {other}"),
        }
        std::thread::sleep(std::time::Duration::from_millis(200));
        let n = publisher
            .send_copy(c)
            .map_err(|e| anyhow::anyhow!("{e:?}"))?;
        let m = notifier.notify().map_err(|e| anyhow::anyhow!("{e:?}"))?;
        println!("command sent to {n} subscribers, {m} listeners notified");
        if std::env::var("PROBE_REPEAT").is_ok() {
            std::thread::sleep(std::time::Duration::from_millis(100));
            c.seq += 1;
            let n = publisher
                .send_copy(c)
                .map_err(|e| anyhow::anyhow!("{e:?}"))?;
            let m = notifier.notify().map_err(|e| anyhow::anyhow!("{e:?}"))?;
            println!("command sent again to {n} subscribers, {m} listeners notified");
        }
    }
    let end = monotonic_ns() + (secs * 1e9) as u64;
    while monotonic_ns() < end {
        while let Some(s) = status.receive().map_err(|e| anyhow::anyhow!("{e:?}"))? {
            let role = ServiceRole::from_wire(s.role)
                .map(|r| r.name())
                .unwrap_or("?");
            println!(
                "{role:9} ready={} life={} cycles={} miss={} skip={} lost={} refused={} stale={} clamp={} faults={} cmd={}/{} t={:.3} done={} cpu={}ms rss={}KiB lat p50/p99/max={}/{}/{}us track={:.2e} peak={:.2}",
                s.ready,
                s.lifecycle,
                s.cycles,
                s.deadline_misses,
                s.skipped_ticks,
                s.lost_messages,
                s.refused_messages,
                s.stale_cycles,
                s.clamped_cycles,
                s.faults,
                s.commands_accepted,
                s.commands_refused,
                s.motion_time_s,
                s.program_done,
                s.cpu_time_ms,
                s.rss_kib,
                s.latency.p50_ns / 1000,
                s.latency.p99_ns / 1000,
                s.latency.max_ns / 1000,
                s.tracking_error_max.iter().cloned().fold(0.0, f64::max),
                s.peak_torque.iter().cloned().fold(0.0, f64::max),
            );
        }
        std::thread::sleep(std::time::Duration::from_millis(100));
    }
    Ok(())
}
