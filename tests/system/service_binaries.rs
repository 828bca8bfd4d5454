//! The three services run as slim binaries of the same build as the CLI: each refuses a
//! bad config with exit code 2 naming the file and key before touching the bus, prints
//! the build id it shares with `microrobot`, and `microrobot run` refuses to start a
//! service binary that is missing or from another build, naming it and the command that
//! builds them all, before anything runs.

use std::path::{Path, PathBuf};
use std::process::Command;

use crate::common::*;
use microrobot_runtime::exit_code;

fn service_bin(role: &str) -> PathBuf {
    Path::new(bin())
        .parent()
        .expect("binary dir")
        .join(format!("microrobot-{role}"))
}

#[test]
fn a_service_binary_refuses_a_bad_config_naming_the_key() {
    let dir = tempfile::tempdir().expect("tempdir");
    let cfg = dir.path().join("pipeline.toml");
    let text = format!(
        "robot = {:?}\n[watchdog]\nstale_ms = \"soon\"\n",
        seed_arm().display().to_string()
    );
    std::fs::write(&cfg, text).expect("write config");
    let out = Command::new(actuator_bin())
        .arg("--config")
        .arg(&cfg)
        .env("RUST_LOG", "error")
        .output()
        .expect("run microrobot-actuator");
    assert_eq!(out.status.code(), Some(exit_code::BAD_CONFIG as i32));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("pipeline.toml") && err.contains("watchdog.stale_ms"),
        "{err}"
    );
}

#[test]
fn a_service_binary_without_arguments_exits_with_the_usage_code() {
    let out = Command::new(actuator_bin())
        .output()
        .expect("run microrobot-actuator");
    assert_eq!(out.status.code(), Some(exit_code::USAGE as i32));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("usage: microrobot-actuator --config FILE"),
        "{err}"
    );
}

#[test]
fn every_real_time_binary_is_of_the_clis_build() {
    let version = Command::new(bin())
        .arg("--version")
        .output()
        .expect("microrobot --version");
    let version = String::from_utf8_lossy(&version.stdout).into_owned();
    // The three services and the bare chain's link (`probe-chain`).
    for role in ["planner", "dynamics", "actuator", "chain-link"] {
        let out = Command::new(service_bin(role))
            .arg("--build-id")
            .output()
            .expect("--build-id");
        assert!(out.status.success(), "{role}: {:?}", out.status);
        let id = String::from_utf8_lossy(&out.stdout).trim().to_string();
        assert_eq!(id.len(), 16, "{role}: build id {id:?}");
        assert!(
            version.contains(&format!("(build {id})")),
            "{role}: build id {id} not in `microrobot --version`: {version}"
        );
    }
}

/// A copy of the CLI and the three services in a directory of its own, with `planner`
/// replaced by `replacement` (or removed when `None`).
fn install_with_planner(dir: &Path, replacement: Option<&str>) -> PathBuf {
    for name in [
        "microrobot",
        "microrobot-planner",
        "microrobot-dynamics",
        "microrobot-actuator",
    ] {
        let from = Path::new(bin()).parent().expect("binary dir").join(name);
        std::fs::copy(&from, dir.join(name))
            .unwrap_or_else(|e| panic!("copy {}: {e}", from.display()));
    }
    let planner = dir.join("microrobot-planner");
    std::fs::remove_file(&planner).expect("remove planner");
    if let Some(script) = replacement {
        use std::os::unix::fs::PermissionsExt as _;
        std::fs::write(&planner, script).expect("write planner");
        std::fs::set_permissions(&planner, std::fs::Permissions::from_mode(0o755))
            .expect("chmod planner");
    }
    dir.join("microrobot")
}

fn run_installed(cli: &Path, config: &Path) -> Finished {
    let out = Command::new(cli)
        .args(["run", "--config"])
        .arg(config)
        .args(["--duration", "1"])
        .env("RUST_LOG", "error")
        .output()
        .expect("run the copied microrobot");
    Finished {
        status: out.status,
        stdout: String::from_utf8_lossy(&out.stdout).into_owned(),
        stderr: String::from_utf8_lossy(&out.stderr).into_owned(),
    }
}

#[test]
fn run_refuses_a_service_binary_from_another_build_or_a_missing_one() {
    for (case, replacement, expected) in [
        (
            "stale",
            Some("#!/bin/sh\necho 0123456789abcdef\n"),
            "is from another build (build id 0123456789abcdef",
        ),
        ("missing", None, "microrobot-planner is missing"),
    ] {
        let dir = tempfile::tempdir().expect("tempdir");
        let cli = install_with_planner(dir.path(), replacement);
        let inst = instance(&format!("binaries-{case}"));
        let cfg = write_config(dir.path(), &inst, "", "");
        let out = run_installed(&cli, &cfg);
        assert_eq!(
            out.code(),
            Some(exit_code::FAILURE as i32),
            "{case}: {}",
            out.stderr
        );
        assert!(out.stderr.contains(expected), "{case}: {}", out.stderr);
        assert!(
            out.stderr.contains("build them all with `cargo build"),
            "{case}: {}",
            out.stderr
        );
        // Refused before anything started: the error is all it printed.
        assert_eq!(out.stderr.lines().count(), 1, "{case}: {}", out.stderr);
    }
}
