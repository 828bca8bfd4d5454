//! `microrobot record`: attaches to a pipeline instance and writes every stream to MCAP.
//!
//! The drain thread (this one) runs the bus tap ([`super::tap::BusTap`], shared with
//! `microrobot view`): it sleeps in an iceoryx2 WaitSet on the event services, the
//! shutdown eventfd and a 100 ms timerfd; on every wake-up it drains every listener
//! and then every subscriber, and hands the copied payloads (with their receive time)
//! to a writer thread over an unbounded channel, so JSON encoding and file I/O never
//! hold up draining. The writer thread runs at a lower priority (nice +10).
//!
//! Ready protocol: once all ports are open (the services are created with the
//! contract's QoS if the pipeline is not up yet) the recorder creates `--ready-file`
//! (if given) and prints the line `recording <FILE>` on stdout. Start it before the
//! pipeline to miss nothing. It stops on SIGINT/SIGTERM, after `--duration`, or with
//! `--until-finalized` once planner, dynamics and actuator each published their final
//! status; it then finishes the file (summary, indexes) and prints one JSON line on
//! stdout: messages, sequence gaps and messages sent before the first recorded one per
//! topic, largest receive lag.

use std::collections::{BTreeMap, HashMap};
use std::fs::File;
use std::io::{BufWriter, Write as _};
use std::path::PathBuf;
use std::sync::mpsc;

use anyhow::{Context as _, Result, anyhow, bail, ensure};
use microrobot_messages::{LifecycleState, monotonic_ns};
use microrobot_runtime::Shutdown;
use serde::Serialize;
use serde_json::Value;

use super::tap::{
    BusTap, Payload, Received, Wake, check_instance, clock_offset_ns, run_config, wall_ns,
};
use super::{CONFIG_ATTACHMENT, TOPICS};

/// Options of `microrobot record`.
#[derive(Debug, Clone, clap::Args)]
pub struct RecordArgs {
    /// Instance name of the pipeline to record.
    #[arg(long, default_value = "default", value_name = "NAME")]
    pub instance: String,
    /// MCAP file to write (replaced if it exists).
    #[arg(long, value_name = "FILE.mcap")]
    pub out: PathBuf,
    /// Stop after this many seconds.
    #[arg(long, value_name = "DURATION", value_parser = microrobot_command_line::duration::parse)]
    pub duration: Option<f64>,
    /// Create this file once every subscriber is open (the ready signal for a supervisor).
    #[arg(long, value_name = "FILE")]
    pub ready_file: Option<PathBuf>,
    /// Stop once planner, dynamics and actuator have each published their final status.
    #[arg(long)]
    pub until_finalized: bool,
    /// SCHED_FIFO priority of the draining thread (0: normal scheduling).
    #[arg(long, default_value_t = 10, value_name = "PRIO")]
    pub rt_priority: i32,
    /// Derive the viewer channels (`transforms`, `joints`, `scene`) from every state and
    /// setpoint instead of at 100 Hz.
    #[arg(long)]
    pub full_rate: bool,
}

/// Period of the derived viewer channels by default (100 Hz).
const VIEWER_PERIOD_NS: u64 = 10_000_000;

/// What the recorder reports at the end (one JSON line on stdout).
#[derive(Debug, Clone, Default, Serialize)]
pub struct RecordSummary {
    pub file: String,
    pub instance: String,
    pub duration_s: f64,
    /// Messages written per topic.
    pub messages: BTreeMap<String, u64>,
    /// Messages missing between received ones per topic (sequence gaps, per publisher).
    pub gaps: BTreeMap<String, u64>,
    /// Messages each publisher sent before the first one recorded from it, per topic
    /// (its first `seq` − 1: the contract numbers every cyclic stream from 1). Lost if the
    /// recorder was subscribed before that publisher started (its queue overflowed while
    /// it was held off); not yet subscribed if it attached to a running pipeline. Motion
    /// commands are stamped, not numbered from 1, and count 0 here.
    pub before_first: BTreeMap<String, u64>,
    /// Largest receive time − message stamp, µs.
    pub max_lag_us: f64,
    /// Whether the resolved pipeline config was attached.
    pub config_attached: bool,
    /// `CLOCK_REALTIME` − `CLOCK_MONOTONIC` when the recorder started, ns: a message's
    /// `log_time` is its stamp plus this (also in the file's `clocks` metadata).
    pub realtime_minus_monotonic_ns: i64,
    /// Size of the finished file, bytes.
    pub bytes: u64,
    /// `bytes` over the recording's duration (zstd-compressed chunks).
    pub bytes_per_s: f64,
}

/// Lowers the calling thread's priority (best effort).
fn nice_this_thread(inc: i32) {
    // SAFETY: plain syscalls on the calling thread.
    unsafe {
        let tid = libc::syscall(libc::SYS_gettid) as libc::id_t;
        libc::setpriority(libc::PRIO_PROCESS, tid, inc);
    }
}

/// How often the writer reads the services' new log lines.
const LOG_POLL_MS: u64 = 200;

/// Longest span of message time in one chunk: a chunk is closed (and the file flushed)
/// once its messages span this much, so a killed recorder loses at most this much.
const CHUNK_SPAN_NS: u64 = 1_000_000_000;

struct Writer {
    mcap: mcap::Writer<BufWriter<File>>,
    channels: [u16; 5],
    sequence: [u32; 5],
    last_seq: [HashMap<u128, u64>; 5],
    summary: RecordSummary,
    /// Stamp of the first message of the open chunk.
    chunk_start_ns: Option<u64>,
    /// The viewer channels: ids (`transforms`, `joints`, `scene`), MCAP sequence numbers,
    /// and what derives them.
    derived: Derived,
    /// The services' log lines (`log`, `foxglove.Log`): channel id, sequence, the files.
    logs: (u16, u32, super::logs::LogTail),
}

struct Derived {
    channels: [u16; 3],
    sequence: [u32; 3],
    feed: super::viewer::Feed,
}

/// Writes one message on `(channel, sequence)` with log time `wall` (`CLOCK_REALTIME`)
/// and publish time `stamp` (`CLOCK_MONOTONIC`) to the recording `file`.
fn put(
    mcap: &mut mcap::Writer<BufWriter<File>>,
    file: &str,
    (channel_id, sequence): (u16, u32),
    (wall, stamp): (u64, u64),
    data: &[u8],
) -> Result<()> {
    mcap.write_to_known_channel(
        &mcap::records::MessageHeader {
            channel_id,
            sequence,
            log_time: wall,
            publish_time: stamp,
        },
        data,
    )
    .with_context(|| format!("cannot write to {file}"))
}

/// Adds a JSON channel `topic` with its JSON schema `(name, schema)` to the recording
/// at `path`; returns the channel id.
fn add_channel(
    mcap: &mut mcap::Writer<BufWriter<File>>,
    path: &std::path::Path,
    (topic, name, schema): (&str, &str, &Value),
    meta: &BTreeMap<String, String>,
) -> Result<u16> {
    let schema_id = mcap
        .add_schema(name, "jsonschema", schema.to_string().as_bytes())
        .with_context(|| format!("cannot write {}", path.display()))?;
    mcap.add_channel(schema_id, topic, "json", meta)
        .with_context(|| format!("cannot write {}", path.display()))
}

/// Attaches the run's resolved config (`data`, TOML) to the recording `file`, stamped
/// with the wall-clock time now.
fn attach_config(
    mcap: &mut mcap::Writer<BufWriter<File>>,
    file: &str,
    offset: i64,
    data: Vec<u8>,
) -> Result<()> {
    let now = wall_ns(monotonic_ns(), offset);
    mcap.attach(&mcap::Attachment {
        log_time: now,
        create_time: now,
        name: CONFIG_ATTACHMENT.to_string(),
        media_type: "application/toml".to_string(),
        data: data.into(),
    })
    .with_context(|| format!("cannot write to {file}"))
}

impl Writer {
    fn create(args: &RecordArgs) -> Result<Self> {
        let path = &args.out;
        let file =
            File::create(path).with_context(|| format!("cannot create {}", path.display()))?;
        let mut mcap = mcap::WriteOptions::new()
            .compression(Some(mcap::Compression::Zstd))
            .profile("")
            .library(concat!("microrobot ", env!("CARGO_PKG_VERSION")))
            .create(BufWriter::with_capacity(1 << 20, file))
            .with_context(|| format!("cannot start MCAP file {}", path.display()))?;
        // Metadata and attachments are written between chunks, so each one closes the
        // chunk open before it: written ahead of the schemas and channels, they leave no
        // chunk without messages (whose zero time range and missing message index
        // Foxglove Studio refuses).
        let offset = clock_offset_ns();
        let clocks = BTreeMap::from([
            (
                "realtime_minus_monotonic_ns".to_string(),
                offset.to_string(),
            ),
            (
                "log_time".to_string(),
                "CLOCK_REALTIME ns: the message's CLOCK_MONOTONIC stamp + realtime_minus_monotonic_ns".to_string(),
            ),
            (
                "publish_time".to_string(),
                "CLOCK_MONOTONIC ns: the message's own stamp (header.stamp_ns or stamp_ns)".to_string(),
            ),
        ]);
        mcap.write_metadata(&mcap::records::Metadata {
            name: "clocks".to_string(),
            metadata: clocks,
        })
        .with_context(|| format!("cannot write {}", path.display()))?;
        let mut summary = RecordSummary {
            file: path.display().to_string(),
            instance: args.instance.clone(),
            realtime_minus_monotonic_ns: offset,
            ..Default::default()
        };
        // The run's config now if the pipeline is up (so a killed recorder keeps it),
        // else at the end.
        if let Some(data) = run_config(&args.instance) {
            attach_config(&mut mcap, &summary.file, offset, data)?;
            summary.config_attached = true;
        }
        let mut meta = BTreeMap::new();
        meta.insert("instance".to_string(), args.instance.clone());
        let mut channels = [0u16; 5];
        for (i, topic) in TOPICS.iter().enumerate() {
            let (name, schema) = super::schema(topic)?;
            channels[i] = add_channel(&mut mcap, path, (topic, name, &schema), &meta)?;
        }
        let mut derived_channels = [0u16; 3];
        for (i, (topic, name, schema)) in super::viewer::channels().into_iter().enumerate() {
            derived_channels[i] = add_channel(&mut mcap, path, (topic, name, &schema), &meta)?;
        }
        let log_channel = add_channel(
            &mut mcap,
            path,
            (
                super::logs::TOPIC,
                super::logs::SCHEMA_NAME,
                &super::logs::schema(),
            ),
            &meta,
        )?;
        for t in TOPICS {
            summary.messages.insert(t.to_string(), 0);
            summary.gaps.insert(t.to_string(), 0);
            summary.before_first.insert(t.to_string(), 0);
        }
        Ok(Self {
            mcap,
            channels,
            sequence: [0; 5],
            last_seq: Default::default(),
            summary,
            chunk_start_ns: None,
            derived: Derived {
                channels: derived_channels,
                sequence: [0; 3],
                feed: super::viewer::Feed::new(
                    &args.instance,
                    super::viewer::Periods::every(if args.full_rate {
                        0
                    } else {
                        VIEWER_PERIOD_NS
                    }),
                ),
            },
            logs: (log_channel, 0, super::logs::LogTail::new(&args.instance)),
        })
    }

    fn write(&mut self, r: &Received) -> Result<()> {
        let t = r.payload.topic();
        let (seq, stamp) = r.payload.seq_and_stamp();
        match self.last_seq[t].insert(r.publisher, seq) {
            Some(last) if seq > last + 1 => {
                *self.summary.gaps.entry(TOPICS[t].into()).or_default() += seq - last - 1;
            }
            None if r.payload.numbered_from_one() => {
                *self
                    .summary
                    .before_first
                    .entry(TOPICS[t].into())
                    .or_default() += seq.saturating_sub(1);
            }
            _ => {}
        }
        let lag_us = r.recv_ns.saturating_sub(stamp) as f64 / 1000.0;
        self.summary.max_lag_us = self.summary.max_lag_us.max(lag_us);
        let data = serde_json::to_vec(&r.payload.json()).context("JSON encoding")?;
        self.sequence[t] = self.sequence[t].wrapping_add(1);
        let wall = wall_ns(stamp, self.summary.realtime_minus_monotonic_ns);
        put(
            &mut self.mcap,
            &self.summary.file,
            (self.channels[t], self.sequence[t]),
            (wall, stamp),
            &data,
        )?;
        self.derive(&r.payload, stamp, wall)?;
        match self.chunk_start_ns {
            None => self.chunk_start_ns = Some(stamp),
            Some(t0) if stamp.saturating_sub(t0) >= CHUNK_SPAN_NS => {
                self.mcap
                    .flush()
                    .with_context(|| format!("cannot write to {}", self.summary.file))?;
                self.chunk_start_ns = None;
            }
            Some(_) => {}
        }
        *self.summary.messages.entry(TOPICS[t].into()).or_default() += 1;
        Ok(())
    }

    /// Writes the viewer channels a state or setpoint is due for (see
    /// [`super::viewer`]); nothing until the run's config (the robot) is found.
    fn derive(&mut self, payload: &Payload, stamp: u64, wall: u64) -> Result<()> {
        let d = &mut self.derived;
        for (i, v) in d.feed.derive(payload, stamp, wall) {
            let data = serde_json::to_vec(&v).context("JSON encoding")?;
            d.sequence[i] = d.sequence[i].wrapping_add(1);
            put(
                &mut self.mcap,
                &self.summary.file,
                (d.channels[i], d.sequence[i]),
                (wall, stamp),
                &data,
            )?;
            let topic = super::viewer::DERIVED_TOPICS[i];
            *self.summary.messages.entry(topic.into()).or_default() += 1;
        }
        Ok(())
    }

    /// Writes the services' log lines appended since the last call (`flush`: also a
    /// last line without its newline).
    fn write_logs(&mut self, flush: bool) -> Result<()> {
        let offset = self.summary.realtime_minus_monotonic_ns;
        let now = wall_ns(monotonic_ns(), offset);
        let (channel, sequence, tail) = &mut self.logs;
        let mut lines = Vec::new();
        tail.poll(now, flush, |wall, msg| lines.push((wall, msg)));
        for (wall, msg) in lines {
            let data = serde_json::to_vec(&msg).context("JSON encoding")?;
            *sequence = sequence.wrapping_add(1);
            let mono = (wall as i128 - offset as i128).clamp(0, u64::MAX as i128) as u64;
            put(
                &mut self.mcap,
                &self.summary.file,
                (*channel, *sequence),
                (wall, mono),
                &data,
            )?;
            *self
                .summary
                .messages
                .entry(super::logs::TOPIC.into())
                .or_default() += 1;
        }
        Ok(())
    }

    fn finish(mut self, instance: &str) -> Result<RecordSummary> {
        self.write_logs(true)?;
        let data = if self.summary.config_attached {
            None
        } else {
            run_config(instance)
        };
        if let Some(data) = data {
            let offset = self.summary.realtime_minus_monotonic_ns;
            attach_config(&mut self.mcap, &self.summary.file, offset, data)?;
            self.summary.config_attached = true;
        }
        self.mcap
            .finish()
            .with_context(|| format!("cannot finish {}", self.summary.file))?;
        let mut inner = self.mcap.into_inner();
        inner
            .flush()
            .with_context(|| format!("cannot write {}", self.summary.file))?;
        self.summary.bytes = inner.get_ref().metadata().map_or(0, |m| m.len());
        Ok(self.summary)
    }
}

/// Records until stopped; see the module documentation for the protocol.
pub fn main(args: RecordArgs) -> Result<()> {
    check_instance(&args.instance)?;
    if let Some(d) = args.duration {
        ensure!(
            d.is_finite() && d > 0.0,
            "--duration {d}: must be a positive number of seconds"
        );
    }
    iceoryx2::prelude::set_log_level_from_env_or(iceoryx2::prelude::LogLevel::Error);
    let shutdown =
        std::sync::Arc::new(Shutdown::new().context("cannot create the shutdown eventfd")?);
    shutdown
        .install_signal_handler()
        .context("cannot install the SIGINT/SIGTERM handler")?;

    let writer = Writer::create(&args)?;
    let tap = BusTap::open(&args.instance, "microrobot-record")?;

    let (tx, rx) = mpsc::channel::<Received>();
    let instance = args.instance.clone();
    let stop = shutdown.clone();
    let writer_thread = std::thread::Builder::new()
        .name("mcap-writer".into())
        .spawn(move || -> Result<RecordSummary> {
            nice_this_thread(10);
            let mut w = writer;
            let mut first_error = None;
            let mut logs_read_ns = 0;
            loop {
                let r = match rx.recv_timeout(std::time::Duration::from_millis(LOG_POLL_MS)) {
                    Ok(r) => Some(r),
                    Err(mpsc::RecvTimeoutError::Timeout) => None,
                    Err(mpsc::RecvTimeoutError::Disconnected) => break,
                };
                if first_error.is_some() {
                    // Drained, not written: the file ends at its last flushed chunk.
                    continue;
                }
                let now = monotonic_ns();
                let written = match r {
                    Some(r) => w.write(&r),
                    None => Ok(()),
                }
                .and_then(|()| {
                    if now.saturating_sub(logs_read_ns) < LOG_POLL_MS * 1_000_000 {
                        return Ok(());
                    }
                    logs_read_ns = now;
                    w.write_logs(false)
                });
                if let Err(e) = written {
                    // Said at once (a full disk), and the recorder stops: what it
                    // wrote up to its last flushed chunk stays readable.
                    eprintln!("error: {e:#}; the recorder stops");
                    stop.request();
                    first_error = Some(e);
                }
            }
            if first_error.is_some() {
                // Said when it happened; the file holds every chunk flushed before it.
                bail!("the recording stopped at that write error");
            }
            w.finish(&instance)
        })
        .context("cannot start the writer thread")?;

    // The drain thread (this one, not the writer spawned above) asks for SCHED_FIFO so a
    // free-wheeling lockstep chain cannot starve it past the 64-sample queues; best effort.
    let fifo = if args.rt_priority > 0 {
        let p = libc::sched_param {
            sched_priority: args.rt_priority,
        };
        // SAFETY: plain syscall on the calling thread.
        unsafe { libc::sched_setscheduler(0, libc::SCHED_FIFO, &p) == 0 }
    } else {
        false
    };
    if args.rt_priority > 0 && !fifo {
        eprintln!(
            "warning: SCHED_FIFO {} refused; draining at normal priority",
            args.rt_priority
        );
    }
    if let Some(path) = &args.ready_file {
        // A new file (a stale one removed first), owner-only, never through a symlink.
        let _ = std::fs::remove_file(path);
        microrobot_supervisor::instance::create_private_new(path)
            .with_context(|| format!("cannot create {}", path.display()))?;
    }
    println!("recording {}", args.out.display());
    let _ = std::io::stdout().flush();

    let start = monotonic_ns();
    let end = args
        .duration
        .map(|d| start.saturating_add((d * 1e9) as u64));
    let finalized = std::cell::Cell::new([false; 3]);
    let mut settle_until: Option<u64> = None;
    let on_payload = |p: &Payload| {
        if let Payload::Status(s) = p
            && s.lifecycle == LifecycleState::Finalized as u32
            && (1..=3).contains(&s.role)
        {
            let mut f = finalized.get();
            f[(s.role - 1) as usize] = true;
            finalized.set(f);
        }
    };
    let mut on = |r: Received| {
        on_payload(&r.payload);
        // The writer only goes away after this thread is done; a send error cannot happen.
        let _ = tx.send(r);
    };
    let result = tap.run(&shutdown, Wake::OnEvents, 100_000_000, &mut on, |now| {
        if end.is_some_and(|e| now >= e) {
            return false;
        }
        if args.until_finalized && finalized.get().iter().all(|f| *f) {
            // Give stragglers of the other streams one timer period to arrive.
            match settle_until {
                None => settle_until = Some(now + 100_000_000),
                Some(t) if now >= t => return false,
                Some(_) => {}
            }
        }
        true
    });
    // Whatever is still queued goes in too.
    tap.drain(&mut on);
    drop(tx);
    let written = writer_thread
        .join()
        .map_err(|_| anyhow!("the MCAP writer thread panicked"))?;
    result?;
    let mut summary = written?;
    summary.duration_s = monotonic_ns().saturating_sub(start) as f64 / 1e9;
    if summary.duration_s > 0.0 {
        summary.bytes_per_s = summary.bytes as f64 / summary.duration_s;
    }
    let gaps: u64 = summary.gaps.values().sum();
    let before: u64 = summary.before_first.values().sum();
    eprintln!(
        "recorded {} messages to {} in {:.1} s, {:.1} kB/s ({} lost to sequence gaps, {} sent before the first recorded)",
        summary.messages.values().sum::<u64>(),
        summary.file,
        summary.duration_s,
        summary.bytes_per_s / 1e3,
        gaps,
        before
    );
    println!(
        "{}",
        serde_json::to_string(&summary).context("cannot serialise the summary")?
    );
    if summary.messages.values().all(|n| *n == 0) {
        eprintln!(
            "warning: nothing recorded from instance `{}`: was it running?",
            args.instance
        );
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use microrobot_messages::{JointSetpoint, MotionCommand};

    fn setpoint(seq: u64) -> Payload {
        let mut m = JointSetpoint::default();
        m.header.seq = seq;
        Payload::Setpoint(m)
    }

    fn writer(dir: &std::path::Path) -> Writer {
        Writer::create(&RecordArgs {
            instance: "unit".into(),
            out: dir.join("unit.mcap"),
            duration: None,
            ready_file: None,
            until_finalized: false,
            rt_priority: 0,
            full_rate: false,
        })
        .expect("writer")
    }

    fn write(w: &mut Writer, payload: Payload, publisher: u128) {
        w.write(&Received {
            payload,
            publisher,
            recv_ns: 0,
        })
        .expect("write");
    }

    /// What a publisher sent before the first recorded message and what went missing
    /// between recorded ones are both counted, per publisher, and add up to its last seq.
    #[test]
    fn losses_at_the_head_and_in_the_middle_are_both_reported() {
        let dir = tempfile::tempdir().expect("tempdir");
        let mut w = writer(dir.path());
        // Publisher 7: the first 4 overwritten before the recorder drained, then 10..=12 lost.
        for seq in [5, 6, 7, 8, 9, 13, 14] {
            write(&mut w, setpoint(seq), 7);
        }
        // Publisher 8 (a restarted planner) numbers from 1 again: nothing missing.
        for seq in 1..=3 {
            write(&mut w, setpoint(seq), 8);
        }
        // Motion commands carry the sender's stamp as seq: never counted as missing.
        let c = MotionCommand {
            seq: 1_000_000,
            ..Default::default()
        };
        write(&mut w, Payload::Command(c), 9);
        let s = w.finish("unit-no-such-instance").expect("finish");
        assert_eq!(s.messages["setpoint"], 10);
        assert_eq!(s.before_first["setpoint"], 4);
        assert_eq!(s.gaps["setpoint"], 3);
        assert_eq!(
            s.messages["setpoint"] + s.before_first["setpoint"] + s.gaps["setpoint"],
            14 + 3
        );
        assert_eq!(s.before_first["command"], 0);
        assert_eq!(s.gaps["command"], 0);
    }
}
