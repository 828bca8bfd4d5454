//! Property test of the config loader: any text, and any single-line mutation of the
//! shipped config, gives a config or an error naming the file — never a panic, never a
//! non-finite value.

use std::path::{Path, PathBuf};

use microrobot_actuator::ActuatorConfig;
use microrobot_config::{from_toml_str, load};
use microrobot_dynamics::DynamicsConfig;
use microrobot_runtime::config::OwnedSection;
use proptest::prelude::*;

fn config_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../config")
}

fn shipped() -> String {
    std::fs::read_to_string(config_dir().join("pipeline.toml")).unwrap()
}

fn check(text: &str) {
    match from_toml_str(text, "fuzz.toml", &config_dir()) {
        Ok(c) => {
            assert!(c.rate_hz.is_finite() && c.rate_hz > 0.0);
            assert!(c.watchdog.stale_ms.is_finite() && c.watchdog.fault_ms >= c.watchdog.stale_ms);
            let dynamics = DynamicsConfig::from_pipeline(&c).unwrap();
            let actuator = ActuatorConfig::from_pipeline(&c).unwrap();
            assert!(dynamics.kp_per_s2.is_finite() && actuator.sim.mass_scale.is_finite());
            // What loads also round-trips.
            let back = from_toml_str(&c.to_toml_string(), "re.toml", Path::new("/")).unwrap();
            assert_eq!(back, c);
        }
        Err(e) => assert!(e.to_string().starts_with("fuzz.toml: "), "{e}"),
    }
}

#[test]
fn the_shipped_config_loads() {
    load(&config_dir().join("pipeline.toml")).unwrap();
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]

    #[test]
    fn arbitrary_text_never_panics(text in "\\PC{0,200}") {
        check(&text);
    }

    #[test]
    fn mutated_values_never_panic(line in 0usize..80, value in prop_oneof![
        Just("nan".to_string()), Just("-inf".to_string()), Just("-1".to_string()), Just("0".to_string()),
        Just("1e308".to_string()), Just("\"x\"".to_string()), Just("[]".to_string()), Just("true".to_string()),
        Just("{ a = 1 }".to_string()), (-1.0e6f64..1.0e6).prop_map(|v| format!("{v:?}")),
    ]) {
        let text = shipped();
        let mut lines: Vec<String> = text.lines().map(str::to_string).collect();
        let n = lines.len();
        let l = &mut lines[line % n];
        if let Some(eq) = l.find('=') {
            let key = l[..eq].to_string();
            *l = format!("{key}= {value}");
        }
        check(&lines.join("\n"));
    }
}

/// Replays every file of `tests/corpus/config/` (interesting configs, one per file)
/// through the same property on every run.
#[test]
fn the_config_corpus_never_panics() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/corpus/config");
    let mut n = 0;
    for entry in std::fs::read_dir(&dir).expect("corpus dir") {
        let path = entry.expect("entry").path();
        let bytes = std::fs::read(&path).expect("corpus file");
        // Not every corpus file is valid UTF-8 on purpose: those must be refused too.
        match String::from_utf8(bytes) {
            Ok(text) => check(&text),
            Err(_) => assert!(load(&path).is_err(), "{}", path.display()),
        }
        n += 1;
    }
    assert!(n >= 20, "{n} corpus files");
}
