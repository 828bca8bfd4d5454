//! Child processes of the supervisor: spawned in their own process group (so a terminal
//! Ctrl-C reaches only the supervisor, which then stops them in order) with
//! `PR_SET_PDEATHSIG = SIGTERM` (so they stop if the supervisor dies, however it dies),
//! output appended to a log file per service (owner-only, never through a symlink).

use std::os::unix::process::{CommandExt, ExitStatusExt};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitStatus, Stdio};

use anyhow::Context as _;
use microrobot_messages::monotonic_ns;

/// How to start one service (kept to restart it the same way).
#[derive(Debug, Clone)]
pub struct Launch {
    /// Role name: planner, dynamics, actuator.
    pub role: &'static str,
    /// Program and arguments.
    pub argv: Vec<String>,
    /// Extra environment.
    pub env: Vec<(String, String)>,
    /// Log file (stdout and stderr).
    pub log: PathBuf,
}

/// A running (or exited) service process.
#[derive(Debug)]
pub struct Service {
    pub launch: Launch,
    child: Child,
    /// `CLOCK_MONOTONIC` ns at spawn: statuses older than this are from a predecessor.
    pub spawned_ns: u64,
    /// Set once reaped.
    pub exit: Option<ExitStatus>,
}

impl Service {
    /// Starts `launch`.
    pub fn spawn(launch: Launch) -> anyhow::Result<Self> {
        let (program, args) = launch
            .argv
            .split_first()
            .context("empty command for a service")?;
        let log = super::instance::open_private_append(&launch.log)
            .with_context(|| format!("cannot open log file {}", launch.log.display()))?;
        let log_err = log
            .try_clone()
            .with_context(|| format!("cannot open log file {}", launch.log.display()))?;
        let mut cmd = Command::new(program);
        cmd.args(args)
            .envs(launch.env.iter().map(|(k, v)| (k, v)))
            .stdin(Stdio::null())
            .stdout(log)
            .stderr(log_err);
        // SAFETY: only async-signal-safe calls (getpid/getppid, setpgid, prctl, _exit)
        // between fork and exec.
        let parent = std::process::id() as libc::pid_t;
        unsafe {
            cmd.pre_exec(move || {
                libc::setpgid(0, 0);
                libc::prctl(libc::PR_SET_PDEATHSIG, libc::SIGTERM, 0, 0, 0);
                // The supervisor died between fork and prctl: do not run orphaned.
                if libc::getppid() != parent {
                    libc::_exit(1);
                }
                Ok(())
            });
        }
        let spawned_ns = monotonic_ns();
        let child = cmd
            .spawn()
            .with_context(|| format!("cannot start the {} service: `{program}`", launch.role))?;
        Ok(Self {
            launch,
            child,
            spawned_ns,
            exit: None,
        })
    }

    /// OS process id.
    pub fn pid(&self) -> u32 {
        self.child.id()
    }

    /// Reaps the process if it exited; returns its status then (and on every later call).
    pub fn poll_exit(&mut self) -> Option<ExitStatus> {
        if self.exit.is_none()
            && let Ok(Some(st)) = self.child.try_wait()
        {
            self.exit = Some(st);
        }
        self.exit
    }

    /// Sends `signal` unless the process was already reaped.
    pub fn signal(&mut self, signal: libc::c_int) {
        if self.poll_exit().is_none() {
            // SAFETY: plain kill(2) on our own, not yet reaped, child.
            unsafe { libc::kill(self.child.id() as libc::pid_t, signal) };
        }
    }

    /// Sends SIGKILL and reaps.
    pub fn kill_and_reap(&mut self) {
        if self.poll_exit().is_none() {
            let _ = self.child.kill();
            if let Ok(st) = self.child.wait() {
                self.exit = Some(st);
            }
        }
    }
}

/// "exit code 3" / "killed by signal 9".
pub fn describe(status: ExitStatus) -> String {
    match (status.code(), status.signal()) {
        (Some(c), _) => format!("exit code {c}"),
        (None, Some(s)) => format!("killed by signal {s}"),
        _ => "unknown exit".to_string(),
    }
}

/// The last `lines` lines of a log file, for error messages.
pub fn log_tail(path: &Path, lines: usize) -> String {
    let text = std::fs::read_to_string(path).unwrap_or_default();
    let all: Vec<&str> = text.lines().collect();
    let start = all.len().saturating_sub(lines);
    all[start..].join("\n")
}
