//! What looking at an empty inbox costs: one `Inbox::next` on a `command` stream with no
//! message, back to back (warm) and after a sleep of one 4 kHz period (as a service polls
//! it, with its caches cooled by the other processes). It is why the services take their
//! on-demand inboxes on their event and at the runner's sweep (`SWEEP_NS`), not with an
//! empty receive at every wake-up.
//!
//! `cargo run --release -p microrobot-runtime --example empty_poll -- [POLLS]`

use microrobot_messages::{MotionCommand, monotonic_ns, topic};
use microrobot_runtime::{Inbox, Subscription};

fn main() -> anyhow::Result<()> {
    let polls: usize = match std::env::args().nth(1) {
        None => 20_000,
        Some(s) => s
            .parse()
            .map_err(|e| anyhow::anyhow!("POLLS must be a whole number, got `{s}`: {e}"))?,
    };
    anyhow::ensure!(polls > 0, "POLLS must be at least 1");
    let instance = format!("empty-poll-{}", std::process::id());
    let node = microrobot_runtime::node::named_node(&instance)?;
    let inbox: Inbox<MotionCommand> = Inbox::open(
        &node,
        &instance,
        topic::COMMAND,
        Subscription::CYCLIC.default_queue(),
    )?;
    println!("{polls} empty receives (each timed with two clock reads):");
    for (name, sleep_us) in [("back to back", 0u64), ("after a 250 µs sleep", 250)] {
        let mut ns = Vec::with_capacity(polls);
        for _ in 0..polls {
            if sleep_us > 0 {
                std::thread::sleep(std::time::Duration::from_micros(sleep_us));
            }
            let t0 = monotonic_ns();
            let got = inbox.next().is_some();
            ns.push(monotonic_ns() - t0);
            std::hint::black_box(got);
        }
        ns.sort_unstable();
        let mean = ns.iter().sum::<u64>() as f64 / ns.len() as f64;
        println!(
            "  {name:<22} p50 {} ns, p90 {} ns, mean {mean:.0} ns",
            ns[ns.len() / 2],
            ns[ns.len() * 9 / 10]
        );
    }
    Ok(())
}
