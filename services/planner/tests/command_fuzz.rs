//! Property test of the command decoder: any bit pattern in any field of a
//! `MotionCommand` is accepted or refused without a panic, and a refused command leaves
//! the setpoint stream exactly where it was.

use std::path::PathBuf;

use microrobot_messages::{Header, JointState, MotionCommand};
use microrobot_model::Robot;
use microrobot_planner::PlannerCore;
use microrobot_runtime::config::PipelineConfig;
use proptest::prelude::*;

fn planner() -> PlannerCore {
    let cfg = PipelineConfig {
        robot: PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../config/robots/seed-arm.toml"),
        ..Default::default()
    };
    let robot = Robot::from_file(&cfg.robot).unwrap();
    let mut p = PlannerCore::new(&robot, &cfg, None);
    let s = JointState {
        dof: 6,
        header: Header {
            seq: 1,
            ..Default::default()
        },
        ..Default::default()
    };
    assert!(p.accept_state(&s, 1, 0));
    p
}

fn any_f64() -> impl Strategy<Value = f64> {
    prop_oneof![
        any::<u64>().prop_map(f64::from_bits),
        -4.0f64..4.0,
        Just(f64::NAN),
        Just(f64::INFINITY),
        Just(0.0),
    ]
}

/// The property: decoded without a panic; a refused command leaves the setpoint stream
/// exactly where it was; every setpoint stays finite.
fn check(c: &MotionCommand) -> Result<(), TestCaseError> {
    let mut p = planner();
    let before = p.tick(1);
    let accepted = p.on_command(c, 1_000_000_000_000).is_ok();
    let after = p.tick(1);
    if !accepted {
        prop_assert_eq!(before.q, after.q);
        prop_assert_eq!(before.qd, after.qd);
    }
    for i in 0..6 {
        prop_assert!(after.q[i].is_finite() && after.qd[i].is_finite() && after.qdd[i].is_finite());
    }
    Ok(())
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(512))]

    #[test]
    fn any_command_is_decoded_safely(
        kind in 0u32..6, profile in 0u32..6, space in 0u32..4, dof in 0u32..10,
        target in proptest::array::uniform8(any_f64()), duration_s in any_f64(), limit_scale in any_f64(),
        stamp_ns in any::<u64>(),
    ) {
        check(&MotionCommand { seq: 1, stamp_ns, kind, profile, space, dof, target, duration_s, limit_scale })?;
    }
}

/// A float of the corpus: decimal, `nan`, `inf`, `-inf`, or `0x` + raw bits.
fn corpus_f64(s: &str) -> f64 {
    match s.strip_prefix("0x") {
        Some(hex) => f64::from_bits(u64::from_str_radix(hex, 16).expect("hex bits")),
        None => s.parse().unwrap_or_else(|_| panic!("corpus float `{s}`")),
    }
}

/// Replays `tests/corpus/commands.txt` (interesting commands, one per line) through the
/// same property on every run.
#[test]
fn the_command_corpus_is_decoded_safely() {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/corpus/commands.txt");
    let text = std::fs::read_to_string(&path).expect("corpus");
    let mut n = 0;
    for (i, line) in text.lines().enumerate() {
        let line = line.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let f: Vec<&str> = line.split_whitespace().collect();
        assert_eq!(f.len(), 15, "line {}: 15 fields", i + 1);
        let int = |s: &str| {
            s.parse::<u64>()
                .unwrap_or_else(|_| panic!("line {}: `{s}`", i + 1))
        };
        let mut target = [0.0; 8];
        for (t, s) in target.iter_mut().zip(&f[4..12]) {
            *t = corpus_f64(s);
        }
        let c = MotionCommand {
            seq: 1,
            kind: int(f[0]) as u32,
            profile: int(f[1]) as u32,
            space: int(f[2]) as u32,
            dof: int(f[3]) as u32,
            target,
            duration_s: corpus_f64(f[12]),
            limit_scale: corpus_f64(f[13]),
            stamp_ns: int(f[14]),
        };
        if let Err(e) = check(&c) {
            panic!("corpus line {}: {e}: {c:?}", i + 1);
        }
        n += 1;
    }
    assert!(n >= 30, "{n} corpus commands");
}
