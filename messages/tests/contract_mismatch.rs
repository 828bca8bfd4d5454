//! A process built against another contract (a payload with another type name or
//! layout on the same service) cannot open our services, and the error says why.

use iceoryx2::prelude::*;
use microrobot_messages::{BusError, JointSetpoint, ServiceKind, open_publish_subscribe};

/// What a build whose setpoint changed shape without a new contract version would send.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, ZeroCopySend)]
#[type_name("microrobot::v2::JointSetpoint")]
struct ReshapedSetpoint {
    q: [f64; 6],
}

/// What a build of the next contract version would send on the same name.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, ZeroCopySend)]
#[type_name("microrobot::v3::JointSetpoint")]
struct NextVersionSetpoint {
    q: [f64; 8],
}

fn node() -> Node<ipc::Service> {
    match NodeBuilder::new().create::<ipc::Service>() {
        Ok(n) => n,
        Err(e) => panic!("node: {e:?}"),
    }
}

fn refused<T: std::fmt::Debug + ZeroCopySend + 'static>(node: &Node<ipc::Service>, inst: &str) {
    match open_publish_subscribe::<T>(node, inst, ServiceKind::Setpoint) {
        Ok(_) => panic!("{} opened a v2 service", std::any::type_name::<T>()),
        Err(e @ BusError::Open { .. }) => {
            let msg = e.to_string();
            assert!(msg.contains("different contract version"), "{msg}");
            assert!(
                msg.contains(&format!("microrobot/v2/{inst}/setpoint")),
                "{msg}"
            );
        }
        Err(e) => panic!("unexpected error {e}"),
    }
}

#[test]
fn another_contract_cannot_open_the_services_and_says_so() {
    let inst = format!("contract-test-{}", std::process::id());
    let node = node();
    let ours = match open_publish_subscribe::<JointSetpoint>(&node, &inst, ServiceKind::Setpoint) {
        Ok(s) => s,
        Err(e) => panic!("{e}"),
    };
    let other = self::node();
    refused::<ReshapedSetpoint>(&other, &inst);
    refused::<NextVersionSetpoint>(&other, &inst);
    // Our own type still opens the same service.
    assert!(open_publish_subscribe::<JointSetpoint>(&other, &inst, ServiceKind::Setpoint).is_ok());
    drop(ours);
}
