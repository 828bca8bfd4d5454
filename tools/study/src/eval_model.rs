//! `microrobot eval model --robot FILE [--method newton-euler|lagrange-euler]`:
//! the model library's machine interface. Reads JSON lines `{"q":[..],"qd":[..],"qdd":[..]}`
//! (SI: rad or m) on stdin and writes, per input line and in order, one JSON line
//! `{"fk", "tool_pose", "jacobian", "mass_matrix", "gravity_torque", "coriolis_torque",
//! "tau"}` (fk: 4×4 row-major, metres; tool_pose: the same pose as
//! `[x, y, z, qw, qx, qy, qz]` in m and a unit quaternion, the form `microrobot send move
//! --pose` takes; jacobian: 6×n, rows vx vy vz wx wy wz) on stdout,
//! flushed per line. A bad line gets `{"error": "line N: ..."}` and processing
//! continues. Floats are printed in their shortest round-trip form.

use std::io::{BufRead, Write};
use std::path::Path;

use anyhow::Context;
use microrobot_runtime::exit_code;

use crate::eval_trajectory::RefusedLines;
use microrobot_command_line::exit::with_code;
use microrobot_model::{
    JointVector, MAX_JOINTS, ModelData, Robot, coriolis_torque, gravity_torque, jacobian,
    lagrange_euler, mass_matrix, rnea,
};
use serde::Deserialize;
use serde_json::{Value, json};

/// Which dynamics implementation fills `tau`, `mass_matrix`, `gravity_torque`
/// and `coriolis_torque` (kinematics is the same for both).
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Method {
    /// Recursive Newton-Euler and CRBA: the hot path.
    NewtonEuler,
    /// The seed's Lagrange-Euler equations (18–20, corrected): the reference.
    LagrangeEuler,
}

/// Runs the interface on stdin/stdout for the robot file at `robot_path`.
pub fn run(robot_path: &Path, method: Method) -> anyhow::Result<()> {
    let robot = Robot::from_file(robot_path)
        .map_err(|e| anyhow::anyhow!("--robot: {e}"))
        .map_err(with_code(exit_code::BAD_CONFIG))?;
    let stdin = std::io::stdin();
    let stdout = std::io::stdout();
    process(&robot, method, stdin.lock(), stdout.lock()).map_err(exit_code_of_refused)
}

/// Tags an error that is (or is caused by) [`RefusedLines`] with `JOB_FAILED`, the exit
/// code of an `eval` command that answered some lines with an error; any other error
/// passes unchanged.
pub fn exit_code_of_refused(e: anyhow::Error) -> anyhow::Error {
    if e.chain().any(|c| c.is::<RefusedLines>()) {
        with_code(exit_code::JOB_FAILED)(e)
    } else {
        e
    }
}

/// Processes every line of `input`, writing one output line each to `output`.
/// Only I/O failures end it early; bad lines produce error lines, and the command then
/// fails (`JOB_FAILED`) once every line is answered.
pub fn process(
    robot: &Robot,
    method: Method,
    input: impl BufRead,
    mut output: impl Write,
) -> anyhow::Result<()> {
    let mut data = ModelData::new(robot);
    let (mut lines, mut refused) = (0usize, 0usize);
    for (index, line) in input.lines().enumerate() {
        let line = line.context("reading stdin")?;
        if line.trim().is_empty() {
            continue;
        }
        lines += 1;
        let reply = match evaluate_line(robot, &mut data, method, &line) {
            Ok(v) => v,
            Err(message) => {
                refused += 1;
                json!({ "error": format!("line {}: {message}", index + 1) })
            }
        };
        serde_json::to_writer(&mut output, &reply).context("writing stdout")?;
        output.write_all(b"\n").context("writing stdout")?;
        output.flush().context("flushing stdout")?;
    }
    refused_lines(refused, lines)
}

/// Fails with [`RefusedLines`] when any of `lines` input lines was answered with an
/// error line.
pub fn refused_lines(refused: usize, lines: usize) -> anyhow::Result<()> {
    if refused > 0 {
        return Err(RefusedLines { refused, lines }.into());
    }
    Ok(())
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct Input {
    q: Vec<f64>,
    qd: Vec<f64>,
    qdd: Vec<f64>,
}

fn joint_vector(name: &str, values: &[f64], dof: usize) -> Result<JointVector, String> {
    if values.len() != dof {
        return Err(format!(
            "{name} has {} entries, the robot has {dof} joints",
            values.len()
        ));
    }
    let mut v = JointVector::zeros();
    for (i, x) in values.iter().enumerate().take(MAX_JOINTS) {
        if !x.is_finite() {
            return Err(format!("{name}[{i}] is not finite"));
        }
        v[i] = *x;
    }
    Ok(v)
}

/// Evaluates one input line; `Err` carries the message for the error line.
pub fn evaluate_line(
    robot: &Robot,
    data: &mut ModelData,
    method: Method,
    line: &str,
) -> Result<Value, String> {
    let input: Input = serde_json::from_str(line).map_err(|e| format!("invalid input: {e}"))?;
    let n = robot.dof();
    let q = joint_vector("q", &input.q, n)?;
    let qd = joint_vector("qd", &input.qd, n)?;
    let qdd = joint_vector("qdd", &input.qdd, n)?;

    let pose = microrobot_model::tool_pose(robot, data, &q);
    let fk = pose.to_homogeneous();
    let iso = pose.to_isometry();
    let (t, r) = (iso.translation.vector, iso.rotation);
    let tool_pose = vec![t.x, t.y, t.z, r.w, r.i, r.j, r.k];
    let jac = jacobian(robot, data, &q);
    let (m, g, c, tau) = match method {
        Method::NewtonEuler => (
            mass_matrix(robot, data, &q),
            gravity_torque(robot, data, &q),
            coriolis_torque(robot, data, &q, &qd),
            rnea(robot, data, &q, &qd, &qdd),
        ),
        Method::LagrangeEuler => (
            lagrange_euler::mass_matrix(robot, &q),
            lagrange_euler::gravity(robot, &q),
            lagrange_euler::coriolis(robot, &q, &qd),
            lagrange_euler::torque(robot, &q, &qd, &qdd),
        ),
    };
    let rows = |r: usize, cols: usize, at: &dyn Fn(usize, usize) -> f64| -> Vec<Vec<f64>> {
        (0..r)
            .map(|i| (0..cols).map(|j| at(i, j)).collect())
            .collect()
    };
    let vec = |v: &JointVector| -> Vec<f64> { (0..n).map(|i| v[i]).collect() };
    let out = Output {
        fk: rows(4, 4, &|i, j| fk[(i, j)]),
        tool_pose,
        jacobian: rows(6, n, &|i, j| jac[(i, j)]),
        mass_matrix: rows(n, n, &|i, j| m[(i, j)]),
        gravity_torque: vec(&g),
        coriolis_torque: vec(&c),
        tau: vec(&tau),
    };
    let all_finite = out
        .fk
        .iter()
        .chain(&out.jacobian)
        .chain(&out.mass_matrix)
        .flatten()
        .all(|x| x.is_finite())
        && out
            .gravity_torque
            .iter()
            .chain(&out.coriolis_torque)
            .chain(&out.tau)
            .all(|x| x.is_finite());
    if !all_finite {
        return Err("the model produced a non-finite result for this state".to_string());
    }
    serde_json::to_value(out).map_err(|e| format!("cannot encode the result: {e}"))
}

#[derive(serde::Serialize)]
struct Output {
    fk: Vec<Vec<f64>>,
    tool_pose: Vec<f64>,
    jacobian: Vec<Vec<f64>>,
    mass_matrix: Vec<Vec<f64>>,
    gravity_torque: Vec<f64>,
    coriolis_torque: Vec<f64>,
    tau: Vec<f64>,
}

#[cfg(test)]
mod tests {
    use super::*;

    fn seed_arm() -> Robot {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../config/robots/seed-arm.toml");
        Robot::from_file(&path).unwrap_or_else(|e| panic!("{e}"))
    }

    /// The output lines; the command's result must say how many lines were refused.
    fn lines(method: Method, input: &str) -> Vec<Value> {
        let mut out = Vec::new();
        let result = process(&seed_arm(), method, input.as_bytes(), &mut out);
        let text = String::from_utf8(out.clone()).unwrap_or_default();
        let errors = text.lines().filter(|l| l.starts_with("{\"error\"")).count();
        let total = text.lines().count();
        match result {
            Ok(()) => assert_eq!(errors, 0, "an error line, yet the command succeeded"),
            Err(e) => assert_eq!(
                e.downcast_ref::<RefusedLines>(),
                Some(&RefusedLines {
                    refused: errors,
                    lines: total
                }),
                "{e}"
            ),
        }
        String::from_utf8(out)
            .unwrap_or_default()
            .lines()
            .map(|l| serde_json::from_str(l).unwrap_or_else(|e| panic!("{e}: {l}")))
            .collect()
    }

    #[test]
    fn tool_pose_is_fk_as_position_and_unit_quaternion() {
        let line = r#"{"q":[0.3,-0.4,1.1,0.7,-0.5,2.0],"qd":[0,0,0,0,0,0],"qdd":[0,0,0,0,0,0]}"#;
        let out = lines(Method::NewtonEuler, line);
        let fk = |i: usize, j: usize| out[0]["fk"][i][j].as_f64().expect("fk entry");
        let p: Vec<f64> = (0..7)
            .map(|k| out[0]["tool_pose"][k].as_f64().expect("tool_pose entry"))
            .collect();
        for (k, v) in p[..3].iter().enumerate() {
            assert_eq!(*v, fk(k, 3), "position {k}");
        }
        let (w, x, y, z) = (p[3], p[4], p[5], p[6]);
        assert!((w * w + x * x + y * y + z * z - 1.0).abs() < 1e-12);
        // The rotation matrix of (w, x, y, z) is fk's 3×3 block.
        let r = [
            [
                1.0 - 2.0 * (y * y + z * z),
                2.0 * (x * y - w * z),
                2.0 * (x * z + w * y),
            ],
            [
                2.0 * (x * y + w * z),
                1.0 - 2.0 * (x * x + z * z),
                2.0 * (y * z - w * x),
            ],
            [
                2.0 * (x * z - w * y),
                2.0 * (y * z + w * x),
                1.0 - 2.0 * (x * x + y * y),
            ],
        ];
        for (i, row) in r.iter().enumerate() {
            for (j, v) in row.iter().enumerate() {
                assert!(
                    (v - fk(i, j)).abs() < 1e-12,
                    "R[{i}][{j}] {v} vs {}",
                    fk(i, j)
                );
            }
        }
    }

    #[test]
    fn good_lines_give_all_quantities_and_bad_lines_give_errors_in_order() {
        let good = r#"{"q":[0.1,0.2,0.3,0.4,0.5,0.6],"qd":[0,0,0,0,0,0],"qdd":[1,0,0,0,0,0]}"#;
        let input = format!(
            "{good}\nnot json\n{}\n{}\n{good}\n",
            r#"{"q":[0.1],"qd":[0,0,0,0,0,0],"qdd":[0,0,0,0,0,0]}"#,
            r#"{"q":[0.1,0.2,0.3,0.4,0.5,0.6],"qd":[0,0,0,0,0,0],"qdd":[0,0,0,0,0,0],"extra":1}"#
        );
        let out = lines(Method::NewtonEuler, &input);
        assert_eq!(out.len(), 5);
        assert_eq!(out[0]["fk"].as_array().map(Vec::len), Some(4));
        assert_eq!(out[0]["jacobian"].as_array().map(Vec::len), Some(6));
        assert_eq!(out[0]["jacobian"][0].as_array().map(Vec::len), Some(6));
        assert_eq!(out[0]["mass_matrix"].as_array().map(Vec::len), Some(6));
        assert_eq!(out[0]["tau"].as_array().map(Vec::len), Some(6));
        assert!(
            out[1]["error"]
                .as_str()
                .is_some_and(|e| e.starts_with("line 2: invalid input"))
        );
        assert!(
            out[2]["error"]
                .as_str()
                .is_some_and(|e| e.contains("q has 1 entries"))
        );
        assert!(
            out[3]["error"]
                .as_str()
                .is_some_and(|e| e.contains("extra"))
        );
        assert_eq!(out[4], out[0]);
    }

    #[test]
    fn both_methods_agree_and_floats_round_trip() {
        let input = r#"{"q":[0.1,-0.2,0.3,0.4,0.5,0.6],"qd":[0.3,0.1,-0.2,0.4,0.2,0.1],"qdd":[1,0.5,0,-1,0,0.2]}"#;
        let ne = lines(Method::NewtonEuler, input);
        let le = lines(Method::LagrangeEuler, input);
        for key in ["tau", "gravity_torque", "coriolis_torque"] {
            for i in 0..6 {
                let (a, b) = (
                    ne[0][key][i].as_f64().unwrap_or(f64::NAN),
                    le[0][key][i].as_f64().unwrap_or(f64::NAN),
                );
                assert!(
                    (a - b).abs() <= 1e-9 * b.abs().max(1e-3),
                    "{key}[{i}]: {a} vs {b}"
                );
            }
        }
        // Round trip: the printed tau equals the library's value bit for bit.
        let robot = seed_arm();
        let mut data = ModelData::new(&robot);
        let mut q = JointVector::zeros();
        let mut qd = JointVector::zeros();
        let mut qdd = JointVector::zeros();
        let parsed: Input = serde_json::from_str(input).unwrap_or_else(|e| panic!("{e}"));
        for i in 0..6 {
            q[i] = parsed.q[i];
            qd[i] = parsed.qd[i];
            qdd[i] = parsed.qdd[i];
        }
        let tau = rnea(&robot, &mut data, &q, &qd, &qdd);
        for i in 0..6 {
            assert_eq!(ne[0]["tau"][i].as_f64(), Some(tau[i]));
        }
    }

    #[test]
    fn non_finite_numbers_are_refused() {
        let out = lines(
            Method::NewtonEuler,
            r#"{"q":[1e999,0,0,0,0,0],"qd":[0,0,0,0,0,0],"qdd":[0,0,0,0,0,0]}"#,
        );
        assert!(out[0]["error"].is_string());
        let out = lines(
            Method::NewtonEuler,
            r#"{"q":[null,0,0,0,0,0],"qd":[0,0,0,0,0,0],"qdd":[0,0,0,0,0,0]}"#,
        );
        assert!(out[0]["error"].is_string());
    }
}
