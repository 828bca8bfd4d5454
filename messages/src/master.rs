//! The master console's input: the pose of the surgeon's hand (a haptic device's
//! stylus) and its buttons, published at the device's rate (typically 500 Hz–1 kHz) by
//! a device driver or `microrobot teleop-source`, read by the planner in teleop mode.

use iceoryx2::prelude::ZeroCopySend;

/// One sample of the master device. Position and orientation are in the device's own
/// frame; the planner maps them into the robot's base frame (`[teleop] frame_rpy_deg`)
/// and scales the position (`[teleop] ratio`). The planner refuses a sample whose
/// numbers are not finite or whose quaternion is not unit length (±1e-3).
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[type_name("microrobot::v2::MasterPose")]
pub struct MasterPose {
    /// Device sequence number, +1 per sample; a gap is a lost sample.
    pub seq: u64,
    /// `CLOCK_MONOTONIC` ns when this sample was published (the planner's staleness
    /// check and the master → setpoint latency use it).
    pub stamp_ns: u64,
    /// The device's own timestamp of the measurement (its clock, ns); carried, not
    /// interpreted by the planner.
    pub device_stamp_ns: u64,
    /// Stylus tip position in the device frame, m.
    pub position: [f64; 3],
    /// Stylus orientation in the device frame, unit quaternion w, x, y, z.
    pub orientation: [f64; 4],
    /// Grip (tool DOF) opening, 0 = closed … 1 = fully open.
    pub grip: f64,
    /// 1 = clutch engaged (the hand drives the arm), 0 = released (the arm holds).
    pub clutch: u32,
    /// Padding, always 0 (keeps the layout identical in every language).
    pub reserved: u32,
}

impl MasterPose {
    /// Whether every number is finite, the quaternion unit length within `1e-3` and
    /// the clutch 0 or 1: what the planner requires before it uses a sample.
    pub fn is_valid(&self) -> bool {
        let finite = self
            .position
            .iter()
            .chain(self.orientation.iter())
            .all(|v| v.is_finite())
            && self.grip.is_finite();
        let n2: f64 = self.orientation.iter().map(|v| v * v).sum();
        finite && (n2.sqrt() - 1.0).abs() <= 1e-3 && self.clutch <= 1
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::mem::{align_of, offset_of, size_of};

    /// The offsets a Python (ctypes) or C++ publisher must reproduce; see messages/README.md.
    #[test]
    fn layout_is_pinned() {
        assert_eq!(offset_of!(MasterPose, seq), 0);
        assert_eq!(offset_of!(MasterPose, stamp_ns), 8);
        assert_eq!(offset_of!(MasterPose, device_stamp_ns), 16);
        assert_eq!(offset_of!(MasterPose, position), 24);
        assert_eq!(offset_of!(MasterPose, orientation), 48);
        assert_eq!(offset_of!(MasterPose, grip), 80);
        assert_eq!(offset_of!(MasterPose, clutch), 88);
        assert_eq!(offset_of!(MasterPose, reserved), 92);
        assert_eq!(size_of::<MasterPose>(), 96);
        assert_eq!(align_of::<MasterPose>(), 8);
    }

    #[test]
    fn validity_refuses_nan_non_unit_quaternions_and_bad_clutch() {
        let good = MasterPose {
            orientation: [1.0, 0.0, 0.0, 0.0],
            clutch: 1,
            ..Default::default()
        };
        assert!(good.is_valid());
        let mut nan = good;
        nan.position[1] = f64::NAN;
        assert!(!nan.is_valid());
        let mut inf = good;
        inf.grip = f64::INFINITY;
        assert!(!inf.is_valid());
        let mut long = good;
        long.orientation = [1.01, 0.0, 0.0, 0.0];
        assert!(!long.is_valid());
        let mut clutch = good;
        clutch.clutch = 2;
        assert!(!clutch.is_valid());
    }
}
