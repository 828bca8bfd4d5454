//! The `microrobot eval trajectory` line protocol (tools/study/src/eval_trajectory.rs),
//! compiled here against this crate so it is tested with the library.

#[allow(dead_code)]
#[path = "../../../tools/study/src/eval_trajectory.rs"]
mod eval_trajectory;

use eval_trajectory::eval_line;
use serde_json::Value;

fn ask(line: &str) -> Value {
    serde_json::from_str(&eval_line(line)).expect("answer is JSON")
}

fn error_of(line: &str) -> String {
    ask(line)["error"]
        .as_str()
        .unwrap_or_else(|| panic!("no error for {line}"))
        .to_string()
}

#[test]
fn soft_single_joint_matches_table4() {
    let r = ask(
        r#"{"profile":"soft","q0":-3.141592653589793,"q1":3.141592653589793,"vmax":2.356194490192345,"amax":1.3962634015954636,"jmax":2.792526803190927,"times":[0,2.4270833333333335,100]}"#,
    );
    assert!((r["duration"].as_f64().expect("duration") - 4.854166666666667).abs() < 1e-12);
    assert!(r["q"][1].as_f64().expect("q").abs() < 1e-12);
    assert_eq!(r["q"][2].as_f64(), Some(std::f64::consts::PI));
    assert_eq!(r["qd"][2].as_f64(), Some(0.0));
}

#[test]
fn arrays_make_one_synchronised_problem() {
    let r = ask(
        r#"{"profile":"soft","q0":[0,0],"q1":[1,0.1],"vmax":1,"amax":1,"jmax":[1,2],"times":[0,1]}"#,
    );
    assert_eq!(r["q"][0].as_array().expect("row").len(), 2);
    let single = ask(r#"{"profile":"soft","q0":0,"q1":1,"vmax":1,"amax":1,"jmax":1,"times":[]}"#);
    assert_eq!(r["duration"], single["duration"]);
}

#[test]
fn floats_round_trip_exactly() {
    let r = ask(r#"{"profile":"cubic","q0":0.1,"q1":0.7,"duration":3,"times":[3]}"#);
    assert_eq!(r["q"][0].as_f64(), Some(0.7));
}

#[test]
fn bad_problems_name_the_field() {
    assert!(error_of(r#"{"profile":"cubic","q0":0,"q1":1,"times":[0]}"#).starts_with("duration"));
    assert!(
        error_of(r#"{"profile":"soft","q0":0,"q1":1,"vmax":1,"amax":1,"times":[0]}"#)
            .starts_with("jmax")
    );
    assert!(
        error_of(r#"{"profile":"soft","q0":0,"q1":1,"vmax":-1,"amax":1,"jmax":1}"#)
            .starts_with("vmax")
    );
    assert!(
        error_of(r#"{"profile":"cubic","q0":0,"q1":1,"duration":1,"times":[-1]}"#)
            .starts_with("times[0]")
    );
    assert!(
        error_of(r#"{"profile":"lspb","q0":0,"q1":1,"duration":1,"cruise_velocity":0.5}"#)
            .starts_with("cruise_velocity")
    );
    assert!(
        error_of(r#"{"profile":"lspb","q0":0,"q1":1,"duration":1,"cruise_velocity":2.5}"#)
            .starts_with("cruise_velocity")
    );
    assert!(
        error_of(r#"{"profile":"lspb","q0":0,"q1":1,"duration":1,"cruise_velocity":-1.5}"#)
            .starts_with("cruise_velocity")
    );
    assert!(
        error_of(r#"{"profile":"soft","q0":[0,0],"q1":[1,2,3],"vmax":1,"amax":1,"jmax":1}"#)
            .starts_with("q1")
    );
    assert!(
        error_of(r#"{"profile":"soft","q0":0,"q1":1,"vmax":1,"amax":1,"jmax":1,"speed":3}"#)
            .starts_with("speed")
    );
    assert!(error_of(r#"{"profile":"warp","q0":0,"q1":1}"#).starts_with("profile"));
    assert!(
        error_of(
            r#"{"profile":"soft","q0":[0,0],"q1":[1,1],"v0":[0,5],"vmax":1,"amax":1,"jmax":1}"#
        )
        .starts_with("v0[1]")
    );
    assert!(error_of("not json").starts_with("problem"));
}

#[test]
fn lspb_accepts_the_closed_end_and_q1_equal_q0() {
    let r =
        ask(r#"{"profile":"lspb","q0":0,"q1":1,"duration":1,"cruise_velocity":2,"times":[0.5,1]}"#);
    assert_eq!(r["qd"][0].as_f64(), Some(2.0));
    let r = ask(r#"{"profile":"lspb","q0":1,"q1":1,"duration":1,"times":[0.5]}"#);
    assert_eq!(r["q"][0].as_f64(), Some(1.0));
    let r = ask(r#"{"profile":"lspb","q0":1,"q1":0,"duration":2,"times":[1]}"#);
    assert!((r["q"][0].as_f64().expect("q") - 0.5).abs() < 1e-12);
}
