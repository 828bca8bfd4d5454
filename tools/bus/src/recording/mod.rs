//! Recordings of a pipeline's bus in MCAP: `microrobot record` writes them, `export`,
//! `plot` and `replay` read them.
//!
//! File layout: one channel per stream (`setpoint`, `torque`, `state`, `command`,
//! `status`), message encoding `json`, schema encoding `jsonschema` (what Foxglove
//! decodes and plots). Each message is one JSON object with the payload's field names;
//! arrays of the cyclic streams hold the `dof` active joints only, the status arrays all
//! [`MAX_JOINTS`]. Floats are printed shortest-round-trip (they parse back bit for bit).
//! `publish_time` is the message's own `CLOCK_MONOTONIC` stamp (`header.stamp_ns`,
//! `stamp_ns`), in ns; `log_time` is the same instant on the wall clock
//! (`CLOCK_REALTIME` ns: the stamp plus the offset between the clocks measured when the
//! recorder started, kept in the metadata record `clocks`), so viewers show the real
//! date. Chunks are zstd-compressed and closed at least once a second of message time,
//! so a recorder killed with `kill -9` or stopped by a full disk loses at most its last
//! second: the readers here read such a file up to its last complete chunk and say where
//! it was cut, and `microrobot recover` writes a finished, indexed copy. The resolved
//! pipeline config, when the recorder finds it, is attached as `pipeline.resolved.toml`
//! (at the start when the pipeline is already up, else at the end).

pub mod closed_loop;
pub mod export;
pub mod logs;
pub mod plot;
pub mod record;
pub mod recover;
pub mod replay;
pub mod tap;
pub mod viewer;

use std::collections::BTreeMap;
use std::path::Path;

use anyhow::{Context as _, Result, anyhow, bail};
use microrobot_messages::{
    Header, JointSetpoint, JointState, LatencySummary, MAX_JOINTS, MotionCommand, ServiceStatus,
    TorqueCommand,
};
use serde_json::{Map, Value, json};

/// Name of the attachment holding the pipeline config the recorded run used.
pub const CONFIG_ATTACHMENT: &str = "pipeline.resolved.toml";

/// The recorded streams, in pipeline order (also the MCAP topic names).
pub const TOPICS: [&str; 5] = ["setpoint", "torque", "state", "command", "status"];

fn active(v: &[f64; MAX_JOINTS], dof: u32) -> Value {
    let n = (dof as usize).min(MAX_JOINTS);
    Value::from(v[..n].to_vec())
}

fn header(h: &Header) -> Value {
    json!({
        "seq": h.seq,
        "tick": h.tick,
        "stamp_ns": h.stamp_ns,
        "source_stamp_ns": h.source_stamp_ns,
    })
}

/// JSON form of a setpoint.
pub fn setpoint_json(m: &JointSetpoint) -> Value {
    json!({
        "header": header(&m.header),
        "q": active(&m.q, m.dof),
        "qd": active(&m.qd, m.dof),
        "qdd": active(&m.qdd, m.dof),
        "jerk": active(&m.jerk, m.dof),
        "dof": m.dof,
        "flags": m.flags,
    })
}

/// JSON form of a torque command.
pub fn torque_json(m: &TorqueCommand) -> Value {
    json!({
        "header": header(&m.header),
        "tau": active(&m.tau, m.dof),
        "q_desired": active(&m.q_desired, m.dof),
        "setpoint_seq": m.setpoint_seq,
        "state_seq": m.state_seq,
        "dof": m.dof,
        "flags": m.flags,
    })
}

/// JSON form of a measured state.
pub fn state_json(m: &JointState) -> Value {
    json!({
        "header": header(&m.header),
        "q": active(&m.q, m.dof),
        "qd": active(&m.qd, m.dof),
        "tau_applied": active(&m.tau_applied, m.dof),
        "torque_seq": m.torque_seq,
        "dof": m.dof,
        "lifecycle": m.lifecycle,
        "flags": m.flags,
        "reserved": m.reserved,
    })
}

/// JSON form of a motion command (the whole `target`: it may be a pose).
pub fn command_json(m: &MotionCommand) -> Value {
    json!({
        "seq": m.seq,
        "stamp_ns": m.stamp_ns,
        "kind": m.kind,
        "profile": m.profile,
        "space": m.space,
        "dof": m.dof,
        "target": m.target.to_vec(),
        "duration_s": m.duration_s,
        "limit_scale": m.limit_scale,
    })
}

fn latency_json(l: &LatencySummary) -> Value {
    json!({
        "count": l.count,
        "p50_ns": l.p50_ns,
        "p99_ns": l.p99_ns,
        "p999_ns": l.p999_ns,
        "p9999_ns": l.p9999_ns,
        "max_ns": l.max_ns,
    })
}

/// JSON form of a service status.
pub fn status_json(m: &ServiceStatus) -> Value {
    json!({
        "seq": m.seq,
        "stamp_ns": m.stamp_ns,
        "role": m.role,
        "lifecycle": m.lifecycle,
        "pid": m.pid,
        "ready": m.ready,
        "cycles": m.cycles,
        "deadline_misses": m.deadline_misses,
        "skipped_ticks": m.skipped_ticks,
        "lost_messages": m.lost_messages,
        "refused_messages": m.refused_messages,
        "stale_cycles": m.stale_cycles,
        "clamped_cycles": m.clamped_cycles,
        "faults": m.faults,
        "commands_accepted": m.commands_accepted,
        "commands_refused": m.commands_refused,
        "motion_time_s": m.motion_time_s,
        "program_done": m.program_done,
        "cpu_time_ms": m.cpu_time_ms,
        "rss_kib": m.rss_kib,
        "latency": latency_json(&m.latency),
        "tracking_error_max": m.tracking_error_max.to_vec(),
        "peak_torque": m.peak_torque.to_vec(),
        "estops": m.estops,
        "estop_latency_ns": m.estop_latency_ns,
        "estop_latency_max_ns": m.estop_latency_max_ns,
        "last_command_refusal": m.last_command_refusal,
        "last_input_refusal": m.last_input_refusal,
    })
}

/// JSON Schema of a value shaped like the encoders' output (integers, numbers, arrays of
/// numbers, nested objects), every property required.
fn schema_of(v: &Value) -> Value {
    match v {
        Value::Object(m) => {
            let props: Map<String, Value> =
                m.iter().map(|(k, v)| (k.clone(), schema_of(v))).collect();
            let required: Vec<&String> = m.keys().collect();
            json!({ "type": "object", "properties": props, "required": required })
        }
        Value::Array(_) => json!({ "type": "array", "items": { "type": "number" } }),
        Value::Number(n) if n.is_u64() || n.is_i64() => json!({ "type": "integer" }),
        Value::Number(_) => json!({ "type": "number" }),
        Value::Bool(_) => json!({ "type": "boolean" }),
        _ => json!({}),
    }
}

/// Schema name (the payload's contract type name) and JSON Schema of `topic`.
pub fn schema(topic: &str) -> Result<(&'static str, Value)> {
    let (name, sample) = match topic {
        "setpoint" => (
            "microrobot::v2::JointSetpoint",
            setpoint_json(&JointSetpoint::default()),
        ),
        "torque" => (
            "microrobot::v2::TorqueCommand",
            torque_json(&TorqueCommand::default()),
        ),
        "state" => (
            "microrobot::v2::JointState",
            state_json(&JointState::default()),
        ),
        "command" => (
            "microrobot::v2::MotionCommand",
            command_json(&MotionCommand::default()),
        ),
        "status" => (
            "microrobot::v2::ServiceStatus",
            status_json(&ServiceStatus::default()),
        ),
        other => bail!("unknown topic `{other}`"),
    };
    let mut s = schema_of(&sample);
    if let Value::Object(m) = &mut s {
        m.insert("title".into(), Value::from(name));
    }
    Ok((name, s))
}

// ---- decoding ----

fn field<'a>(v: &'a Value, key: &str) -> Result<&'a Value> {
    v.get(key).ok_or_else(|| anyhow!("missing field `{key}`"))
}

fn u64_of(v: &Value, key: &str) -> Result<u64> {
    field(v, key)?
        .as_u64()
        .ok_or_else(|| anyhow!("field `{key}` is not an unsigned integer"))
}

fn u32_of(v: &Value, key: &str) -> Result<u32> {
    u32::try_from(u64_of(v, key)?).map_err(|_| anyhow!("field `{key}` does not fit in u32"))
}

/// A joint array (null, as serde_json prints a non-finite float, reads as NaN).
fn joints_of(v: &Value, key: &str) -> Result<[f64; MAX_JOINTS]> {
    let arr = field(v, key)?
        .as_array()
        .ok_or_else(|| anyhow!("field `{key}` is not an array"))?;
    if arr.len() > MAX_JOINTS {
        bail!(
            "field `{key}` has {} entries, at most {MAX_JOINTS}",
            arr.len()
        );
    }
    let mut out = [0.0; MAX_JOINTS];
    for (o, x) in out.iter_mut().zip(arr) {
        *o = match x {
            Value::Null => f64::NAN,
            x => x
                .as_f64()
                .ok_or_else(|| anyhow!("field `{key}` holds a non-number"))?,
        };
    }
    Ok(out)
}

fn header_of(v: &Value) -> Result<Header> {
    let h = field(v, "header")?;
    Ok(Header {
        seq: u64_of(h, "seq")?,
        tick: u64_of(h, "tick")?,
        stamp_ns: u64_of(h, "stamp_ns")?,
        source_stamp_ns: u64_of(h, "source_stamp_ns")?,
    })
}

/// Parses a recorded setpoint.
pub fn setpoint_from(v: &Value) -> Result<JointSetpoint> {
    Ok(JointSetpoint {
        header: header_of(v)?,
        q: joints_of(v, "q")?,
        qd: joints_of(v, "qd")?,
        qdd: joints_of(v, "qdd")?,
        jerk: joints_of(v, "jerk")?,
        dof: u32_of(v, "dof")?,
        flags: u32_of(v, "flags")?,
    })
}

/// Parses a recorded torque command.
pub fn torque_from(v: &Value) -> Result<TorqueCommand> {
    Ok(TorqueCommand {
        header: header_of(v)?,
        tau: joints_of(v, "tau")?,
        q_desired: joints_of(v, "q_desired")?,
        setpoint_seq: u64_of(v, "setpoint_seq")?,
        state_seq: u64_of(v, "state_seq")?,
        dof: u32_of(v, "dof")?,
        flags: u32_of(v, "flags")?,
    })
}

/// Parses a recorded measured state.
pub fn state_from(v: &Value) -> Result<JointState> {
    Ok(JointState {
        header: header_of(v)?,
        q: joints_of(v, "q")?,
        qd: joints_of(v, "qd")?,
        tau_applied: joints_of(v, "tau_applied")?,
        torque_seq: u64_of(v, "torque_seq")?,
        dof: u32_of(v, "dof")?,
        lifecycle: u32_of(v, "lifecycle")?,
        flags: u32_of(v, "flags")?,
        reserved: u32_of(v, "reserved")?,
    })
}

// ---- reading ----

/// What a reader says about a file that ends early: how much it read, up to when, and the
/// record error where it stopped.
fn cut_note(messages: usize, last_log_time: Option<u64>, e: &mcap::McapError) -> String {
    let upto = last_log_time.map_or_else(String::new, |t| {
        format!(" (the last at log time {:.3} s)", t as f64 * 1e-9)
    });
    format!(
        "the file ends early (a recorder killed or a full disk?): read {messages} complete message(s){upto}, then: {e}; `microrobot recover IN OUT` writes a finished copy"
    )
}

/// Every attachment of an MCAP file, read record by record (outside chunks), so a file
/// without its summary section (a recorder killed) still gives those written before.
fn attachments(bytes: &[u8]) -> BTreeMap<String, Vec<u8>> {
    let mut out = BTreeMap::new();
    let Ok(reader) = mcap::read::LinearReader::new_with_options(
        bytes,
        mcap::read::Options::IgnoreEndMagic.into(),
    ) else {
        return out;
    };
    for record in reader {
        match record {
            Ok(mcap::records::Record::Attachment { header, data, .. }) => {
                out.insert(header.name, data.into_owned());
            }
            Ok(_) => {}
            Err(_) => break,
        }
    }
    out
}

/// One recorded message: its topic's JSON and the MCAP times.
#[derive(Debug, Clone)]
pub struct Recorded {
    pub log_time: u64,
    pub publish_time: u64,
    /// Position among the topic's messages in the file (malformed ones included).
    pub index: usize,
    pub value: Value,
}

/// A recording read back: messages per topic (file order) and the attachments.
#[derive(Debug, Default)]
pub struct Recording {
    pub topics: BTreeMap<String, Vec<Recorded>>,
    pub attachments: BTreeMap<String, Vec<u8>>,
    /// Messages left out as malformed, per topic: (position among the topic's messages in
    /// the file, why). Filled only by the readers that skip them
    /// ([`Recording::read_skipping_malformed`], [`Recording::parse_skipping`]).
    pub malformed: BTreeMap<String, Vec<(usize, String)>>,
    /// Where the file ended early (a recorder killed, a full disk): the messages before
    /// the first incomplete record were read, the rest is lost. `None` for a whole file.
    pub cut: Option<String>,
}

impl Recording {
    /// Reads `path`; every message must be JSON on a known channel.
    pub fn read(path: &Path) -> Result<Self> {
        Self::read_with(path, false)
    }

    /// Reads `path` like [`Recording::read`], but a message that is not valid JSON is
    /// left out and noted in [`Recording::malformed`] instead of failing the whole file
    /// (for `export` and `plot`; `replay` compares every message and stays strict).
    pub fn read_skipping_malformed(path: &Path) -> Result<Self> {
        Self::read_with(path, true)
    }

    /// One line per topic with malformed messages: how many were skipped, and the first.
    pub fn malformed_report(&self, path: &Path) -> Vec<String> {
        self.cut
            .iter()
            .map(|c| format!("{}: {c}", path.display()))
            .chain(
                self.malformed
                    .iter()
                    .filter(|(_, v)| !v.is_empty())
                    .map(|(topic, v)| {
                        format!(
                            "{}: skipped {} malformed `{topic}` message{} (first: message {}: {})",
                            path.display(),
                            v.len(),
                            if v.len() == 1 { "" } else { "s" },
                            v[0].0,
                            v[0].1
                        )
                    }),
            )
            .collect()
    }

    fn read_with(path: &Path, skip_malformed: bool) -> Result<Self> {
        let what = || path.display().to_string();
        let bytes = std::fs::read(path).with_context(|| format!("cannot read {}", what()))?;
        let mut rec = Recording::default();
        let mut per_topic: BTreeMap<String, usize> = BTreeMap::new();
        let stream = mcap::MessageStream::new(&bytes)
            .with_context(|| format!("{}: not an MCAP file", what()))?;
        let mut last_time = None;
        for (i, m) in stream.enumerate() {
            let m = match m {
                Ok(m) => m,
                Err(e) => {
                    rec.cut = Some(cut_note(i, last_time, &e));
                    break;
                }
            };
            last_time = Some(m.log_time);
            if m.channel.message_encoding != "json" {
                bail!(
                    "{}: channel `{}` has message encoding `{}`, expected json",
                    what(),
                    m.channel.topic,
                    m.channel.message_encoding
                );
            }
            // The viewer channels are derived from the streams, the log is text: nothing
            // to read back.
            if viewer::DERIVED_TOPICS.contains(&m.channel.topic.as_str())
                || m.channel.topic == logs::TOPIC
            {
                continue;
            }
            let position = per_topic.entry(m.channel.topic.clone()).or_default();
            let index = *position;
            *position += 1;
            let value: Value = match serde_json::from_slice(&m.data) {
                Ok(v) => v,
                Err(e) if skip_malformed => {
                    rec.malformed
                        .entry(m.channel.topic.clone())
                        .or_default()
                        .push((index, format!("not valid JSON: {e}")));
                    continue;
                }
                Err(e) => bail!(
                    "{}: message {i} on `{}` is not valid JSON: {e}",
                    what(),
                    m.channel.topic
                ),
            };
            rec.topics
                .entry(m.channel.topic.clone())
                .or_default()
                .push(Recorded {
                    log_time: m.log_time,
                    publish_time: m.publish_time,
                    index,
                    value,
                });
        }
        rec.attachments = attachments(&bytes);
        Ok(rec)
    }

    /// The messages of `topic` (empty if none were recorded).
    pub fn messages(&self, topic: &str) -> &[Recorded] {
        self.topics.get(topic).map_or(&[], Vec::as_slice)
    }

    /// Parses the messages of `topic` with `parse`, leaving out (and noting in
    /// [`Recording::malformed`]) those it refuses.
    pub fn parse_skipping<T>(&mut self, topic: &str, parse: fn(&Value) -> Result<T>) -> Vec<T> {
        let mut out = Vec::with_capacity(self.messages(topic).len());
        let mut bad = Vec::new();
        for m in self.messages(topic) {
            match parse(&m.value) {
                Ok(v) => out.push(v),
                Err(e) => bad.push((m.index, format!("{e:#}"))),
            }
        }
        self.note_malformed(topic, bad);
        out
    }

    /// Adds `bad` to the malformed messages of `topic`, in file order.
    pub fn note_malformed(&mut self, topic: &str, bad: Vec<(usize, String)>) {
        if bad.is_empty() {
            return;
        }
        let v = self.malformed.entry(topic.to_string()).or_default();
        v.extend(bad);
        v.sort_by_key(|(i, _)| *i);
    }

    /// Parses every message of `topic` with `parse`, naming the file and message on error.
    pub fn parse<T>(
        &self,
        path: &Path,
        topic: &str,
        parse: fn(&Value) -> Result<T>,
    ) -> Result<Vec<T>> {
        self.messages(topic)
            .iter()
            .enumerate()
            .map(|(i, m)| {
                parse(&m.value).with_context(|| {
                    format!("{}: `{topic}` message {i} is malformed", path.display())
                })
            })
            .collect()
    }
}

/// Flattens a message into (column, value) pairs: nested objects as `outer.inner`,
/// arrays as `name_0`, `name_1`, ...
pub fn flatten(prefix: &str, v: &Value, out: &mut Vec<(String, String)>) {
    match v {
        Value::Object(m) => {
            for (k, x) in m {
                let key = if prefix.is_empty() {
                    k.clone()
                } else {
                    format!("{prefix}.{k}")
                };
                flatten(&key, x, out);
            }
        }
        Value::Array(a) => {
            for (i, x) in a.iter().enumerate() {
                flatten(&format!("{prefix}_{i}"), x, out);
            }
        }
        Value::Null => out.push((prefix.to_string(), String::new())),
        Value::String(s) => out.push((prefix.to_string(), s.clone())),
        other => out.push((prefix.to_string(), other.to_string())),
    }
}
