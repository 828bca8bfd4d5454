//! `microrobot recover IN OUT`: a finished, indexed copy of a recording that ended early
//! (a recorder killed with `kill -9`, a full disk). Every record up to the first
//! incomplete one is copied — schemas, channels, messages, metadata, attachments — into
//! a new file with zstd chunks, a summary section and indexes; what was cut is said.
//! A whole file is copied as it is (and says so).

use std::collections::HashMap;
use std::fs::File;
use std::io::BufWriter;
use std::path::{Path, PathBuf};

use anyhow::{Context as _, Result, bail};
use mcap::records::Record;

/// Options of `microrobot recover`.
#[derive(Debug, Clone, clap::Args)]
pub struct RecoverArgs {
    /// A recording that ended early.
    #[arg(value_name = "IN.mcap")]
    pub input: PathBuf,
    /// The finished copy to write (must not be IN).
    #[arg(value_name = "OUT.mcap")]
    pub output: PathBuf,
}

/// What [`recover`] copied.
#[derive(Debug, Default)]
pub struct Recovered {
    pub messages: u64,
    pub attachments: u64,
    pub metadata: u64,
    /// Why the copy stopped before the end of the input; `None` when it was whole.
    pub cut: Option<String>,
}

/// Copies every complete record of `input` into a finished `output`.
pub fn recover(input: &Path, output: &Path) -> Result<Recovered> {
    if let (Ok(a), Ok(b)) = (input.canonicalize(), output.canonicalize())
        && a == b
    {
        bail!("{}: OUT must be another file than IN", output.display());
    }
    let bytes = std::fs::read(input).with_context(|| format!("cannot read {}", input.display()))?;
    let records = mcap::read::ChunkFlattener::new_with_options(
        &bytes,
        mcap::read::Options::IgnoreEndMagic.into(),
    )
    .with_context(|| format!("{}: not an MCAP file", input.display()))?;
    let file =
        File::create(output).with_context(|| format!("cannot create {}", output.display()))?;
    let mut w = mcap::WriteOptions::new()
        .compression(Some(mcap::Compression::Zstd))
        .profile("")
        .library(concat!(
            "microrobot ",
            env!("CARGO_PKG_VERSION"),
            " (recover)"
        ))
        .create(BufWriter::new(file))
        .with_context(|| format!("cannot start {}", output.display()))?;
    let werr = || format!("cannot write {}", output.display());
    let mut schemas: HashMap<u16, u16> = HashMap::new();
    let mut channels: HashMap<u16, u16> = HashMap::new();
    let mut out = Recovered::default();
    for record in records {
        let record = match record {
            Ok(r) => r,
            Err(e) => {
                out.cut = Some(format!(
                    "{}: ends early after {} complete message(s): {e}",
                    input.display(),
                    out.messages
                ));
                break;
            }
        };
        match record {
            Record::Schema { header, data } => {
                let id = w
                    .add_schema(&header.name, &header.encoding, &data)
                    .with_context(werr)?;
                schemas.insert(header.id, id);
            }
            Record::Channel(c) => {
                let schema = match c.schema_id {
                    0 => 0,
                    s => *schemas.get(&s).with_context(|| {
                        format!(
                            "{}: channel {} names unknown schema {s}",
                            input.display(),
                            c.id
                        )
                    })?,
                };
                let id = w
                    .add_channel(schema, &c.topic, &c.message_encoding, &c.metadata)
                    .with_context(werr)?;
                channels.insert(c.id, id);
            }
            Record::Message { header, data } => {
                let Some(&channel_id) = channels.get(&header.channel_id) else {
                    bail!(
                        "{}: a message on unknown channel {}",
                        input.display(),
                        header.channel_id
                    );
                };
                w.write_to_known_channel(
                    &mcap::records::MessageHeader {
                        channel_id,
                        ..header
                    },
                    &data,
                )
                .with_context(werr)?;
                out.messages += 1;
            }
            Record::Metadata(m) => {
                w.write_metadata(&m).with_context(werr)?;
                out.metadata += 1;
            }
            Record::Attachment { header, data, .. } => {
                w.attach(&mcap::Attachment {
                    log_time: header.log_time,
                    create_time: header.create_time,
                    name: header.name,
                    media_type: header.media_type,
                    data,
                })
                .with_context(werr)?;
                out.attachments += 1;
            }
            // The summary, indexes and footer are written anew.
            _ => {}
        }
    }
    w.finish().with_context(werr)?;
    std::io::Write::flush(&mut w.into_inner()).with_context(werr)?;
    Ok(out)
}

/// Runs `microrobot recover`.
pub fn main(args: RecoverArgs) -> Result<()> {
    let r = recover(&args.input, &args.output)?;
    match &r.cut {
        Some(cut) => eprintln!("{cut}; the rest is lost"),
        None => eprintln!("{}: the file was whole", args.input.display()),
    }
    println!(
        "wrote {}: {} messages, {} metadata record(s), {} attachment(s)",
        args.output.display(),
        r.messages,
        r.metadata,
        r.attachments
    );
    Ok(())
}
