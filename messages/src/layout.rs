//! The layout of every bus payload, read from the compiled types: iceoryx2 type name,
//! size, alignment and each field's offset and size. The contract page's tables and the
//! Python mirror (`tools/python/check_layout.py`, through the `layout_json` example) are
//! checked against it. Every type is listed with an exhaustive struct pattern, so a field
//! added to a payload without being added here is a compile error, not a shorter list.

use core::mem::{align_of, offset_of, size_of, size_of_val};

use iceoryx2::prelude::ZeroCopySend;

use crate::{
    CommandVerdict, Header, HopLatency, JointSetpoint, JointState, LatencySummary, MasterPose,
    MotionCommand, ServiceStatus, TorqueCommand,
};

/// One payload type: name, iceoryx2 type name, size, alignment, (field, offset, size).
pub struct Layout {
    pub name: &'static str,
    pub type_name: &'static str,
    pub size: usize,
    pub align: usize,
    /// (field, offset, size), in offset order.
    pub fields: Vec<(&'static str, usize, usize)>,
}

/// The layout of `$t`, whose fields must be exactly `$f...` (in any order).
macro_rules! layout {
    ($t:ident { $($f:ident),* $(,)? }) => {{
        let v = $t::default();
        // Exhaustive: fails to compile when `$t` has a field not named above.
        let $t { $($f: _),* } = v;
        Layout {
            name: stringify!($t),
            // SAFETY: `type_name` only returns the `#[type_name]` string of the type.
            type_name: unsafe { <$t as ZeroCopySend>::type_name() },
            size: size_of::<$t>(),
            align: align_of::<$t>(),
            fields: vec![$((stringify!($f), offset_of!($t, $f), size_of_val(&v.$f))),*],
        }
    }};
}

/// Every payload of the contract, each with its fields in offset order.
pub fn payload_layouts() -> Vec<Layout> {
    let mut types = vec![
        layout!(Header {
            seq,
            tick,
            stamp_ns,
            source_stamp_ns
        }),
        layout!(JointSetpoint {
            header,
            q,
            qd,
            qdd,
            jerk,
            dof,
            flags
        }),
        layout!(TorqueCommand {
            header,
            tau,
            q_desired,
            setpoint_seq,
            state_seq,
            dof,
            flags
        }),
        layout!(JointState {
            header,
            q,
            qd,
            tau_applied,
            torque_seq,
            dof,
            lifecycle,
            flags,
            reserved
        }),
        layout!(MotionCommand {
            seq,
            stamp_ns,
            kind,
            profile,
            space,
            dof,
            target,
            duration_s,
            limit_scale
        }),
        layout!(LatencySummary {
            count,
            p50_ns,
            p99_ns,
            p999_ns,
            p9999_ns,
            max_ns
        }),
        layout!(ServiceStatus {
            seq,
            stamp_ns,
            role,
            lifecycle,
            pid,
            ready,
            cycles,
            deadline_misses,
            skipped_ticks,
            lost_messages,
            refused_messages,
            stale_cycles,
            clamped_cycles,
            faults,
            commands_accepted,
            commands_refused,
            motion_time_s,
            program_done,
            cpu_time_ms,
            rss_kib,
            latency,
            tracking_error_max,
            peak_torque,
            estops,
            estop_latency_ns,
            estop_latency_max_ns,
            last_command_refusal,
            last_input_refusal,
            program_state,
            program_end,
            activity,
            reserved,
            refusal_joint,
            refusal_quantity,
            refusal_value,
            refusal_min,
            refusal_max,
            command_verdicts,
            fault_code,
            fault_joint,
            latency_sum_ns,
            hops,
            hook,
            hook_budget_ms
        }),
        layout!(HopLatency {
            count,
            sum_ns,
            p50_ns,
            p99_ns,
            p999_ns,
            max_ns
        }),
        layout!(CommandVerdict {
            seq,
            publisher,
            refusal,
            reserved
        }),
        layout!(MasterPose {
            seq,
            stamp_ns,
            device_stamp_ns,
            position,
            orientation,
            grip,
            clutch,
            reserved
        }),
    ];
    for t in &mut types {
        t.fields.sort_by_key(|&(_, offset, _)| offset);
    }
    types
}
