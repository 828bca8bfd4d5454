//! Motion scaling: the hand's displacement since the clutch engaged, rotated from the
//! master device's frame into the robot's base frame and divided by the ratio
//! (3:1 → a 3 mm hand motion moves the tool 1 mm).

use nalgebra::{Rotation3, Vector3};

/// Hand → tool displacement map.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MotionScaling {
    /// Hand displacement / tool displacement (≥ 1 scales down).
    ratio: f64,
    /// Orientation of the master device's frame in the robot's base frame.
    frame: Rotation3<f64>,
}

impl MotionScaling {
    /// `ratio` > 0 (finite); `frame` maps device-frame vectors into the base frame.
    pub fn new(ratio: f64, frame: Rotation3<f64>) -> Option<Self> {
        (ratio > 0.0 && ratio.is_finite()).then_some(Self { ratio, frame })
    }

    /// The frame from roll, pitch, yaw (rad, fixed axes x, y, z).
    pub fn frame_from_rpy(roll: f64, pitch: f64, yaw: f64) -> Rotation3<f64> {
        Rotation3::from_euler_angles(roll, pitch, yaw)
    }

    /// The scaling ratio.
    pub fn ratio(&self) -> f64 {
        self.ratio
    }

    /// Tool displacement in the base frame for a hand displacement in the device frame.
    #[inline]
    pub fn tool_displacement(&self, hand_displacement: &Vector3<f64>) -> Vector3<f64> {
        self.frame * hand_displacement / self.ratio
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn scales_and_rotates() {
        let s = MotionScaling::new(
            5.0,
            MotionScaling::frame_from_rpy(0.0, 0.0, std::f64::consts::FRAC_PI_2),
        )
        .expect("valid");
        let d = s.tool_displacement(&Vector3::new(0.01, 0.0, 0.005));
        // Device x is base y after a 90° yaw; z unchanged; all divided by 5.
        assert!((d - Vector3::new(0.0, 0.002, 0.001)).norm() < 1e-15, "{d}");
        assert!(MotionScaling::new(0.0, Rotation3::identity()).is_none());
        assert!(MotionScaling::new(f64::NAN, Rotation3::identity()).is_none());
    }
}
