//! The channels a viewer shows without knowing this project: `transforms`
//! (`foxglove.FrameTransforms`: every joint frame, the URDF links of a URDF robot and the
//! tool, from the model's forward kinematics of the measured state, and under `cmd/` of
//! the commanded setpoint) and `joints` (per joint name, position, velocity, effort), both
//! derived from the recorded streams at a viewer's rate. Foxglove's 3D panel draws the
//! frames, its plots the joints. Derived data: the readers here skip these channels.

use anyhow::{Context as _, Result};
use microrobot_messages::{JointSetpoint, JointState, MAX_JOINTS};
use microrobot_model::{JointVector, ModelData, Pose, Robot, forward_kinematics};
use microrobot_runtime::config::PipelineConfig;
use nalgebra::UnitQuaternion;
use serde_json::{Value, json};

/// The derived channels: (topic, schema name, JSON Schema).
pub fn channels() -> [(&'static str, &'static str, Value); 2] {
    let time = json!({
        "type": "object",
        "properties": {"sec": {"type": "integer"}, "nsec": {"type": "integer"}},
        "required": ["sec", "nsec"]
    });
    let vec3 = json!({
        "type": "object",
        "properties": {"x": {"type": "number"}, "y": {"type": "number"}, "z": {"type": "number"}},
        "required": ["x", "y", "z"]
    });
    let quat = json!({
        "type": "object",
        "properties": {
            "x": {"type": "number"}, "y": {"type": "number"},
            "z": {"type": "number"}, "w": {"type": "number"}
        },
        "required": ["x", "y", "z", "w"]
    });
    let transform = json!({
        "title": "foxglove.FrameTransform",
        "type": "object",
        "properties": {
            "timestamp": time,
            "parent_frame_id": {"type": "string"},
            "child_frame_id": {"type": "string"},
            "translation": vec3,
            "rotation": quat
        },
        "required": ["timestamp", "parent_frame_id", "child_frame_id", "translation", "rotation"]
    });
    let transforms = json!({
        "title": "foxglove.FrameTransforms",
        "description": "An array of FrameTransform messages",
        "type": "object",
        "properties": {"transforms": {"type": "array", "items": transform}},
        "required": ["transforms"]
    });
    let numbers = json!({"type": "array", "items": {"type": "number"}});
    let joints = json!({
        "title": "microrobot.JointStates",
        "description": "Measured joints by name (SI: rad or m, rad/s or m/s, N·m or N)",
        "type": "object",
        "properties": {
            "timestamp": time,
            "name": {"type": "array", "items": {"type": "string"}},
            "position": numbers,
            "velocity": numbers,
            "effort": numbers
        },
        "required": ["timestamp", "name", "position", "velocity", "effort"]
    });
    [
        ("transforms", "foxglove.FrameTransforms", transforms),
        ("joints", "microrobot.JointStates", joints),
    ]
}

/// The topics of [`channels`].
pub const DERIVED_TOPICS: [&str; 2] = ["transforms", "joints"];

/// The root frame every transform hangs from.
pub const ROOT_FRAME: &str = "base_link";

/// The robot of a run and a workspace for its kinematics.
pub struct Viewer {
    robot: Robot,
    data: ModelData,
}

fn time(wall_ns: u64) -> Value {
    json!({"sec": wall_ns / 1_000_000_000, "nsec": wall_ns % 1_000_000_000})
}

fn transform(wall_ns: u64, child: &str, p: &Pose) -> Value {
    let q = UnitQuaternion::from_matrix(&p.rotation);
    json!({
        "timestamp": time(wall_ns),
        "parent_frame_id": ROOT_FRAME,
        "child_frame_id": child,
        "translation": {"x": p.translation.x, "y": p.translation.y, "z": p.translation.z},
        "rotation": {"x": q.i, "y": q.j, "z": q.k, "w": q.w}
    })
}

impl Viewer {
    /// The robot named by a resolved pipeline config's text (`origin` names it in errors).
    pub fn from_config_text(text: &str, origin: &str) -> Result<Self> {
        let cfg = PipelineConfig::from_toml_str(text, origin, std::path::Path::new("."))
            .map_err(anyhow::Error::new)?;
        let robot = Robot::from_file(&cfg.robot)
            .map_err(|e| anyhow::anyhow!("robot file {}: {e}", cfg.robot.display()))
            .with_context(|| format!("{origin}: the robot for the transforms"))?;
        let data = ModelData::new(&robot);
        Ok(Self { robot, data })
    }

    fn q(&self, q: &[f64; MAX_JOINTS], dof: u32) -> Option<JointVector> {
        let n = self.robot.dof();
        if dof as usize != n || q[..n].iter().any(|x| !x.is_finite()) {
            return None;
        }
        let mut v = JointVector::zeros();
        v.as_mut_slice()[..n].copy_from_slice(&q[..n]);
        Some(v)
    }

    /// Every frame at `q`, named with `prefix`: the joint frames (by joint name), a URDF
    /// robot's links, and `tool`.
    fn frames(&mut self, q: &JointVector, prefix: &str, wall_ns: u64) -> Value {
        forward_kinematics(&self.robot, &mut self.data, q);
        let mut out = Vec::new();
        for (i, j) in self.robot.joints().iter().enumerate() {
            out.push(transform(
                wall_ns,
                &format!("{prefix}{}", j.name),
                &self.data.frame(i + 1),
            ));
        }
        for l in self.robot.links() {
            let pose = self.data.frame(l.frame).compose(&l.offset);
            out.push(transform(wall_ns, &format!("{prefix}{}", l.name), &pose));
        }
        out.push(transform(
            wall_ns,
            &format!("{prefix}tool"),
            &self.data.tool_frame(),
        ));
        json!({ "transforms": out })
    }

    /// The `transforms` message of a measured state; `None` for a state of another arm.
    pub fn state_transforms(&mut self, m: &JointState, wall_ns: u64) -> Option<Value> {
        let q = self.q(&m.q, m.dof)?;
        Some(self.frames(&q, "", wall_ns))
    }

    /// The `transforms` message of a setpoint (frames under `cmd/`).
    pub fn setpoint_transforms(&mut self, m: &JointSetpoint, wall_ns: u64) -> Option<Value> {
        let q = self.q(&m.q, m.dof)?;
        Some(self.frames(&q, "cmd/", wall_ns))
    }

    /// The `joints` message of a measured state.
    pub fn joints(&self, m: &JointState, wall_ns: u64) -> Option<Value> {
        let n = self.robot.dof();
        if m.dof as usize != n {
            return None;
        }
        let names: Vec<&str> = self
            .robot
            .joints()
            .iter()
            .map(|j| j.name.as_str())
            .collect();
        Some(json!({
            "timestamp": time(wall_ns),
            "name": names,
            "position": &m.q[..n],
            "velocity": &m.qd[..n],
            "effort": &m.tau_applied[..n],
        }))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn viewer() -> Viewer {
        let robot =
            std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("config/robots/seed-arm.toml");
        let text = format!("robot = \"{}\"\n", robot.display());
        Viewer::from_config_text(&text, "test").expect("viewer")
    }

    #[test]
    fn the_tool_transform_is_the_models_tool_pose() {
        let mut v = viewer();
        let mut m = JointState {
            dof: 6,
            ..Default::default()
        };
        m.q[..6].copy_from_slice(&[0.1, 0.2, 0.3, 0.4, 0.5, 0.6]);
        let t = v.state_transforms(&m, 1_500_000_000).expect("transforms");
        let list = t["transforms"].as_array().expect("array");
        assert_eq!(list.len(), 7, "six joint frames and the tool");
        let tool = &list[6];
        assert_eq!(tool["child_frame_id"], "tool");
        assert_eq!(tool["parent_frame_id"], ROOT_FRAME);
        assert_eq!(tool["timestamp"]["sec"], 1);
        assert_eq!(tool["timestamp"]["nsec"], 500_000_000);
        let robot = v.robot.clone();
        let mut data = ModelData::new(&robot);
        let q = JointVector::from_column_slice(&[0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.0, 0.0]);
        let want = microrobot_model::tool_pose(&robot, &mut data, &q);
        for (axis, k) in ["x", "y", "z"].iter().enumerate() {
            let got = tool["translation"][k].as_f64().expect("number");
            assert!((got - want.translation[axis]).abs() < 1e-12, "{k}");
        }
        // A state of another arm (other joint count) gives nothing.
        m.dof = 5;
        assert!(v.state_transforms(&m, 0).is_none());
        assert!(v.joints(&m, 0).is_none());
    }
}
