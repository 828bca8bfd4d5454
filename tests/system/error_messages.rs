//! Every error message of the CLI and the config loaders that a user meets, with the
//! input that produces it and its exit code, so a change of wording shows here first.
//! `{cfg}` stands for the config file's path, `{dir}` for the test's directory, `{seed}`
//! for the seed arm's robot file.

use crate::common::*;
use microrobot_runtime::exit_code::{BAD_CONFIG, FAILURE, JOB_FAILED, USAGE};

/// One case: a config (top-level keys and tables, or none), the command line, the exit
/// code and a line the command must print (stderr, else stdout).
struct Case {
    config: Option<&'static str>,
    args: &'static [&'static str],
    code: u8,
    line: &'static str,
}

const CASES: &[Case] = &[
    // The pipeline config loader: the file and the full key path, what is wrong.
    Case {
        config: Some("rate_hz = -5.0"),
        args: &["check", "--config", "{cfg}", "-q"],
        code: BAD_CONFIG,
        line: "error: bad config: {cfg}: rate_hz: -5 is out of range [1, 10000]",
    },
    Case {
        config: Some("rate_hz = \"fast\""),
        args: &["check", "--config", "{cfg}", "-q"],
        code: BAD_CONFIG,
        line: "error: bad config: {cfg}: rate_hz: expected a number",
    },
    Case {
        config: Some("[watchdog]\nstale_msec = 10.0"),
        args: &["check", "--config", "{cfg}", "-q"],
        code: BAD_CONFIG,
        line: "error: bad config: {cfg}: watchdog.stale_msec: unknown key (expected one of: stale_ms, fault_ms, safe_state, auto_resume, ramp_ms)",
    },
    Case {
        config: Some("[watchdog]\nstale_ms = 100.0\nfault_ms = 50.0"),
        args: &["check", "--config", "{cfg}", "-q"],
        code: BAD_CONFIG,
        line: "error: bad config: {cfg}: watchdog.fault_ms: 50 must be >= watchdog.stale_ms (100)",
    },
    Case {
        config: Some("[supervisor]\nhung_ms = 100.0"),
        args: &["check", "--config", "{cfg}", "-q"],
        code: BAD_CONFIG,
        line: "error: bad config: {cfg}: supervisor.hung_ms: 100 must be >= 2 × status_period_ms (100): a healthy service reports once per status period",
    },
    Case {
        config: None,
        args: &["check", "--config", "{dir}/missing.toml", "-q"],
        code: BAD_CONFIG,
        line: "error: bad config: {dir}/missing.toml: cannot read: No such file or directory (os error 2)",
    },
    Case {
        config: Some(""),
        args: &[
            "check",
            "--config",
            "{cfg}",
            "--program",
            "{dir}/missing.toml",
            "-q",
        ],
        code: BAD_CONFIG,
        line: "error: bad config: --program {dir}/missing.toml: cannot open: No such file or directory (os error 2)",
    },
    Case {
        config: Some(""),
        args: &["run", "--config", "{cfg}", "--rate-hz", "NaN"],
        code: BAD_CONFIG,
        line: "error: bad config: --rate-hz: NaN is not a finite number",
    },
    Case {
        config: Some(""),
        args: &["run", "--config", "{cfg}", "--rate-hz", "0.5"],
        code: BAD_CONFIG,
        line: "error: bad config: {cfg} with command-line overrides: rate_hz: 0.5 is out of range [1, 10000]",
    },
    // The command line (clap): the value and the flag.
    Case {
        config: None,
        args: &["run", "--duration", "10x"],
        code: USAGE,
        line: "error: invalid value '10x' for '--duration <DURATION>': `10x` is not a duration (e.g. 60, 60s, 500ms, 10m, 1h)",
    },
    Case {
        config: None,
        args: &["run", "--duration", "0"],
        code: USAGE,
        line: "error: invalid value '0' for '--duration <DURATION>': `0`: the duration must be greater than 0",
    },
    Case {
        config: None,
        args: &["echo", "nosuch"],
        code: USAGE,
        line: "error: invalid value 'nosuch' for '<STREAM>'",
    },
    // `send`, checked before anything is sent, in the units typed.
    Case {
        config: Some(""),
        args: &[
            "send",
            "--config",
            "{cfg}",
            "--instance",
            "t-none",
            "move",
            "--joints",
            "0.1,NaN,0,0,0,0",
        ],
        code: FAILURE,
        line: "error: --joints: NaN is not a finite number",
    },
    Case {
        config: Some(""),
        args: &[
            "send",
            "--config",
            "{cfg}",
            "--instance",
            "t-none",
            "move",
            "--deg",
            "--joints",
            "0,0,0,0,0,400",
        ],
        code: FAILURE,
        line: "error: --joints: j6 target 400° is outside its range [-180°, 180°]",
    },
    Case {
        config: Some(""),
        args: &[
            "send",
            "--config",
            "{cfg}",
            "--instance",
            "t-none",
            "move",
            "--joints",
            "0,0,0,0,0,4",
        ],
        code: FAILURE,
        line: "error: --joints: j6 target 4 rad is outside its range [-3.141593 rad, 3.141593 rad]",
    },
    // Inspection of an instance that does not run.
    Case {
        config: None,
        args: &["echo", "state", "--instance", "t-none", "-n", "1"],
        code: FAILURE,
        line: "error: no pipeline instance `t-none` is running (see `microrobot list`)",
    },
    Case {
        config: None,
        args: &["record", "--instance", "bad name", "--out", "{dir}/x.mcap"],
        code: FAILURE,
        line: "error: --instance `bad name`: must be 1 to 64 characters of [A-Za-z0-9_-]",
    },
    // Offline tools.
    Case {
        config: None,
        args: &["eval", "model", "--robot", "{dir}/missing.toml"],
        code: BAD_CONFIG,
        line: "error: --robot: missing.toml: cannot read: No such file or directory (os error 2)",
    },
    Case {
        config: None,
        args: &["eval", "trajectory"],
        code: JOB_FAILED,
        line: "error: 1 of 1 input line(s) could not be evaluated (their output lines say why)",
    },
    // `robot urdf`: the robot file, and the output file.
    Case {
        config: None,
        args: &["robot", "urdf", "{dir}/missing.toml"],
        code: BAD_CONFIG,
        line: "error: robot file {dir}/missing.toml: missing.toml: cannot read: No such file or directory (os error 2)",
    },
    Case {
        config: None,
        args: &[
            "robot",
            "urdf",
            "{seed}",
            "-o",
            "{dir}/no-such-dir/arm.urdf",
        ],
        code: FAILURE,
        line: "error: cannot write {dir}/no-such-dir/arm.urdf: No such file or directory (os error 2)",
    },
];

#[test]
fn every_error_message_is_the_one_listed() {
    let dir = tempfile::tempdir().expect("tempdir");
    let d = dir.path().to_str().expect("utf-8").to_string();
    let mut wrong = Vec::new();
    for (k, case) in CASES.iter().enumerate() {
        let cfg = case.config.map(|body| {
            let (top, tables) = match body.find('[') {
                Some(i) => (&body[..i], &body[i..]),
                None => (body, ""),
            };
            let inst = instance(&format!("errmsg{k}"));
            write_config(dir.path(), &inst, top, tables)
        });
        let c = cfg
            .as_ref()
            .map(|p| p.to_str().expect("utf-8").to_string())
            .unwrap_or_default();
        let seed = seed_arm().to_str().expect("utf-8").to_string();
        let fill = |s: &str| {
            s.replace("{cfg}", &c)
                .replace("{dir}", &d)
                .replace("{seed}", &seed)
        };
        let args: Vec<String> = case.args.iter().map(|a| fill(a)).collect();
        let argv: Vec<&str> = args.iter().map(String::as_str).collect();
        // `eval trajectory` reads one bad line from stdin.
        let out = if argv == ["eval", "trajectory"] {
            let mut child = std::process::Command::new(bin())
                .args(&argv)
                .stdin(std::process::Stdio::piped())
                .stdout(std::process::Stdio::piped())
                .stderr(std::process::Stdio::piped())
                .spawn()
                .expect("spawn");
            use std::io::Write as _;
            child
                .stdin
                .take()
                .expect("stdin")
                .write_all(b"{\"profile\":\"nope\"}\n")
                .expect("write stdin");
            let o = child.wait_with_output().expect("wait");
            (
                o.status.code(),
                String::from_utf8_lossy(&o.stdout).into_owned(),
                String::from_utf8_lossy(&o.stderr).into_owned(),
            )
        } else {
            let o = run(&argv, 60.0);
            (o.code(), o.stdout.clone(), o.stderr.clone())
        };
        let line = fill(case.line);
        let printed = out.2.lines().chain(out.1.lines()).any(|l| l == line);
        if out.0 != Some(i32::from(case.code)) || !printed {
            wrong.push(format!(
                "{argv:?}: exit {:?} (want {}); want the line\n  {line}\nstderr:\n{}stdout:\n{}",
                out.0, case.code, out.2, out.1
            ));
        }
    }
    assert!(wrong.is_empty(), "{}", wrong.join("\n\n"));
}
