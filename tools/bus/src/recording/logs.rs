//! The services' log lines in a recording, as `foxglove.Log` messages on the `log`
//! channel, so Foxglove's Log panel shows them beside the plots and the 3D view.
//!
//! The recorder follows the run directory's `planner.log`, `dynamics.log` and
//! `actuator.log` (a service's stderr, see the supervisor) from their start, a few times
//! a second, in its writer thread: the services themselves do nothing for it, so no
//! control cycle pays for a recording. A line of the services' tracing format
//! (`2026-12-04T05:00:53.402755Z  INFO target: message`) keeps its own time and level; any
//! other line (a driver's own output) is logged at level UNKNOWN at the time it was read.
//! A file that a new run replaces (same instance) is read again from its start; a
//! recorder started before that run may first take the previous run's lines, with
//! their own (earlier) times.

use std::io::{Read as _, Seek as _, SeekFrom};
use std::os::unix::fs::{MetadataExt as _, OpenOptionsExt as _};
use std::path::PathBuf;

use serde_json::{Value, json};

/// The channel's topic.
pub const TOPIC: &str = "log";
/// The channel's schema name.
pub const SCHEMA_NAME: &str = "foxglove.Log";

/// The log files followed, by the role that writes them.
const ROLES: [&str; 3] = ["planner", "dynamics", "actuator"];

/// At most this much of one file is read per poll (a runaway log cannot stall the
/// recorder; the rest comes at the next poll).
const MAX_READ: u64 = 1 << 20;

/// `foxglove.Log` level of an informational line.
pub const LEVEL_INFO: u8 = 2;
/// `foxglove.Log` level of a warning.
pub const LEVEL_WARNING: u8 = 3;

/// `foxglove.Log`'s level enum of a tracing level word (0: unknown).
fn level_of(word: &str) -> u8 {
    match word {
        "TRACE" | "DEBUG" => 1,
        "INFO" => LEVEL_INFO,
        "WARN" | "WARNING" => LEVEL_WARNING,
        "ERROR" => 4,
        _ => 0,
    }
}

/// The JSON Schema of `foxglove.Log` (as Foxglove publishes it, minimal).
pub fn schema() -> Value {
    json!({
        "title": SCHEMA_NAME,
        "description": "A log message",
        "type": "object",
        "properties": {
            "timestamp": {
                "type": "object",
                "properties": {"sec": {"type": "integer"}, "nsec": {"type": "integer"}},
                "required": ["sec", "nsec"]
            },
            "level": {"type": "integer", "description": "0 UNKNOWN, 1 DEBUG, 2 INFO, 3 WARNING, 4 ERROR, 5 FATAL"},
            "message": {"type": "string"},
            "name": {"type": "string"},
            "file": {"type": "string"},
            "line": {"type": "integer"}
        },
        "required": ["timestamp", "level", "message", "name", "file", "line"]
    })
}

/// One log line as a `foxglove.Log` message and its wall-clock time (ns since the
/// Unix epoch): its own stamp when it has one, else `read_wall_ns`.
pub fn parse_line(role: &str, line: &str, read_wall_ns: u64) -> (u64, Value) {
    let parsed = line.split_once(' ').and_then(|(stamp, rest)| {
        let wall = rfc3339_utc_ns(stamp)?;
        let rest = rest.trim_start();
        let (level, rest) = rest.split_once(' ')?;
        let level = level_of(level);
        (level != 0).then_some(())?;
        let rest = rest.trim_start();
        let (target, message) = match rest.split_once(": ") {
            Some((t, m)) if !t.contains(' ') => (t, m),
            _ => ("", rest),
        };
        Some((wall, level, target, message))
    });
    let (wall, level, file, message) = parsed.unwrap_or((read_wall_ns, 0, "", line));
    (wall, message_at(wall, level, role, file, message))
}

/// A `foxglove.Log` message stamped `wall` (ns since the Unix epoch) from `name`, with
/// `file` the line's source (its tracing target; empty when unknown).
pub fn message_at(wall: u64, level: u8, name: &str, file: &str, message: &str) -> Value {
    json!({
        "timestamp": {"sec": wall / 1_000_000_000, "nsec": wall % 1_000_000_000},
        "level": level,
        "message": message,
        "name": name,
        "file": file,
        "line": 0
    })
}

/// `YYYY-MM-DDTHH:MM:SS[.fraction]Z` (UTC, as tracing writes it) in ns since the Unix
/// epoch; `None` for anything else.
pub fn rfc3339_utc_ns(s: &str) -> Option<u64> {
    let s = s.strip_suffix('Z')?;
    let (date, time) = s.split_once('T')?;
    let mut d = date.splitn(3, '-');
    let (y, mo, da): (i64, u32, u32) = (
        d.next()?.parse().ok()?,
        d.next()?.parse().ok()?,
        d.next()?.parse().ok()?,
    );
    let (hms, frac) = time.split_once('.').unwrap_or((time, ""));
    let mut t = hms.splitn(3, ':');
    let (h, mi, se): (u64, u64, u64) = (
        t.next()?.parse().ok()?,
        t.next()?.parse().ok()?,
        t.next()?.parse().ok()?,
    );
    if !(1..=12).contains(&mo) || !(1..=31).contains(&da) || h > 23 || mi > 59 || se > 60 {
        return None;
    }
    if frac.len() > 9 || !frac.bytes().all(|b| b.is_ascii_digit()) {
        return None;
    }
    let nanos: u64 = if frac.is_empty() {
        0
    } else {
        frac.parse::<u64>().ok()? * 10u64.pow(9 - frac.len() as u32)
    };
    // Checked: a line is input, and a year like 99999999 must not overflow (a panic in
    // debug builds, a wrapped time in release).
    let days = u64::try_from(days_from_civil(y, mo, da)).ok()?;
    let secs = days
        .checked_mul(86_400)?
        .checked_add(h * 3600 + mi * 60 + se)?;
    secs.checked_mul(1_000_000_000)?.checked_add(nanos)
}

/// Days since 1970-01-01 of a proleptic Gregorian date (H. Hinnant's `days_from_civil`).
fn days_from_civil(y: i64, m: u32, d: u32) -> i64 {
    let y = if m <= 2 { y - 1 } else { y };
    let era = y.div_euclid(400);
    let yoe = y - era * 400;
    let m = i64::from(m);
    let doy = (153 * (if m > 2 { m - 3 } else { m + 9 }) + 2) / 5 + i64::from(d) - 1;
    let doe = yoe * 365 + yoe / 4 - yoe / 100 + doy;
    era * 146_097 + doe - 719_468
}

/// One followed file.
struct Tail {
    role: &'static str,
    /// Found once the run directory exists (a recorder may start before the run).
    path: Option<PathBuf>,
    /// The file followed (a new run replaces it: start again from its beginning).
    ino: Option<u64>,
    offset: u64,
    /// A line not yet ended.
    partial: Vec<u8>,
}

/// Follows the log files of a run directory.
pub struct LogTail {
    instance: String,
    tails: Vec<Tail>,
}

impl LogTail {
    /// Follows the services' logs of `instance` (none while its run directory does not
    /// exist or is not this user's private one).
    pub fn new(instance: &str) -> Self {
        let tails = ROLES
            .iter()
            .map(|role| Tail {
                role,
                path: None,
                ino: None,
                offset: 0,
                partial: Vec::new(),
            })
            .collect();
        Self {
            instance: instance.to_string(),
            tails,
        }
    }

    /// Reads what was appended since the last poll and calls `emit(wall_ns, message)`
    /// for every complete line; `flush` also emits a last line without its newline
    /// (at the end of the recording).
    pub fn poll(&mut self, read_wall_ns: u64, flush: bool, mut emit: impl FnMut(u64, Value)) {
        for t in &mut self.tails {
            if t.path.is_none() {
                t.path = microrobot_supervisor::instance::run_file(
                    &self.instance,
                    &format!("{}.log", t.role),
                )
                .ok();
            }
            t.read_new();
            while let Some(end) = t.partial.iter().position(|b| *b == b'\n') {
                let line: Vec<u8> = t.partial.drain(..=end).collect();
                let line = String::from_utf8_lossy(&line[..end]);
                if !line.trim().is_empty() {
                    let (wall, msg) = parse_line(t.role, line.trim_end(), read_wall_ns);
                    emit(wall, msg);
                }
            }
            if flush && !t.partial.is_empty() {
                let line = String::from_utf8_lossy(&t.partial).into_owned();
                t.partial.clear();
                let (wall, msg) = parse_line(t.role, line.trim_end(), read_wall_ns);
                emit(wall, msg);
            }
        }
    }
}

impl Tail {
    fn read_new(&mut self) {
        let Some(path) = &self.path else {
            return;
        };
        let Ok(mut f) = std::fs::OpenOptions::new()
            .read(true)
            .custom_flags(libc::O_NOFOLLOW | libc::O_CLOEXEC)
            .open(path)
        else {
            return;
        };
        let Ok(meta) = f.metadata() else {
            return;
        };
        if self.ino != Some(meta.ino()) || meta.len() < self.offset {
            self.ino = Some(meta.ino());
            self.offset = 0;
            self.partial.clear();
        }
        if meta.len() == self.offset || f.seek(SeekFrom::Start(self.offset)).is_err() {
            return;
        }
        let mut buf = Vec::new();
        if let Ok(n) = f.take(MAX_READ).read_to_end(&mut buf) {
            self.offset += n as u64;
            self.partial.extend_from_slice(&buf);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tracing_lines_keep_their_time_level_and_target() {
        let (wall, m) = parse_line(
            "planner",
            "2026-12-04T05:00:53.402755Z  WARN microrobot_planner::stage: planner: measured state is stale; stopping",
            7,
        );
        // 2026-12-04T05:00:53Z: `date -u -d 2026-12-04T05:00:53Z +%s` = 1796360453.
        assert_eq!(wall, 1_796_360_453_402_755_000);
        assert_eq!(m["level"], 3);
        assert_eq!(m["name"], "planner");
        assert_eq!(m["file"], "microrobot_planner::stage");
        assert_eq!(m["message"], "planner: measured state is stale; stopping");
        assert_eq!(m["timestamp"]["sec"], 1_796_360_453u64);
        assert_eq!(m["timestamp"]["nsec"], 402_755_000u64);
    }

    #[test]
    fn other_lines_are_kept_whole_at_the_time_they_were_read() {
        let (wall, m) = parse_line("actuator", "driver: hello 12:00 world", 42);
        assert_eq!(wall, 42);
        assert_eq!(m["level"], 0);
        assert_eq!(m["message"], "driver: hello 12:00 world");
        let (_, m) = parse_line("actuator", "2026-13-04T05:00:53Z INFO x: y", 42);
        assert_eq!(m["level"], 0, "month 13 is no date");
    }

    #[test]
    fn epoch_days_match_known_dates() {
        assert_eq!(rfc3339_utc_ns("1970-01-01T00:00:00Z"), Some(0));
        assert_eq!(
            rfc3339_utc_ns("2000-03-01T00:00:00.5Z"),
            Some(951_868_800_500_000_000)
        );
        assert_eq!(
            rfc3339_utc_ns("2024-02-29T23:59:59Z"),
            Some(1_709_251_199_000_000_000)
        );
        assert_eq!(rfc3339_utc_ns("2024-02-29 23:59:59Z"), None);
        // Out of u64 ns range, or before 1970: no time (the line is kept whole instead).
        assert_eq!(rfc3339_utc_ns("99999999-01-01T00:00:00Z"), None);
        assert_eq!(rfc3339_utc_ns("1969-12-31T23:59:59Z"), None);
        let (wall, m) = parse_line("planner", "99999999-01-01T00:00:00Z  INFO a: b", 5);
        assert_eq!((wall, m["level"].as_u64()), (5, Some(0)));
    }

    #[test]
    fn a_replaced_file_is_read_from_its_start_and_partial_lines_wait() {
        let dir = std::env::temp_dir().join(format!("mr-logtail-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("planner.log");
        std::fs::write(
            &path,
            "2026-12-04T05:00:53Z  INFO a: one\n2026-12-04T05:00:54Z  INFO a: tw",
        )
        .unwrap();
        let mut tail = LogTail {
            instance: "unused".into(),
            tails: vec![Tail {
                role: "planner",
                path: Some(path.clone()),
                ino: None,
                offset: 0,
                partial: Vec::new(),
            }],
        };
        let mut got = Vec::new();
        tail.poll(0, false, |_, m| {
            got.push(m["message"].as_str().unwrap().to_string())
        });
        assert_eq!(got, ["one"]);
        std::fs::OpenOptions::new()
            .append(true)
            .open(&path)
            .and_then(|mut f| std::io::Write::write_all(&mut f, b"o\n"))
            .unwrap();
        tail.poll(0, false, |_, m| {
            got.push(m["message"].as_str().unwrap().to_string())
        });
        assert_eq!(got, ["one", "two"]);
        // A new run removes the file and writes a new one.
        std::fs::remove_file(&path).unwrap();
        std::fs::write(&path, "2026-12-04T06:00:00Z ERROR b: fresh").unwrap();
        tail.poll(0, true, |_, m| {
            got.push(m["message"].as_str().unwrap().to_string())
        });
        assert_eq!(got, ["one", "two", "fresh"]);
        let _ = std::fs::remove_dir_all(&dir);
    }
}
