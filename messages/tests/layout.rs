//! The wire layout is part of the contract: drivers in C, C++ and Python mirror these
//! structs field by field. A change here must bump `CONTRACT_VERSION`.

use std::mem::{align_of, offset_of, size_of};

use microrobot_messages::*;

#[test]
fn header_layout_is_four_u64() {
    assert_eq!(size_of::<Header>(), 32);
    assert_eq!(offset_of!(Header, tick), 8);
    assert_eq!(offset_of!(Header, source_stamp_ns), 24);
}

#[test]
fn setpoint_layout_is_stable() {
    assert_eq!(offset_of!(JointSetpoint, q), 32);
    assert_eq!(offset_of!(JointSetpoint, qd), 32 + 64);
    assert_eq!(offset_of!(JointSetpoint, jerk), 32 + 3 * 64);
    assert_eq!(offset_of!(JointSetpoint, dof), 32 + 4 * 64);
    assert_eq!(size_of::<JointSetpoint>(), 32 + 4 * 64 + 8);
    assert_eq!(align_of::<JointSetpoint>(), 8);
}

#[test]
fn torque_and_state_layouts_are_stable() {
    assert_eq!(offset_of!(TorqueCommand, setpoint_seq), 32 + 2 * 64);
    assert_eq!(size_of::<TorqueCommand>(), 32 + 2 * 64 + 16 + 8);
    assert_eq!(offset_of!(JointState, torque_seq), 32 + 3 * 64);
    assert_eq!(size_of::<JointState>(), 32 + 3 * 64 + 8 + 16);
}

#[test]
fn status_layout_is_stable() {
    assert_eq!(offset_of!(ServiceStatus, latency), 136);
    assert_eq!(offset_of!(ServiceStatus, peak_torque), 136 + 48 + 64);
    assert_eq!(offset_of!(ServiceStatus, estops), 312);
    assert_eq!(offset_of!(ServiceStatus, estop_latency_ns), 320);
    assert_eq!(offset_of!(ServiceStatus, estop_latency_max_ns), 328);
    assert_eq!(offset_of!(ServiceStatus, last_command_refusal), 336);
    assert_eq!(offset_of!(ServiceStatus, last_input_refusal), 340);
    assert_eq!(offset_of!(ServiceStatus, program_state), 344);
    assert_eq!(offset_of!(ServiceStatus, program_end), 348);
    assert_eq!(offset_of!(ServiceStatus, activity), 352);
    assert_eq!(offset_of!(ServiceStatus, reserved), 356);
    assert_eq!(offset_of!(ServiceStatus, refusal_joint), 360);
    assert_eq!(offset_of!(ServiceStatus, refusal_quantity), 364);
    assert_eq!(offset_of!(ServiceStatus, refusal_value), 368);
    assert_eq!(offset_of!(ServiceStatus, refusal_min), 376);
    assert_eq!(offset_of!(ServiceStatus, refusal_max), 384);
    assert_eq!(offset_of!(ServiceStatus, command_verdicts), 392);
    assert_eq!(offset_of!(CommandVerdict, publisher), 8);
    assert_eq!(offset_of!(CommandVerdict, refusal), 24);
    assert_eq!(size_of::<CommandVerdict>(), 32);
    assert_eq!(COMMAND_VERDICTS, 16);
    assert_eq!(offset_of!(ServiceStatus, fault_code), 904);
    assert_eq!(offset_of!(ServiceStatus, fault_joint), 908);
    assert_eq!(offset_of!(ServiceStatus, latency_sum_ns), 912);
    assert_eq!(offset_of!(ServiceStatus, hops), 920);
    assert_eq!(size_of::<HopLatency>(), 48);
    assert_eq!(offset_of!(HopLatency, sum_ns), 8);
    assert_eq!(STATUS_HOPS, 2);
    assert_eq!(offset_of!(ServiceStatus, hook), 1016);
    assert_eq!(offset_of!(ServiceStatus, hook_budget_ms), 1020);
    assert_eq!(size_of::<ServiceStatus>(), 1024);
    assert_eq!(align_of::<ServiceStatus>(), 8);
}

#[test]
fn command_layout_is_stable() {
    assert_eq!(offset_of!(MotionCommand, target), 32);
    assert_eq!(offset_of!(MotionCommand, duration_s), 32 + 64);
    assert_eq!(size_of::<MotionCommand>(), 32 + 64 + 16);
}

#[test]
fn wire_enums_round_trip_and_refuse_unknown_values() {
    for k in [
        CommandKind::Move,
        CommandKind::Stop,
        CommandKind::EStop,
        CommandKind::Reset,
    ] {
        assert_eq!(CommandKind::from_wire(k as u32), Some(k));
    }
    assert_eq!(CommandKind::from_wire(0), None);
    assert_eq!(CommandKind::from_wire(99), None);
    assert_eq!(ProfileKind::from_wire(5), None);
    assert_eq!(TargetSpace::from_wire(3), None);
    assert_eq!(ServiceRole::from_wire(4), None);
    assert_eq!(LifecycleState::from_wire(5), None);
    for v in 0..=20 {
        let r = RefusalReason::from_wire(v).expect("known reason");
        assert_eq!(r as u32, v);
        assert!(!r.describe().is_empty());
    }
    assert_eq!(RefusalReason::from_wire(21), None);
    for v in 0..=5 {
        let p = ProgramState::from_wire(v).expect("known program state");
        assert_eq!(p as u32, v);
    }
    assert_eq!(ProgramState::from_wire(6), None);
    for v in 0..=6 {
        let e = ProgramEnd::from_wire(v).expect("known program end");
        assert_eq!(e as u32, v);
        assert!(!e.describe().is_empty());
    }
    assert_eq!(ProgramEnd::from_wire(7), None);
    for v in 0..=7 {
        let a = Activity::from_wire(v).expect("known activity");
        assert_eq!(a as u32, v);
    }
    assert_eq!(Activity::from_wire(8), None);
    for v in 0..=5 {
        let q = RefusalQuantity::from_wire(v).expect("known quantity");
        assert_eq!(q as u32, v);
    }
    assert_eq!(RefusalQuantity::from_wire(6), None);
}

/// The version goes with the layouts pinned here: it is in every payload's type name,
/// and version 2 is the one whose `ServiceStatus` is 1024 B (version 1's was 1016 B,
/// without `hook` and `hook_budget_ms`).
#[test]
fn every_type_name_carries_the_contract_version() {
    assert_eq!(CONTRACT_VERSION, 2);
    assert_eq!(size_of::<ServiceStatus>(), 1024);
    for t in layout::payload_layouts() {
        assert_eq!(
            t.type_name,
            format!("microrobot::v{CONTRACT_VERSION}::{}", t.name),
            "{}",
            t.name
        );
    }
}

#[test]
fn service_names_carry_version_and_instance() {
    assert_eq!(
        service_name("lab1", ServiceKind::Setpoint),
        format!("microrobot/v{CONTRACT_VERSION}/lab1/setpoint")
    );
    let names: std::collections::HashSet<_> = ServiceKind::ALL
        .iter()
        .map(|k| service_name("a", *k))
        .collect();
    assert_eq!(names.len(), ServiceKind::ALL.len());
}

#[test]
fn all_finite_checks_only_active_joints() {
    let mut v = [0.0; MAX_JOINTS];
    v[7] = f64::NAN;
    assert!(all_finite(&v, 6));
    assert!(!all_finite(&v, 8));
    assert!(!all_finite(&v, 9));
}

/// Each sender finds its own command's verdict in the ring, also after it wrapped, and
/// is told when newer commands may have pushed its verdict out.
#[test]
fn command_verdicts_are_found_by_publisher_and_seq() {
    let mut st = ServiceStatus::default();
    let take = |st: &mut ServiceStatus, seq: u64, publisher: u128, r: RefusalReason| {
        if r == RefusalReason::None {
            st.commands_accepted += 1;
        } else {
            st.commands_refused += 1;
        }
        st.record_command_verdict(seq, publisher, r);
    };
    let a = 1u128 << 100 | 7;
    let b = 2u128 << 100 | 7;
    assert_eq!(st.command_verdict(a, 5, 0), VerdictLookup::NotYet);
    take(&mut st, 5, a, RefusalReason::None);
    // The same seq from another publisher is another command.
    take(&mut st, 5, b, RefusalReason::CannotPlan);
    assert_eq!(st.command_verdict(a, 5, 0), VerdictLookup::Accepted);
    assert_eq!(
        st.command_verdict(b, 5, 0),
        VerdictLookup::Refused(Some(RefusalReason::CannotPlan))
    );
    // Taken before the sender's baseline: not this sender's command.
    assert_eq!(st.command_verdict(a, 5, 2), VerdictLookup::NotYet);
    for k in 0..15u64 {
        take(&mut st, 100 + k, a, RefusalReason::None);
    }
    // 17 taken: the first fell out of the ring of 16, the second is still there.
    assert_eq!(st.commands_taken(), 17);
    assert_eq!(st.command_verdict(a, 5, 0), VerdictLookup::MaybeOverwritten);
    assert_eq!(
        st.command_verdict(b, 5, 0),
        VerdictLookup::Refused(Some(RefusalReason::CannotPlan))
    );
    assert_eq!(st.command_verdict(a, 114, 0), VerdictLookup::Accepted);
}
