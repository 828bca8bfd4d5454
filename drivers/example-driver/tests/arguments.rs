//! Bad arguments are refused with a message that names them, before the driver touches
//! the bus. (Having an integration test also makes `cargo test --workspace` build the
//! driver binary, which the system tests start in place of the actuator.)

use std::process::Command;

fn driver(args: &[&str]) -> (bool, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_microrobot-example-driver"))
        .args(args)
        .env(
            "MICROROBOT_INSTANCE",
            format!("driver-args-{}", std::process::id()),
        )
        .output()
        .expect("the example driver starts");
    (
        out.status.success(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

#[test]
fn unknown_argument_is_named() {
    let (ok, err) = driver(&["--speed", "3"]);
    assert!(!ok);
    assert!(err.contains("--speed"), "{err}");
}

#[test]
fn dof_out_of_range_is_refused() {
    let (ok, err) = driver(&["--dof", "9"]);
    assert!(!ok);
    assert!(err.contains("--dof"), "{err}");
}

#[test]
fn non_finite_start_position_is_refused() {
    let (ok, err) = driver(&["--dof", "2", "--q0-deg", "0,NaN"]);
    assert!(!ok);
    assert!(err.contains("finite"), "{err}");
}
