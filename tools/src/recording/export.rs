//! `microrobot export FILE.mcap --csv DIR`: one CSV per recorded topic.
//!
//! Columns: `log_time_ns`, then the message's fields flattened (`header.seq`, ...,
//! `q_0`..`q_{dof-1}`); floats as recorded (shortest round-trip form).

use std::io::Write as _;
use std::path::{Path, PathBuf};

use anyhow::{Context as _, Result, bail};

use super::{Recording, TOPICS, flatten};

/// Options of `microrobot export`.
#[derive(Debug, Clone, clap::Args)]
pub struct ExportArgs {
    /// Recording made by `microrobot record`.
    #[arg(value_name = "FILE.mcap")]
    pub file: PathBuf,
    /// Directory for `<topic>.csv` (created if missing).
    #[arg(long, value_name = "DIR")]
    pub csv: PathBuf,
}

fn csv_field(s: &str) -> String {
    if s.contains([',', '"', '\n']) {
        format!("\"{}\"", s.replace('"', "\"\""))
    } else {
        s.to_string()
    }
}

/// Writes one CSV per topic that has messages; returns (topic, rows) written.
pub fn export(file: &Path, dir: &Path) -> Result<Vec<(String, usize)>> {
    let rec = Recording::read(file)?;
    std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
    let mut written = Vec::new();
    let mut topics: Vec<&String> = rec.topics.keys().collect();
    topics.sort_by_key(|t| TOPICS.iter().position(|k| k == t).unwrap_or(TOPICS.len()));
    for topic in topics {
        let msgs = rec.messages(topic);
        let path = dir.join(format!("{topic}.csv"));
        let mut out = std::io::BufWriter::new(
            std::fs::File::create(&path)
                .with_context(|| format!("cannot create {}", path.display()))?,
        );
        let mut columns: Option<Vec<String>> = None;
        let mut cells = Vec::new();
        for (i, m) in msgs.iter().enumerate() {
            cells.clear();
            flatten("", &m.value, &mut cells);
            let names: Vec<String> = cells.iter().map(|(k, _)| k.clone()).collect();
            match &columns {
                None => {
                    let mut head = vec!["log_time_ns".to_string()];
                    head.extend(names.iter().map(|n| csv_field(n)));
                    writeln!(out, "{}", head.join(","))
                        .with_context(|| format!("cannot write {}", path.display()))?;
                    columns = Some(names);
                }
                Some(c) if *c != names => bail!(
                    "{}: `{topic}` message {i} has other fields than the first (dof changed?)",
                    file.display()
                ),
                Some(_) => {}
            }
            let mut row = vec![m.log_time.to_string()];
            row.extend(cells.iter().map(|(_, v)| csv_field(v)));
            writeln!(out, "{}", row.join(","))
                .with_context(|| format!("cannot write {}", path.display()))?;
        }
        out.flush()
            .with_context(|| format!("cannot write {}", path.display()))?;
        written.push((topic.clone(), msgs.len()));
    }
    Ok(written)
}

/// Runs `microrobot export`.
pub fn main(args: ExportArgs) -> Result<()> {
    let written = export(&args.file, &args.csv)?;
    if written.is_empty() {
        bail!("{}: the recording holds no messages", args.file.display());
    }
    for (topic, rows) in written {
        eprintln!(
            "{}: {rows} rows",
            args.csv.join(format!("{topic}.csv")).display()
        );
    }
    Ok(())
}
