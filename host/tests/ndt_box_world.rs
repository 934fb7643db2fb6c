//! Given / When / Then tests of NDT through its public API on ray-cast scans of the
//! simulator's box world ([`msreg_host::sim::BoxWorld`]): recovery of known transforms,
//! degeneracy, the local map, bad input and the sandwich covariances. (The derivative check
//! against central differences needs NDT's private score and stays in `ndt/tests.rs`.)

// A test crate: its helpers may panic on bad fixtures.
#![allow(clippy::unwrap_used)]

use msreg_host::ndt::{
    align, align_scans, InvalidParam, LocalMap, NdtError, NdtParams, NdtResult, NdtTarget,
};
use msreg_host::pointcloud::{voxel_downsample, PointCloud};
use msreg_host::sim::BoxWorld;
use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};

fn pose(t: [f64; 3], rpy_deg: [f64; 3]) -> Isometry3<f64> {
    let [r, p, y] = rpy_deg.map(f64::to_radians);
    Isometry3::from_parts(
        Translation3::new(t[0], t[1], t[2]),
        UnitQuaternion::from_euler_angles(r, p, y),
    )
}

fn indoor_scan(rings: usize, columns: usize) -> Vec<Vector3<f64>> {
    let sensor = pose([0.3, -0.4, 1.2], [0.0, 0.0, 10.0]);
    let raw = BoxWorld::indoor().scan(&sensor, rings, columns, 40.0, 0.0);
    voxel_downsample(&PointCloud::from_xyz(raw), 0.1).positions()
}

/// Scan to scan NDT (default parameters, from identity) of two 64 x 1024 scans of `world`
/// with `jitter_m` range jitter, each voxel-filtered at 0.2 m.
fn register_pair(
    world: &BoxWorld,
    t_w_target: &Isometry3<f64>,
    t_w_source: &Isometry3<f64>,
    jitter_m: f64,
) -> NdtResult {
    let cloud = |t: &Isometry3<f64>| {
        voxel_downsample(
            &PointCloud::from_xyz(world.scan(t, 64, 1024, 40.0, jitter_m)),
            0.2,
        )
    };
    align_scans(
        &cloud(t_w_target),
        &cloud(t_w_source),
        &Isometry3::identity(),
        &NdtParams::default(),
    )
    .unwrap()
}

/// Errors (m, deg) of `estimate` against `truth`.
fn errors(estimate: &Isometry3<f64>, truth: &Isometry3<f64>) -> (f64, f64) {
    let d = truth.inverse() * estimate;
    (d.translation.vector.norm(), d.rotation.angle().to_degrees())
}

#[test]
fn known_transform_is_recovered_on_a_structured_scene() {
    // Given a scan of the indoor box world and the same points seen from a
    // sensor moved by a known T_target_source
    let target_points = indoor_scan(64, 512);
    let truth = pose([0.42, -0.31, 0.08], [1.5, -2.0, 8.0]);
    let source: Vec<Vector3<f64>> = target_points
        .iter()
        .map(|p| (truth.inverse() * nalgebra::Point3::from(*p)).coords)
        .collect();
    let params = NdtParams::default();
    let target = NdtTarget::build(&target_points, &params).unwrap();
    // When registered from identity
    let result = align(&target, &source, &Isometry3::identity(), &params).unwrap();
    // Then the transform is recovered within 1 mm / 0.01 deg, converged and
    // not degenerate, with a small, positive-definite covariance
    let (dt, dr) = errors(&result.t_target_source, &truth);
    assert!(
        dt < 1e-3 && dr < 0.01,
        "error {dt} m {dr} deg after {} it",
        result.iterations
    );
    assert!(result.converged, "{result:?}");
    assert!(result.degenerate.is_none());
    assert!(
        result.fitness > 0.3 && result.fitness < 1.5,
        "fitness {}",
        result.fitness
    );
    let eig = result.covariance.symmetric_eigenvalues();
    assert!(eig.min() > 0.0 && eig.max().sqrt() < 0.01, "{eig}");
}

#[test]
fn independent_scans_register_within_a_centimetre() {
    // Given two ray-cast scans of the room from poses 0.5 m / 8 deg apart,
    // with 2 cm range jitter
    let world = BoxWorld::indoor();
    let t_w_target = pose([0.3, -0.4, 1.2], [0.0, 0.0, 10.0]);
    let t_w_source = pose([0.7, -0.1, 1.25], [1.0, -1.0, 18.0]);
    let truth = t_w_target.inverse() * t_w_source;
    // When registered scan to scan from identity
    let result = register_pair(&world, &t_w_target, &t_w_source, 0.02);
    // Then
    let (dt, dr) = errors(&result.t_target_source, &truth);
    assert!(dt < 0.01 && dr < 0.1, "error {dt} m {dr} deg");
    assert!(result.converged);
}

#[test]
fn corridor_is_reported_degenerate_not_converged() {
    // Given two scans in a corridor of two parallel walls and a floor
    let world = BoxWorld::corridor();
    let t_w_target = pose([0.0, 0.2, 1.0], [0.0, 0.0, 0.0]);
    let t_w_source = pose([0.5, 0.1, 1.0], [0.0, 0.0, 3.0]);
    // When registered
    let result = register_pair(&world, &t_w_target, &t_w_source, 0.0);
    // Then degeneracy is reported, along the corridor axis, and not converged
    let report = result
        .degenerate
        .as_ref()
        .expect("corridor must be degenerate");
    assert!(!result.converged);
    let along = report.weak_translation.expect("translation must be weak");
    assert!(along.x.abs() > 0.99, "{report:?}");
    assert!(report.translation_ratio < report.threshold);
}

#[test]
fn structured_scene_is_well_inside_the_degeneracy_threshold() {
    // Given a registration of the furnished room with every block reported
    let target_points = indoor_scan(64, 512);
    let params = NdtParams {
        degeneracy_ratio: f64::INFINITY,
        ..NdtParams::default()
    };
    let target = NdtTarget::build(&target_points, &params).unwrap();
    let result = align(&target, &target_points, &Isometry3::identity(), &params).unwrap();
    // Then both marginal ratios clear the default threshold with margin
    let report = result.degenerate.unwrap();
    let threshold = NdtParams::default().degeneracy_ratio;
    assert!(report.translation_ratio > 1.5 * threshold, "{report:?}");
    assert!(report.rotation_ratio > 1.5 * threshold, "{report:?}");
}

#[test]
fn local_map_tracks_a_moving_sensor() {
    // Given a sensor moving through the room, scans inserted at their true poses
    let world = BoxWorld::indoor();
    let params = NdtParams::default();
    let mut map = LocalMap::new(3, 0.2, params).unwrap();
    let mut previous = Isometry3::identity();
    for k in 0..6 {
        let f = f64::from(k);
        let t_w_s = pose([-2.0 + 0.4 * f, 0.1 * f, 1.2], [0.0, 0.0, 3.0 * f]);
        let scan = voxel_downsample(
            &PointCloud::from_xyz(world.scan(&t_w_s, 32, 1024, 40.0, 0.01)),
            0.2,
        );
        if !map.is_empty() {
            // When each new scan is matched to the map from the previous pose
            let result = map.align(&scan, &previous).unwrap();
            // Then its pose is found
            let (dt, dr) = errors(&result.t_target_source, &t_w_s);
            assert!(dt < 0.01 && dr < 0.1, "scan {k}: {dt} m {dr} deg");
            assert!(result.converged);
        }
        map.insert(&scan, &t_w_s);
        previous = t_w_s;
        assert_eq!(map.len(), (k + 1).min(3) as usize);
    }
}

#[test]
fn local_map_eviction_equals_a_fresh_build() {
    // Given a map of capacity 2 after three insertions
    let world = BoxWorld::indoor();
    let poses = [
        pose([0.0; 3], [0.0; 3]),
        pose([1.0, 0.0, 1.0], [0.0; 3]),
        pose([2.0, 0.5, 1.0], [0.0, 0.0, 20.0]),
    ];
    let scans: Vec<PointCloud> = poses
        .iter()
        .map(|t| PointCloud::from_xyz(world.scan(t, 16, 256, 40.0, 0.0)))
        .collect();
    let params = NdtParams::default();
    let mut rolling = LocalMap::new(2, 0.2, params.clone()).unwrap();
    let mut fresh = LocalMap::new(2, 0.2, params).unwrap();
    for (s, t) in scans.iter().zip(&poses) {
        rolling.insert(s, t);
    }
    for (s, t) in scans.iter().zip(&poses).skip(1) {
        fresh.insert(s, t);
    }
    // Then both hold the same Gaussians
    let a = rolling.target().unwrap().levels()[2].cells().len();
    let b = fresh.target().unwrap().levels()[2].cells().len();
    assert_eq!(a, b);
}

#[test]
fn bad_input_is_an_error_not_a_panic() {
    let params = NdtParams::default();
    let target = NdtTarget::build(&indoor_scan(16, 256), &params).unwrap();
    assert_eq!(
        align(&target, &[], &Isometry3::identity(), &params),
        Err(NdtError::EmptySource)
    );
    let far = vec![Vector3::new(1e4, 0.0, 0.0); 10];
    assert!(matches!(
        align(&target, &far, &Isometry3::identity(), &params),
        Err(NdtError::NoOverlap { .. })
    ));
    assert!(matches!(
        NdtTarget::build(&far[..2], &params),
        Err(NdtError::EmptyTarget { .. })
    ));
    let bad = NdtParams {
        resolutions: vec![],
        ..NdtParams::default()
    };
    assert!(matches!(
        NdtTarget::build(&far, &bad),
        Err(NdtError::InvalidParams(InvalidParam::Resolutions))
    ));
}

#[test]
fn sandwich_covariances_are_symmetric_positive_and_only_on_request() {
    // Given the furnished room registered to itself from a small offset
    let points = indoor_scan(32, 256);
    let mut params = NdtParams::default();
    let target = NdtTarget::build(&points, &params).unwrap();
    let guess = pose([0.05, -0.03, 0.02], [0.01, 0.0, -0.01]);
    // When the sandwich is not asked for, it is absent
    let plain = align(&target, &points, &guess, &params).unwrap();
    assert!(plain.covariance_sandwich.is_none() && plain.covariance_clustered.is_none());
    // When asked for, both are symmetric, positive definite and the same pose comes out
    params.sandwich_covariance = true;
    let r = align(&target, &points, &guess, &params).unwrap();
    assert_eq!(r.t_target_source, plain.t_target_source);
    for c in [
        r.covariance_sandwich.unwrap(),
        r.covariance_clustered.unwrap(),
    ] {
        assert!((c - c.transpose()).amax() <= 1e-12 * c.amax());
        let eig = nalgebra::SymmetricEigen::new(c).eigenvalues;
        assert!(eig.min() > 0.0, "{eig}");
        // Its size is set by the residuals: far below the prior's scale (1 m, 1 rad).
        assert!(c.diagonal().max() < 1e-4, "{}", c.diagonal());
    }
}
