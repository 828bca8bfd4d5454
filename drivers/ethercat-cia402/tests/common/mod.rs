//! What the driver's integration tests share: the drive file they run on.

use microrobot_ethercat_cia402::drive_file::DriveFile;

/// The example drive file with its first `n` axes and `rated_j1` as joint 1's rated
/// torque. The drives' watchdog is 1 s (the example's 10 ms would expire whenever the
/// loaded test machine deschedules the test thread between two cycles).
pub fn drive_file(n: usize, rated_j1: f64) -> DriveFile {
    drive_file_with_watchdog(n, rated_j1, 1000)
}

pub fn drive_file_with_watchdog(n: usize, rated_j1: f64, watchdog_ms: u32) -> DriveFile {
    let text = include_str!("../../example.drive.toml").replace(
        "drive_watchdog_ms = 10",
        &format!("drive_watchdog_ms = {watchdog_ms}"),
    );
    let mut parts = text.split("\n[[axis]]\n");
    let mut out = parts.next().expect("bus table").to_string();
    for (i, p) in parts.take(n).enumerate() {
        out.push_str("\n[[axis]]\n");
        if i == 0 {
            out.push_str(&p.replace(
                "rated_torque_nm = 1.27",
                &format!("rated_torque_nm = {rated_j1}"),
            ));
        } else {
            out.push_str(p);
        }
    }
    DriveFile::from_toml_str(&out, "test.drive.toml").expect("drive file")
}
