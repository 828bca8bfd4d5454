//! `microrobot-chain-link`: one link of the bare chain that `microrobot probe-chain`
//! starts (three of them: sink, relay, source). As slim as the service binaries (the
//! link, the runtime, the build id and the pipeline file's reader), so the chain is
//! measured in processes of the services' size.
//!
//! ```text
//! microrobot-chain-link --config FILE --rate-hz R --duration S --link source|relay|sink --instance NAME
//! microrobot-chain-link --build-id
//! ```
//!
//! Prints `ready` once its ports exist, then its report as one JSON line when it ends.

use std::io::Write as _;
use std::path::PathBuf;
use std::process::ExitCode;

use microrobot_chain_link::{BINARY, Link};
use microrobot_runtime::exit_code;

/// The link's arguments.
struct Args {
    config: PathBuf,
    rate_hz: f64,
    duration_s: f64,
    link: Link,
    instance: String,
}

/// Reads `--flag value` pairs; every flag once, none missing, nothing else.
fn parse(args: &[String]) -> Result<Args, String> {
    let mut config = None;
    let mut rate_hz = None;
    let mut duration_s = None;
    let mut link = None;
    let mut instance = None;
    let mut it = args.iter();
    while let Some(flag) = it.next() {
        let value = it.next().ok_or_else(|| format!("{flag} needs a value"))?;
        let number = |what: &str| {
            value
                .parse::<f64>()
                .ok()
                .filter(|v| v.is_finite() && *v > 0.0)
                .ok_or_else(|| format!("{what} `{value}`: not a positive number"))
        };
        let slot_taken = match flag.as_str() {
            "--config" => config.replace(PathBuf::from(value)).is_some(),
            "--rate-hz" => rate_hz.replace(number("--rate-hz")?).is_some(),
            "--duration" => duration_s.replace(number("--duration")?).is_some(),
            "--link" => link
                .replace(
                    Link::from_name(value)
                        .ok_or_else(|| format!("--link `{value}`: one of source, relay, sink"))?,
                )
                .is_some(),
            "--instance" => instance.replace(value.clone()).is_some(),
            other => return Err(format!("unknown argument `{other}`")),
        };
        if slot_taken {
            return Err(format!("{flag} given twice"));
        }
    }
    let missing = |what: &str| format!("{what} is missing");
    Ok(Args {
        config: config.ok_or_else(|| missing("--config"))?,
        rate_hz: rate_hz.ok_or_else(|| missing("--rate-hz"))?,
        duration_s: duration_s.ok_or_else(|| missing("--duration"))?,
        link: link.ok_or_else(|| missing("--link"))?,
        instance: instance.ok_or_else(|| missing("--instance"))?,
    })
}

fn run(args: Args) -> anyhow::Result<()> {
    let mut cfg = microrobot_config::load(&args.config)?;
    cfg.rate_hz = args.rate_hz;
    let report = microrobot_chain_link::run(args.link, &args.instance, &cfg, args.duration_s)?;
    let mut out = std::io::stdout().lock();
    writeln!(out, "{}", serde_json::to_string(&report)?)?;
    out.flush()?;
    Ok(())
}

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if args.len() == 1 && args[0] == "--build-id" {
        println!("{}", microrobot_build_id::BUILD_ID);
        return ExitCode::SUCCESS;
    }
    let args = match parse(&args) {
        Ok(a) => a,
        Err(e) => {
            eprintln!(
                "{BINARY}: {e}\nusage: {BINARY} --config FILE --rate-hz R --duration S --link source|relay|sink --instance NAME\n       {BINARY} --build-id"
            );
            return ExitCode::from(exit_code::USAGE);
        }
    };
    match run(args) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("{BINARY}: error: {e:#}");
            ExitCode::from(exit_code::FAILURE)
        }
    }
}
