//! The standalone binary refuses a bad config with exit code 2 and a message naming the
//! file and the key, before touching the bus.

use std::process::Command;

#[test]
fn bad_config_exits_bad_config_naming_the_key() {
    let dir = std::env::temp_dir().join(format!("mr-act-bin-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let cfg = dir.join("pipeline.toml");
    let robot =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../config/robots/seed-arm.toml");
    let text = format!(
        "robot = {:?}\n[watchdog]\nstale_ms = \"soon\"\n",
        robot.display().to_string()
    );
    std::fs::write(&cfg, text).unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_microrobot-actuator"))
        .arg("--config")
        .arg(&cfg)
        .env("RUST_LOG", "error")
        .output()
        .unwrap();
    assert_eq!(
        out.status.code(),
        Some(microrobot_runtime::exit_code::BAD_CONFIG as i32)
    );
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("pipeline.toml") && err.contains("watchdog.stale_ms"),
        "{err}"
    );
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn missing_arguments_exit_with_the_usage_code() {
    let out = Command::new(env!("CARGO_BIN_EXE_microrobot-actuator"))
        .output()
        .unwrap();
    assert_eq!(
        out.status.code(),
        Some(microrobot_runtime::exit_code::USAGE as i32)
    );
}
