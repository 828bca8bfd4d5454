//! Workspace sampling against closed forms: the 2R planar arm with full joint
//! ranges sweeps an annulus (area), the spherical RRP arm a spherical shell
//! (volume); the voxel estimate grows monotonically with the samples and
//! approaches the closed form as the voxels shrink.
#![allow(clippy::needless_range_loop)] // index loops read like the matrix formulas

use microrobot_model::Robot;
use microrobot_model::workspace::{
    WorkspaceError, WorkspaceOptions, WorkspaceProgress, reachable_workspace,
};
use std::f64::consts::PI;
use std::sync::atomic::{AtomicUsize, Ordering};

fn robot(file: &str) -> Robot {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../config/robots")
        .join(file);
    Robot::from_file(&path).unwrap_or_else(|e| panic!("{e}"))
}

fn no_progress(_: WorkspaceProgress) {}

#[test]
fn planar_2r_sweeps_the_annulus() {
    let arm = robot("planar-2r.toml");
    let (l1, l2) = (0.3, 0.2);
    let exact = PI * ((l1 + l2) * (l1 + l2) - (l1 - l2) * (l1 - l2));
    let ws = reachable_workspace(
        &arm,
        &WorkspaceOptions {
            samples: 400_000,
            voxel_size_m: 0.005,
            ..Default::default()
        },
        &no_progress,
    )
    .unwrap_or_else(|e| panic!("{e}"));
    let rel = (ws.area_xy_m2 - exact) / exact;
    assert!(
        rel.abs() < 0.03,
        "area {} vs {exact} ({:.2}%)",
        ws.area_xy_m2,
        rel * 100.0
    );
    // Every point lies in the annulus and in the plane; the box is the disc's.
    for p in &ws.points {
        let r = (p.x * p.x + p.y * p.y).sqrt();
        assert!((l1 - l2 - 1e-12..=l1 + l2 + 1e-12).contains(&r) && p.z.abs() < 1e-12);
    }
    assert!((ws.bounds.max.x - 0.5).abs() < 2e-3 && (ws.bounds.min.y + 0.5).abs() < 2e-3);
}

#[test]
fn spherical_arm_sweeps_the_shell_and_converges() {
    let arm = robot("spherical-rrp.toml");
    let (r_in, r_out) = (0.12_f64, 0.32_f64);
    let exact = 4.0 / 3.0 * PI * (r_out.powi(3) - r_in.powi(3));
    let surface = 4.0 * PI * (r_out * r_out + r_in * r_in);
    let mut errors = Vec::new();
    for (h, samples) in [(0.04, 40_000), (0.02, 320_000)] {
        let ws = reachable_workspace(
            &arm,
            &WorkspaceOptions {
                samples,
                voxel_size_m: h,
                ..Default::default()
            },
            &no_progress,
        )
        .unwrap_or_else(|e| panic!("{e}"));
        let err = ws.volume_m3 - exact;
        // Outer voxel cover: never far below, at most the boundary layer above.
        assert!(
            err > -0.03 * exact && err < surface * h,
            "h = {h}: {} vs {exact}",
            ws.volume_m3
        );
        errors.push(err.abs());
        for p in &ws.points {
            let r = p.coords.norm();
            assert!(r > r_in - 1e-12 && r < r_out + 1e-12, "point at radius {r}");
        }
    }
    assert!(
        errors[1] < errors[0],
        "finer voxels must be closer: {errors:?}"
    );
    assert!(
        errors[1] / exact < 0.12,
        "relative error {}",
        errors[1] / exact
    );
}

#[test]
fn volume_grows_monotonically_with_samples() {
    let arm = robot("seed-arm.toml");
    let mut last = 0.0;
    let mut volumes = Vec::new();
    for samples in [5_000, 20_000, 80_000] {
        let ws = reachable_workspace(
            &arm,
            &WorkspaceOptions {
                samples,
                voxel_size_m: 0.01,
                ..Default::default()
            },
            &no_progress,
        )
        .unwrap_or_else(|e| panic!("{e}"));
        assert!(ws.volume_m3 >= last);
        assert_eq!(ws.samples, samples);
        last = ws.volume_m3;
        volumes.push(ws.volume_m3);
    }
    // Saturation: the relative increment shrinks.
    assert!((volumes[2] - volumes[1]) / volumes[1] < (volumes[1] - volumes[0]) / volumes[0]);
}

#[test]
fn result_is_independent_of_thread_count_and_progress_reaches_total() {
    let arm = robot("seed-arm.toml");
    let calls = AtomicUsize::new(0);
    let last = AtomicUsize::new(0);
    let progress = |p: WorkspaceProgress| {
        calls.fetch_add(1, Ordering::Relaxed);
        last.fetch_max(p.done, Ordering::Relaxed);
        assert_eq!(p.total, 30_000);
    };
    let opts = WorkspaceOptions {
        samples: 30_000,
        voxel_size_m: 0.005,
        max_points: 1000,
        ..Default::default()
    };
    let two = reachable_workspace(&arm, &WorkspaceOptions { threads: 2, ..opts }, &progress)
        .unwrap_or_else(|e| panic!("{e}"));
    let one = reachable_workspace(&arm, &WorkspaceOptions { threads: 1, ..opts }, &no_progress)
        .unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(one, two);
    assert!(two.points.len() <= 1000 && two.points.len() >= 900);
    assert!(calls.load(Ordering::Relaxed) >= 2);
    assert_eq!(last.load(Ordering::Relaxed), 30_000);
}

#[test]
fn bad_options_are_refused() {
    let arm = robot("planar-2r.toml");
    let bad = |o: WorkspaceOptions| reachable_workspace(&arm, &o, &no_progress);
    assert_eq!(
        bad(WorkspaceOptions {
            samples: 0,
            ..Default::default()
        }),
        Err(WorkspaceError::NoSamples)
    );
    assert!(matches!(
        bad(WorkspaceOptions {
            voxel_size_m: -1.0,
            ..Default::default()
        }),
        Err(WorkspaceError::BadVoxelSize(_))
    ));
    assert!(matches!(
        bad(WorkspaceOptions {
            voxel_size_m: f64::NAN,
            ..Default::default()
        }),
        Err(WorkspaceError::BadVoxelSize(_))
    ));
    assert!(matches!(
        bad(WorkspaceOptions {
            samples: 100,
            voxel_size_m: 1e-9,
            ..Default::default()
        }),
        Err(WorkspaceError::GridTooFine { .. })
    ));
}
