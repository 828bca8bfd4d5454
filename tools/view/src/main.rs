//! `microrobot-view` (run as `microrobot view`): a live Foxglove view of a running
//! pipeline. It taps the instance's bus as `microrobot record` does (the same
//! [`BusTap`], subscribers with the contract's QoS: a full queue overwrites its oldest
//! sample, so a publisher never waits for the view) and serves the recording's channels
//! over the Foxglove WebSocket protocol with Foxglove's SDK: the five streams
//! (`setpoint`, `torque`, `state`, `command`, `status`), the derived viewer channels
//! (`transforms`, `joints`, `scene`, computed by the recorder's [`Feed`]) and the
//! services' `log`, with the recording's schemas (JSON, `jsonschema`). The cyclic streams
//! are decimated to a viewer's rate; the tap drains the bus every 10 ms rather than on
//! every message (a fraction of the recorder's wake-ups); a slow client loses its
//! oldest queued messages inside the SDK, never holding up the tap. A package of its
//! own so the WebSocket stack (tokio) is no part of the CLI's build.

use std::io::Write as _;
use std::net::SocketAddr;
use std::process::ExitCode;
use std::sync::Arc;

use anyhow::{Context as _, Result, anyhow};
use clap::Parser;
use foxglove::{ChannelBuilder, PartialMetadata, RawChannel, Schema, WebSocketServer};
use microrobot_bus_tools::recording::tap::{self, BusTap, Payload, Received, Wake};
use microrobot_bus_tools::recording::viewer::{self, Feed, Periods};
use microrobot_bus_tools::recording::{self as recording, logs};
use microrobot_messages::monotonic_ns;
use microrobot_runtime::Shutdown;

/// Options of `microrobot view`.
#[derive(Debug, Parser)]
#[command(
    name = "microrobot view",
    about = "Serve a live Foxglove WebSocket view of a running pipeline (open it in \
             Foxglove: Open connection, Foxglove WebSocket, ws://127.0.0.1:8765)"
)]
struct Args {
    /// Instance name of the running pipeline to view.
    #[arg(long, default_value = "default", value_name = "NAME")]
    instance: String,
    /// Address and port to serve on (port 0: any free port, printed when ready). Loopback
    /// unless another address is asked for: the view has no authentication.
    #[arg(long, default_value = "127.0.0.1:8765", value_name = "ADDR:PORT")]
    bind: SocketAddr,
    /// Rate of the `transforms` and `scene` channels, Hz.
    #[arg(long, default_value_t = 60.0, value_name = "HZ", value_parser = rate)]
    transforms_hz: f64,
    /// Rate of the `joints` channel and of the cyclic streams (`setpoint`, `torque`,
    /// `state`), Hz; `command` and `status` are sent whole.
    #[arg(long, default_value_t = 100.0, value_name = "HZ", value_parser = rate)]
    joints_hz: f64,
    /// Print the build id and exit (how `microrobot` checks that this binary is of its
    /// own build).
    #[arg(long, hide = true)]
    build_id: bool,
}

/// Highest rate a viewer channel can be asked for: the pipeline's fastest loop.
const MAX_HZ: f64 = 4000.0;

/// A rate in Hz: a positive number up to [`MAX_HZ`].
fn rate(s: &str) -> Result<f64, String> {
    let hz: f64 = s
        .trim()
        .parse()
        .map_err(|_| format!("`{s}` is not a number of Hz"))?;
    if !(hz.is_finite() && hz > 0.0 && hz <= MAX_HZ) {
        return Err(format!("{s} Hz: must be above 0 and at most {MAX_HZ}"));
    }
    Ok(hz)
}

/// Period in ns of a rate in Hz (checked by [`rate`]).
fn period_ns(hz: f64) -> u64 {
    (1e9 / hz).round() as u64
}

/// How often the view drains the bus: on a timer, not on every message, so a 1 kHz
/// pipeline costs it 100 wake-ups a second instead of thousands; 10 ms is far below a
/// subscriber queue's depth in time (256 samples: 64 ms at 4 kHz), so nothing is lost,
/// and the decimation by the messages' own stamps is unchanged.
const DRAIN_PERIOD_NS: u64 = 10_000_000;

/// How often the services' new log lines are read.
const LOG_POLL_NS: u64 = 200_000_000;

/// Without a status message for this long (every service sends one at 10 Hz) the
/// pipeline has stopped or stalls: the view says so, keeps serving and says so again
/// when the instance publishes anew (a new run under the same name).
const QUIET_AFTER_NS: u64 = 1_000_000_000;

/// A JSON channel on `ctx` with the recording's schema.
fn channel(
    ctx: &Arc<foxglove::Context>,
    topic: &str,
    name: &str,
    schema: &serde_json::Value,
) -> Result<Arc<RawChannel>> {
    ChannelBuilder::new(topic)
        .message_encoding("json")
        .schema(Schema::new(
            name,
            "jsonschema",
            schema.to_string().into_bytes(),
        ))
        .context(ctx)
        .build_raw()
        .map_err(|e| anyhow!("cannot create the `{topic}` channel: {e}"))
}

/// Sends `msg` on `ch` stamped with the wall-clock time `wall` (ns), if a client listens.
fn send(ch: &RawChannel, msg: &serde_json::Value, wall: u64) {
    if !ch.has_sinks() {
        return;
    }
    if let Ok(data) = serde_json::to_vec(msg) {
        ch.log_with_meta(
            &data,
            PartialMetadata {
                log_time: Some(wall),
            },
        );
    }
}

/// Says `text` on stderr and to the viewer (the `log` channel, as the view's own line).
fn announce(log: &RawChannel, text: &str, level: u8, wall: u64) {
    eprintln!("microrobot view: {text}");
    send(log, &logs::message_at(wall, level, "view", "", text), wall);
}

/// Lowers the whole process's priority (best effort), before any thread starts: the
/// view shares the machine with the real-time services.
fn nice_process(inc: i32) {
    // SAFETY: plain syscall on this process.
    unsafe {
        libc::setpriority(libc::PRIO_PROCESS, 0, inc);
    }
}

fn serve(args: Args) -> Result<()> {
    // iceoryx2's own notices (e.g. "no config file was loaded") only on request.
    iceoryx2::prelude::set_log_level_from_env_or(iceoryx2::prelude::LogLevel::Error);
    tap::check_instance(&args.instance)?;
    microrobot_bus_tools::inspect::require_running(&args.instance)?;
    nice_process(10);
    let shutdown = Shutdown::new().context("cannot create the shutdown eventfd")?;
    shutdown
        .install_signal_handler()
        .context("cannot install the SIGINT/SIGTERM handler")?;

    let ctx = foxglove::Context::new();
    let mut streams = Vec::new();
    for topic in recording::TOPICS {
        let (name, schema) = recording::schema(topic)?;
        streams.push(channel(&ctx, topic, name, &schema)?);
    }
    let mut derived = Vec::new();
    for (topic, name, schema) in viewer::channels() {
        derived.push(channel(&ctx, topic, name, &schema)?);
    }
    let log = channel(&ctx, logs::TOPIC, logs::SCHEMA_NAME, &logs::schema())?;

    let tap = BusTap::open(&args.instance, "microrobot-view")?;
    let server = WebSocketServer::new()
        .name(format!("microrobot {}", args.instance))
        .bind(args.bind.ip().to_string(), args.bind.port())
        .context(&ctx)
        .start_blocking()
        .map_err(|e| anyhow!("cannot serve on {}: {e}", args.bind))?;
    if !args.bind.ip().is_loopback() {
        eprintln!(
            "microrobot view: warning: serving on {} (not loopback): whoever reaches it sees \
             the arm's streams, with no authentication",
            args.bind.ip()
        );
    }
    let url = format!("ws://{}", SocketAddr::new(args.bind.ip(), server.port()));
    println!("serving {url} (instance `{}`)", args.instance);
    let _ = std::io::stdout().flush();
    eprintln!(
        "microrobot view: in Foxglove, Open connection > Foxglove WebSocket > {url}; Ctrl-C stops"
    );

    let offset = tap::clock_offset_ns();
    let raw_period = period_ns(args.joints_hz);
    let mut feed = Feed::new(
        &args.instance,
        Periods {
            transforms_ns: period_ns(args.transforms_hz),
            joints_ns: period_ns(args.joints_hz),
            scene_ns: period_ns(args.transforms_hz),
        },
    );
    let mut last_raw: [Option<u64>; 3] = [None; 3];
    // Monotonic time of the last status message seen, and whether the view has said the
    // instance went quiet; shared by the two closures below.
    let last_status = std::cell::Cell::new(monotonic_ns());
    let quiet = std::cell::Cell::new(false);
    let on = |r: Received| {
        if matches!(r.payload, Payload::Status(_)) {
            last_status.set(monotonic_ns());
        }
        let t = r.payload.topic();
        let (_, stamp) = r.payload.seq_and_stamp();
        let wall = tap::wall_ns(stamp, offset);
        let due = match r.payload {
            Payload::Setpoint(_) | Payload::Torque(_) | Payload::State(_) => {
                let due = last_raw[t].is_none_or(|l| stamp.saturating_sub(l) >= raw_period);
                if due {
                    last_raw[t] = Some(stamp);
                }
                due
            }
            Payload::Command(_) | Payload::Status(_) => true,
        };
        if due {
            send(&streams[t], &r.payload.json(), wall);
        }
        for (i, msg) in feed.derive(&r.payload, stamp, wall) {
            send(&derived[i], &msg, wall);
        }
    };
    let mut tail = logs::LogTail::new(&args.instance);
    let mut logs_read_ns = 0;
    let result = tap.run(&shutdown, Wake::OnTimer, DRAIN_PERIOD_NS, on, |now| {
        let silent_ns = now.saturating_sub(last_status.get());
        if silent_ns >= QUIET_AFTER_NS && !quiet.get() {
            quiet.set(true);
            let text = format!(
                "instance `{}` has sent no status for {:.1} s: the pipeline stopped or \
                 stalls; still serving, waiting for it",
                args.instance,
                silent_ns as f64 * 1e-9
            );
            announce(&log, &text, logs::LEVEL_WARNING, tap::wall_ns(now, offset));
        } else if silent_ns < QUIET_AFTER_NS && quiet.get() {
            quiet.set(false);
            let text = format!("instance `{}` is publishing again", args.instance);
            announce(&log, &text, logs::LEVEL_INFO, tap::wall_ns(now, offset));
        }
        if now.saturating_sub(logs_read_ns) >= LOG_POLL_NS {
            logs_read_ns = now;
            tail.poll(tap::wall_ns(now, offset), false, |wall, msg| {
                send(&log, &msg, wall)
            });
        }
        true
    });
    server.stop().wait_blocking();
    eprintln!("microrobot view: stopped");
    result
}

fn main() -> ExitCode {
    let args = Args::parse();
    if args.build_id {
        println!("{}", microrobot_build_id::BUILD_ID);
        return ExitCode::SUCCESS;
    }
    match serve(args) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::from(microrobot_command_line::exit::code_of(&e))
        }
    }
}
