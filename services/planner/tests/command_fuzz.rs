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
    assert!(p.accept_state(&s, 1));
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

proptest! {
    #![proptest_config(ProptestConfig::with_cases(512))]

    #[test]
    fn any_command_is_decoded_safely(
        kind in 0u32..6, profile in 0u32..6, space in 0u32..4, dof in 0u32..10,
        target in proptest::array::uniform8(any_f64()), duration_s in any_f64(), limit_scale in any_f64(),
        stamp_ns in any::<u64>(),
    ) {
        let mut p = planner();
        let before = p.tick(1);
        let c = MotionCommand { seq: 1, stamp_ns, kind, profile, space, dof, target, duration_s, limit_scale };
        let accepted = p.on_command(&c, 1_000_000_000_000).is_ok();
        let after = p.tick(1);
        if !accepted {
            prop_assert_eq!(before.q, after.q);
            prop_assert_eq!(before.qd, after.qd);
        }
        for i in 0..6 {
            prop_assert!(after.q[i].is_finite() && after.qd[i].is_finite() && after.qdd[i].is_finite());
        }
    }
}
