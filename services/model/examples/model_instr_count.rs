//! Load-independent cost of the hot-path algorithms: runs one algorithm `CALLS`
//! times on the seed arm (the benchmark's 64 random states in turn), for
//! instruction counting under callgrind. Instructions per call =
//! (Ir at `CALLS` − Ir at 0 calls) / `CALLS`:
//!
//! ```text
//! cargo build --release -p microrobot-model --example model_instr_count
//! for a in fk jacobian rnea mass_matrix forward_dynamics; do
//!   for n in 0 10000; do
//!     valgrind --tool=callgrind --callgrind-out-file=/dev/null \
//!       target/release/examples/model_instr_count $a $n 2>&1 | grep 'refs:'
//!   done
//! done
//! ```

use microrobot_model::{
    JointVector, ModelData, forward_dynamics, forward_kinematics, jacobian, lagrange_euler,
    mass_matrix, rnea,
};
use std::hint::black_box;

mod common;

/// One call of an algorithm on a state `[q, qd, qdd]`.
type Call<'a> = Box<dyn FnMut(&[JointVector; 3]) + 'a>;

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let (Some(algo), Some(calls)) = (
        args.get(1),
        args.get(2).and_then(|n| n.parse::<usize>().ok()),
    ) else {
        eprintln!(
            "usage: model_instr_count fk|jacobian|rnea|mass_matrix|forward_dynamics|lagrange_euler CALLS"
        );
        std::process::exit(2);
    };
    let robot = common::seed_arm();
    let mut data = ModelData::new(&robot);
    let states = common::random_states(&robot, 64);
    let mut run: Call = match algo.as_str() {
        "fk" => Box::new(|s| {
            black_box(forward_kinematics(&robot, &mut data, &s[0]));
        }),
        "jacobian" => Box::new(|s| {
            black_box(jacobian(&robot, &mut data, &s[0]));
        }),
        "rnea" => Box::new(|s| {
            black_box(rnea(&robot, &mut data, &s[0], &s[1], &s[2]));
        }),
        "mass_matrix" => Box::new(|s| {
            black_box(mass_matrix(&robot, &mut data, &s[0]));
        }),
        "forward_dynamics" => Box::new(|s| {
            black_box(forward_dynamics(&robot, &mut data, &s[0], &s[1], &s[2]));
        }),
        "lagrange_euler" => Box::new(|s| {
            black_box(lagrange_euler::torque(&robot, &s[0], &s[1], &s[2]));
        }),
        other => {
            eprintln!("unknown algorithm {other}");
            std::process::exit(2);
        }
    };
    for k in 0..calls {
        run(black_box(&states[k & 63]));
    }
}
