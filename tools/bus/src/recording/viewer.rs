//! The channels a viewer shows without knowing this project: `transforms`
//! (`foxglove.FrameTransforms`: every joint frame, the URDF links of a URDF robot and the
//! tool, from the model's forward kinematics of the measured state, and under `cmd/` of
//! the commanded setpoint), `scene` (`foxglove.SceneUpdate`: the arm as a line through
//! its joint origins to the tool, with a sphere at each joint) and `joints` (per joint
//! name, position, velocity, effort), all derived from the recorded streams at a viewer's
//! rate. Foxglove's 3D panel draws the frames and the arm, its plots the joints. Derived
//! data: the readers here skip these channels. [`Feed`] derives them from the bus for
//! both the recorder (into the file) and `microrobot view` (live, over WebSocket).

use anyhow::{Context as _, Result};
use microrobot_messages::{JointSetpoint, JointState, MAX_JOINTS};
use microrobot_model::{JointVector, ModelData, Pose, Robot, forward_kinematics};
use nalgebra::UnitQuaternion;
use serde_json::{Value, json};

/// The derived channels: (topic, schema name, JSON Schema).
pub fn channels() -> [(&'static str, &'static str, Value); 3] {
    let time = object_of("integer", &["sec", "nsec"]);
    let vec3 = object_of("number", &["x", "y", "z"]);
    let quat = object_of("number", &["x", "y", "z", "w"]);
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
    // Items are objects of any shape; `properties` is spelled out (empty) because
    // Foxglove Studio's JSON Schema reader walks it on every object and rejects the
    // whole channel without it.
    let objects = json!({"type": "array", "items": {"type": "object", "properties": {}}});
    let entity = json!({
        "title": "foxglove.SceneEntity",
        "type": "object",
        "properties": {
            "timestamp": time,
            "frame_id": {"type": "string"},
            "id": {"type": "string"},
            "lifetime": time,
            "frame_locked": {"type": "boolean"},
            "metadata": objects, "arrows": objects, "cubes": objects, "spheres": objects,
            "cylinders": objects, "lines": objects, "triangles": objects, "texts": objects,
            "models": objects
        }
    });
    let scene = json!({
        "title": "foxglove.SceneUpdate",
        "description": "An update to the entities displayed in a 3D scene",
        "type": "object",
        "properties": {
            "deletions": objects,
            "entities": {"type": "array", "items": entity}
        },
        "required": ["deletions", "entities"]
    });
    [
        ("transforms", "foxglove.FrameTransforms", transforms),
        ("joints", "microrobot.JointStates", joints),
        ("scene", "foxglove.SceneUpdate", scene),
    ]
}

/// The JSON Schema of an object whose `fields` are all required and of JSON type `ty`
/// (a time `{sec, nsec}`, a vector `{x, y, z}`, a quaternion `{x, y, z, w}`).
fn object_of(ty: &str, fields: &[&str]) -> Value {
    let properties: serde_json::Map<String, Value> = fields
        .iter()
        .map(|f| (f.to_string(), json!({ "type": ty })))
        .collect();
    json!({"type": "object", "properties": properties, "required": fields})
}

/// The topics of [`channels`].
pub const DERIVED_TOPICS: [&str; 3] = ["transforms", "joints", "scene"];

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

/// Periods of the derived channels, ns (0: from every message).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Periods {
    /// `transforms` (of the measured state and, apart, of the setpoint).
    pub transforms_ns: u64,
    /// `joints`.
    pub joints_ns: u64,
    /// `scene`.
    pub scene_ns: u64,
}

impl Periods {
    /// The same period for every channel.
    pub fn every(period_ns: u64) -> Self {
        Self {
            transforms_ns: period_ns,
            joints_ns: period_ns,
            scene_ns: period_ns,
        }
    }
}

/// How often a [`Feed`] looks for the run's config (the robot) until it has it.
const RETRY_NS: u64 = 1_000_000_000;

/// Derives the viewer channels from an instance's states and setpoints, each channel
/// decimated to its period (by the messages' stamps). The robot comes from the run's
/// resolved config, looked for at most once a second until found, so a tap started
/// before the pipeline gets its transforms once the pipeline is up.
pub struct Feed {
    instance: String,
    periods: Periods,
    viewer: Option<Viewer>,
    looked_ns: Option<u64>,
    /// Stamp of the last state transforms, setpoint transforms, joints, scene derived.
    last: [Option<u64>; 4],
}

impl Feed {
    /// A feed for `instance`'s run at `periods`.
    pub fn new(instance: &str, periods: Periods) -> Self {
        Self {
            instance: instance.to_string(),
            periods,
            viewer: None,
            looked_ns: None,
            last: [None; 4],
        }
    }

    /// The derived messages `payload` (stamped `stamp`, `CLOCK_MONOTONIC`; `wall` the
    /// same instant on `CLOCK_REALTIME`) is due for, as (index into [`DERIVED_TOPICS`],
    /// message); nothing until the run's robot is known.
    pub fn derive(
        &mut self,
        payload: &super::tap::Payload,
        stamp: u64,
        wall: u64,
    ) -> Vec<(usize, Value)> {
        use super::tap::Payload;
        let p = self.periods;
        let due =
            |last: Option<u64>, period: u64| last.is_none_or(|t| stamp.saturating_sub(t) >= period);
        let wanted = match payload {
            Payload::State(_) => [
                due(self.last[0], p.transforms_ns),
                false,
                due(self.last[2], p.joints_ns),
                due(self.last[3], p.scene_ns),
            ],
            Payload::Setpoint(_) => [false, due(self.last[1], p.transforms_ns), false, false],
            _ => return Vec::new(),
        };
        if !wanted.iter().any(|w| *w) {
            return Vec::new();
        }
        if self.viewer.is_none()
            && self
                .looked_ns
                .is_none_or(|t| stamp.saturating_sub(t) >= RETRY_NS)
        {
            self.looked_ns = Some(stamp);
            if let Some(text) = super::tap::run_config(&self.instance) {
                let text = String::from_utf8_lossy(&text).into_owned();
                match Viewer::from_config_text(&text, super::CONFIG_ATTACHMENT) {
                    Ok(v) => self.viewer = Some(v),
                    Err(e) => eprintln!("warning: no transforms: {e:#}"),
                }
            }
        }
        let Some(viewer) = self.viewer.as_mut() else {
            return Vec::new();
        };
        let mut out = Vec::new();
        for (k, _) in wanted.iter().enumerate().filter(|(_, w)| **w) {
            self.last[k] = Some(stamp);
            let msg = match (k, payload) {
                (0, Payload::State(m)) => viewer.state_transforms(m, wall).map(|v| (0, v)),
                (1, Payload::Setpoint(m)) => viewer.setpoint_transforms(m, wall).map(|v| (0, v)),
                (2, Payload::State(m)) => viewer.joints(m, wall).map(|v| (1, v)),
                (3, Payload::State(m)) => viewer.scene(m, wall).map(|v| (2, v)),
                _ => None,
            };
            out.extend(msg);
        }
        out
    }
}

impl Viewer {
    /// The robot named by a resolved pipeline config's text (`origin` names it in errors).
    pub fn from_config_text(text: &str, origin: &str) -> Result<Self> {
        let cfg = microrobot_config::from_toml_str(text, origin, std::path::Path::new("."))
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

    /// The `scene` message of a measured state: the arm as a line from the base through
    /// every joint origin to the tool, a sphere at each joint (sizes scale with the arm).
    pub fn scene(&mut self, m: &JointState, wall_ns: u64) -> Option<Value> {
        let q = self.q(&m.q, m.dof)?;
        forward_kinematics(&self.robot, &mut self.data, &q);
        let n = self.robot.dof();
        let mut points = vec![json!({"x": 0.0, "y": 0.0, "z": 0.0})];
        let mut reach: f64 = 0.0;
        for i in 1..=n {
            let p = self.data.frame(i).translation;
            reach = reach.max(p.norm());
            points.push(json!({"x": p.x, "y": p.y, "z": p.z}));
        }
        let tool = self.data.tool_frame().translation;
        reach = reach.max(tool.norm());
        points.push(json!({"x": tool.x, "y": tool.y, "z": tool.z}));
        let size = (reach * 0.04).clamp(0.005, 0.1);
        let identity = json!({
            "position": {"x": 0.0, "y": 0.0, "z": 0.0},
            "orientation": {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0}
        });
        let spheres: Vec<Value> = points[1..=n]
            .iter()
            .map(|p| {
                json!({
                    "pose": {"position": p, "orientation": {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0}},
                    "size": {"x": size, "y": size, "z": size},
                    "color": {"r": 0.9, "g": 0.5, "b": 0.1, "a": 1.0}
                })
            })
            .collect();
        Some(json!({
            "deletions": [],
            "entities": [{
                "timestamp": time(wall_ns),
                "frame_id": ROOT_FRAME,
                "id": "arm",
                "lifetime": {"sec": 0, "nsec": 0},
                "frame_locked": false,
                "metadata": [],
                "arrows": [], "cubes": [], "cylinders": [], "triangles": [], "texts": [],
                "models": [],
                "spheres": spheres,
                "lines": [{
                    "type": 0,
                    "pose": identity,
                    "thickness": size / 2.0,
                    "scale_invariant": false,
                    "points": points,
                    "color": {"r": 0.3, "g": 0.5, "b": 0.8, "a": 1.0},
                    "colors": [],
                    "indices": []
                }]
            }]
        }))
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
        let robot = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../../config/robots/seed-arm.toml");
        let text = format!("robot = \"{}\"\n", robot.display());
        Viewer::from_config_text(&text, "test").expect("viewer")
    }

    /// Each derived channel keeps its own period, by the messages' stamps; setpoints give
    /// their own transforms at the transforms' period; other streams give nothing.
    #[test]
    fn a_feed_decimates_each_channel_to_its_period() {
        use super::super::tap::Payload;
        let mut feed = Feed {
            instance: "unit".into(),
            periods: Periods {
                transforms_ns: 10_000_000,
                joints_ns: 5_000_000,
                scene_ns: 20_000_000,
            },
            viewer: Some(viewer()),
            looked_ns: None,
            last: [None; 4],
        };
        let mut counts = [0usize; 3];
        let mut setpoint_transforms = 0;
        for ms in 0..40u64 {
            let stamp = 1_000_000_000 + ms * 1_000_000;
            let state = JointState {
                dof: 6,
                ..Default::default()
            };
            for (i, _) in feed.derive(&Payload::State(state), stamp, stamp) {
                counts[i] += 1;
            }
            let setpoint = JointSetpoint {
                dof: 6,
                ..Default::default()
            };
            for (i, v) in feed.derive(&Payload::Setpoint(setpoint), stamp, stamp) {
                assert_eq!(i, 0);
                assert!(v.to_string().contains("cmd/tool"));
                setpoint_transforms += 1;
            }
            let status = Payload::Status(Box::default());
            assert!(feed.derive(&status, stamp, stamp).is_empty());
        }
        // 40 ms of 1 kHz states: transforms every 10 ms, joints every 5, scene every 20.
        assert_eq!(counts, [4, 8, 2]);
        assert_eq!(setpoint_transforms, 4);
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
