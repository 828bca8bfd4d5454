//! `microrobot export FILE.mcap --out DIR`: one CSV per recorded topic.
//!
//! Columns: `log_time_ns`, then the message's fields flattened (`header.seq`, ...,
//! `q_0`..`q_{dof-1}`); floats as recorded (shortest round-trip form); `u64::MAX` (the
//! contract's "none") as an empty cell; `lifecycle_name` beside `lifecycle` and
//! `flag_names` beside `flags`. Malformed messages are skipped and counted per topic, not
//! exported. A file that ends early (a recorder killed, a full disk) is exported up to
//! its last complete chunk, with a warning saying where it was cut.

use std::collections::{BTreeMap, HashMap};
use std::io::Write as _;
use std::path::{Path, PathBuf};

use anyhow::{Context as _, Result, bail};
use microrobot_messages::{LifecycleState, setpoint_flags, state_flags, torque_flags};
use serde_json::Value;

use super::{Recording, TOPICS, flatten, setpoint_from, state_from, torque_from};

/// Options of `microrobot export`.
#[derive(Debug, Clone, clap::Args)]
pub struct ExportArgs {
    /// Recording made by `microrobot record`.
    #[arg(value_name = "FILE.mcap")]
    pub file: PathBuf,
    /// Directory for `<topic>.csv` (created if missing); `--csv` is an alias.
    #[arg(long = "out", visible_alias = "csv", value_name = "DIR")]
    pub csv: PathBuf,
}

fn csv_field(s: &str) -> String {
    if s.contains([',', '"', '\n']) {
        format!("\"{}\"", s.replace('"', "\"\""))
    } else {
        s.to_string()
    }
}

/// What [`export`] wrote.
#[derive(Debug, Default)]
pub struct Exported {
    /// (topic, rows written), in pipeline order.
    pub written: Vec<(String, usize)>,
    /// One line per topic with malformed messages (skipped, not exported).
    pub skipped: Vec<String>,
    /// Malformed messages skipped, per topic.
    pub skipped_counts: BTreeMap<String, usize>,
}

/// A message flattened: its position in the topic, log time and (column, value) cells.
type Row = (usize, u64, Vec<(String, String)>);

/// The flag names of `topic`'s `flags` field, if it has flags.
fn flag_names(topic: &str) -> Option<&'static [(u32, &'static str)]> {
    match topic {
        "setpoint" => Some(setpoint_flags::NAMES),
        "torque" => Some(torque_flags::NAMES),
        "state" => Some(state_flags::NAMES),
        _ => None,
    }
}

/// `cells` as a reader wants them: `u64::MAX` (the contract's "none", e.g. a state's
/// `torque_seq` before its first torque) as an empty cell, and beside `lifecycle` and
/// `flags` their names (`lifecycle_name`: `active`, ...; `flag_names`: `MOVING|ESTOP`,
/// empty for none, `0x...` for bits the contract does not name).
fn readable_cells(topic: &str, cells: Vec<(String, String)>) -> Vec<(String, String)> {
    let sentinel = u64::MAX.to_string();
    let mut out = Vec::with_capacity(cells.len() + 2);
    for (k, v) in cells {
        let v = if v == sentinel { String::new() } else { v };
        let named = match k.as_str() {
            "lifecycle" => Some((
                "lifecycle_name",
                v.parse::<u32>()
                    .ok()
                    .and_then(LifecycleState::from_wire)
                    .map_or_else(|| format!("unknown ({v})"), |l| l.name().to_string()),
            )),
            "flags" => flag_names(topic).map(|names| {
                let bits = v.parse::<u32>().unwrap_or(0);
                let mut parts: Vec<String> = names
                    .iter()
                    .filter(|(b, _)| bits & b != 0)
                    .map(|(_, n)| n.to_string())
                    .collect();
                let known = names.iter().fold(0, |acc, (b, _)| acc | b);
                if bits & !known != 0 {
                    parts.push(format!("{:#x}", bits & !known));
                }
                ("flag_names", parts.join("|"))
            }),
            _ => None,
        };
        out.push((k, v));
        if let Some((name, value)) = named {
            out.push((name.to_string(), value));
        }
    }
    out
}

/// Whether the typed reader of `topic` (for the streams that have one) takes `v`.
fn readable(topic: &str, v: &Value) -> Result<()> {
    match topic {
        "setpoint" => setpoint_from(v).map(drop),
        "torque" => torque_from(v).map(drop),
        "state" => state_from(v).map(drop),
        _ => Ok(()),
    }
}

/// Writes one CSV per topic that has messages. A malformed message (not JSON, refused
/// by the topic's reader, or with other fields than the topic's other messages — the
/// columns are those most of its messages have) is skipped and counted, not exported.
pub fn export(file: &Path, dir: &Path) -> Result<Exported> {
    let mut rec = Recording::read_skipping_malformed(file)?;
    std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
    let mut out_report = Exported::default();
    let mut topics: Vec<String> = rec.topics.keys().cloned().collect();
    topics.sort_by_key(|t| TOPICS.iter().position(|k| k == t).unwrap_or(TOPICS.len()));
    for topic in topics {
        // Flatten every message once; the columns are the most common field list.
        let mut rows: Vec<Row> = Vec::new();
        let mut bad = Vec::new();
        for m in rec.messages(&topic) {
            if let Err(e) = readable(&topic, &m.value) {
                bad.push((m.index, format!("{e:#}")));
                continue;
            }
            let mut cells = Vec::new();
            flatten("", &m.value, &mut cells);
            rows.push((m.index, m.log_time, readable_cells(&topic, cells)));
        }
        let mut counts: HashMap<Vec<&str>, usize> = HashMap::new();
        for (_, _, cells) in &rows {
            *counts
                .entry(cells.iter().map(|(k, _)| k.as_str()).collect())
                .or_default() += 1;
        }
        let columns: Vec<String> = counts
            .into_iter()
            .max_by_key(|(names, n)| (*n, std::cmp::Reverse(names.clone())))
            .map(|(names, _)| names.into_iter().map(str::to_string).collect())
            .unwrap_or_default();
        let path = dir.join(format!("{topic}.csv"));
        let mut out = std::io::BufWriter::new(
            std::fs::File::create(&path)
                .with_context(|| format!("cannot create {}", path.display()))?,
        );
        let mut head = vec!["log_time_ns".to_string()];
        head.extend(columns.iter().map(|n| csv_field(n)));
        writeln!(out, "{}", head.join(","))
            .with_context(|| format!("cannot write {}", path.display()))?;
        let mut n = 0;
        for (index, log_time, cells) in &rows {
            if cells.len() != columns.len() || cells.iter().zip(&columns).any(|((k, _), c)| k != c)
            {
                bad.push((
                    *index,
                    format!(
                        "other fields than the topic's other messages ({} columns, expected {})",
                        cells.len(),
                        columns.len()
                    ),
                ));
                continue;
            }
            let mut row = vec![log_time.to_string()];
            row.extend(cells.iter().map(|(_, v)| csv_field(v)));
            writeln!(out, "{}", row.join(","))
                .with_context(|| format!("cannot write {}", path.display()))?;
            n += 1;
        }
        out.flush()
            .with_context(|| format!("cannot write {}", path.display()))?;
        rec.note_malformed(&topic, bad);
        out_report.written.push((topic.clone(), n));
    }
    out_report.skipped = rec.malformed_report(file);
    out_report.skipped_counts = rec
        .malformed
        .iter()
        .map(|(t, v)| (t.clone(), v.len()))
        .collect();
    Ok(out_report)
}

/// Runs `microrobot export`.
pub fn main(args: ExportArgs) -> Result<()> {
    let exported = export(&args.file, &args.csv)?;
    for line in &exported.skipped {
        eprintln!("warning: {line}");
    }
    if exported.written.is_empty() {
        bail!("{}: the recording holds no messages", args.file.display());
    }
    for (topic, rows) in &exported.written {
        let skipped = exported.skipped_counts.get(topic).copied().unwrap_or(0);
        eprintln!(
            "{}: {rows} rows ({skipped} malformed messages skipped)",
            args.csv.join(format!("{topic}.csv")).display()
        );
    }
    Ok(())
}
