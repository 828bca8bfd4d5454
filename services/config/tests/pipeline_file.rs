//! The whole pipeline file read through every owner: defaults, unknown keys, wrong
//! types and ranges named by key, checks that span keys, and the effective config's
//! round trip.

use std::path::{Path, PathBuf};

use microrobot_config::from_toml_str;
use microrobot_runtime::config::{ConfigError, PipelineConfig};

fn dir_with_robot() -> (PathBuf, PathBuf) {
    let dir = std::env::temp_dir().join(format!("mr-cfg-{}-{}", std::process::id(), rand_suffix()));
    std::fs::create_dir_all(dir.join("robots")).unwrap();
    let robot = dir.join("robots/seed-arm.toml");
    std::fs::write(&robot, "# placeholder\n").unwrap();
    (dir, robot)
}

fn rand_suffix() -> u64 {
    use std::sync::atomic::{AtomicU64, Ordering};
    static N: AtomicU64 = AtomicU64::new(0);
    N.fetch_add(1, Ordering::Relaxed)
}

fn parse(text: &str) -> Result<PipelineConfig, ConfigError> {
    let (dir, _) = dir_with_robot();
    from_toml_str(text, "pipeline.toml", &dir)
}

fn err_key(text: &str) -> (Option<String>, String) {
    let e = parse(text).unwrap_err();
    assert_eq!(e.file, "pipeline.toml");
    let msg = e.to_string();
    assert!(msg.starts_with("pipeline.toml: "), "{msg}");
    (e.key, msg)
}

#[test]
fn empty_file_gives_defaults_with_resolved_robot() {
    let c = parse("").unwrap();
    assert_eq!(c.rate_hz, 1000.0);
    assert!(c.robot.is_absolute());
    assert!(c.robot.ends_with("robots/seed-arm.toml"));
    assert_eq!(c.watchdog.stale_ms, 50.0);
    assert_eq!(c.realtime.cpu_affinity, vec![1]);
}

#[test]
fn unknown_key_is_refused_with_its_path() {
    assert_eq!(err_key("rate = 5").0.as_deref(), Some("rate"));
    assert_eq!(
        err_key("[watchdog]\nstale = 5").0.as_deref(),
        Some("watchdog.stale")
    );
    assert_eq!(
        err_key("[actuator.sim]\nmass = 1.0").0.as_deref(),
        Some("actuator.sim.mass")
    );
    assert_eq!(err_key("[bogus]").0.as_deref(), Some("bogus"));
}

#[test]
fn wrong_type_non_finite_and_out_of_range_name_the_key() {
    assert_eq!(err_key("rate_hz = \"fast\"").0.as_deref(), Some("rate_hz"));
    assert_eq!(err_key("rate_hz = nan").0.as_deref(), Some("rate_hz"));
    assert_eq!(err_key("rate_hz = inf").0.as_deref(), Some("rate_hz"));
    assert_eq!(err_key("rate_hz = 0").0.as_deref(), Some("rate_hz"));
    assert_eq!(
        err_key("[watchdog]\nstale_ms = -1").0.as_deref(),
        Some("watchdog.stale_ms")
    );
    assert_eq!(
        err_key("[watchdog]\nfault_ms = 10").0.as_deref(),
        Some("watchdog.fault_ms")
    );
    assert_eq!(
        err_key("[watchdog]\nsafe_state = \"run\"").0.as_deref(),
        Some("watchdog.safe_state")
    );
    assert_eq!(
        err_key("[dynamics]\nfeedback = 1").0.as_deref(),
        Some("dynamics.feedback")
    );
    assert_eq!(
        err_key("[realtime]\nsched_fifo_priority = 100")
            .0
            .as_deref(),
        Some("realtime.sched_fifo_priority")
    );
    assert_eq!(
        err_key("[actuator.sim]\nsubsteps = 0").0.as_deref(),
        Some("actuator.sim.substeps")
    );
    assert_eq!(err_key("instance = \"a/b\"").0.as_deref(), Some("instance"));
    assert_eq!(
        err_key("program = \"nope.toml\"").0.as_deref(),
        Some("program")
    );
    assert_eq!(
        err_key("[planner]\nlimit_scale = 1.5").0.as_deref(),
        Some("planner.limit_scale")
    );
    // Denormal and tiny scales: refused like a command's, named, with the range.
    for (text, key) in [
        ("[planner]\nlimit_scale = 1e-300", "planner.limit_scale"),
        ("[planner]\nlimit_scale = 0.0009", "planner.limit_scale"),
        (
            "[planner]\nestop_limit_scale = 1e-300",
            "planner.estop_limit_scale",
        ),
    ] {
        let (k, msg) = err_key(text);
        assert_eq!(k.as_deref(), Some(key), "{text}");
        assert!(msg.contains("[0.001, 1]"), "{text}: {msg}");
    }
    assert!(parse("[planner]\nlimit_scale = 0.001").is_ok());
}

#[test]
fn syntax_error_names_the_file() {
    let e = parse("rate_hz = = 3").unwrap_err();
    assert_eq!(e.key, None);
    assert!(e.to_string().contains("pipeline.toml"));
}

#[test]
fn too_high_gains_for_the_rate_are_refused() {
    let (k, _) = err_key("rate_hz = 100\n[watchdog]\nstale_ms = 50\n[dynamics]\nkp_per_s2 = 10000");
    assert_eq!(k.as_deref(), Some("dynamics.kp_per_s2"));
}

#[test]
fn round_trip_through_toml_is_exact() {
    let c = parse(
        "instance = \"lab-1\"\nrate_hz = 4000.0\nduration_s = 2.5\nlockstep = true\n\
         [watchdog]\nsafe_state = \"damp\"\nauto_resume = true\n\
         [actuator]\ncommand = [\"drv\", \"--x\"]\n[actuator.sim]\nmass_scale = 1.1\ninitial_q_deg = [10, 20.5]\nintegrator = \"semi_implicit_euler\"\n\
         [realtime]\ncpu_affinity = []\noverrun = \"catch_up\"\n[supervisor]\non_failure = \"restart\"",
    )
    .unwrap();
    let text = c.to_toml_string();
    let back = from_toml_str(&text, "re.toml", Path::new("/nonexistent")).unwrap();
    assert_eq!(back, c);
}
