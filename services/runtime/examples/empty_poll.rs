//! What looking at an empty inbox costs: one `Inbox::next` on a `command` stream with no
//! message, back to back (warm) and after a sleep of one 4 kHz period (as a service polls
//! it, with its caches cooled by the other processes). It is why the services take their
//! on-demand inboxes on their event and at the runner's sweep (`SWEEP_NS`), not with an
//! empty receive at every wake-up.
//!
//! `cargo run --release -p microrobot-runtime --example empty_poll -- [POLLS]`

use std::time::Duration;

use microrobot_messages::{MotionCommand, topic};
use microrobot_runtime::{Inbox, Subscription};

mod common;

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
    common::time_warm_and_after_sleep(
        &format!("{polls} empty receives, after a 250 µs sleep"),
        Duration::from_micros(250),
        polls,
        || {
            std::hint::black_box(inbox.next().is_some());
        },
    );
    Ok(())
}
