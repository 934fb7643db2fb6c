//! Given / When / Then tests of NDT's private derivatives against central differences, on
//! a small local fixture of surface points. The tests through the public API on ray-cast
//! scenes of the simulator's box world (recovery of known transforms, degeneracy, local
//! map, bad input, covariances) are `host/tests/ndt_box_world.rs`: `sim` sits above `ndt`.

use nalgebra::{Isometry3, Matrix6, Translation3, UnitQuaternion, Vector3, Vector6};

use super::score::PoseMat;
use super::solver::{apply, score_derivatives};
use super::*;

fn pose(t: [f64; 3], rpy_deg: [f64; 3]) -> Isometry3<f64> {
    let [r, p, y] = rpy_deg.map(f64::to_radians);
    Isometry3::from_parts(
        Translation3::new(t[0], t[1], t[2]),
        UnitQuaternion::from_euler_angles(r, p, y),
    )
}

/// Points every 0.1 m on a floor, two walls and the top and side of a block: structure
/// along every axis, many 1 m cells.
fn surface_points() -> Vec<Vector3<f64>> {
    let steps = |from: f64, to: f64| {
        let n = ((to - from) / 0.1).round() as usize;
        (0..=n).map(move |i| from + 0.1 * i as f64)
    };
    let mut points = Vec::new();
    for x in steps(-4.0, 4.0) {
        for y in steps(-3.0, 3.0) {
            points.push(Vector3::new(x, y, 0.0));
        }
        for z in steps(0.0, 3.0) {
            points.push(Vector3::new(x, 3.2, z));
        }
    }
    for y in steps(-3.0, 3.0) {
        for z in steps(0.0, 3.0) {
            points.push(Vector3::new(4.3, y, z));
        }
    }
    for x in steps(0.6, 1.8) {
        for y in steps(-1.5, -0.7) {
            points.push(Vector3::new(x, y, 0.9));
        }
    }
    for y in steps(-1.5, -0.7) {
        for z in steps(0.0, 0.9) {
            points.push(Vector3::new(0.6, y, z));
        }
    }
    points
}

fn to_pose_mat(t: &Isometry3<f64>) -> PoseMat {
    PoseMat {
        rotation: t.rotation.to_rotation_matrix().into_inner(),
        translation: t.translation.vector,
    }
}

fn to_iso(p: &PoseMat) -> Isometry3<f64> {
    Isometry3::from_parts(
        Translation3::from(p.translation),
        UnitQuaternion::from_matrix(&p.rotation),
    )
}

#[test]
fn gradient_and_hessian_match_central_differences() {
    // Given a target map and source points moved off the optimum, keeping only
    // points at least 5 mm from any voxel face so the finite differences
    // never change a point's neighbourhood.
    let params = NdtParams {
        resolutions: vec![1.0],
        ..NdtParams::default()
    };
    let target_points = surface_points();
    let target = NdtTarget::build(&target_points, &params).unwrap();
    let map = &target.levels()[0];
    let base = pose([0.05, -0.03, 0.02], [0.5, -0.3, 1.0]);
    let source: Vec<Vector3<f64>> = target_points
        .iter()
        .copied()
        .filter(|p| {
            let x = base * nalgebra::Point3::from(*p);
            p.norm() < 8.0
                && x.coords
                    .iter()
                    .all(|c| (c - c.floor()).min(c.ceil() - c) > 5e-3)
        })
        .step_by(3)
        .collect();
    assert!(source.len() > 200, "{}", source.len());
    let f = |x: &Vector6<f64>| {
        let moved = to_iso(&apply(&to_pose_mat(&base), x));
        score_derivatives(map, &source, &moved, &params).0
    };
    // When the analytic derivatives are evaluated
    let (_, gradient, hessian) = score_derivatives(map, &source, &base, &params);
    // Then they match central differences of the score
    let h = 1e-6;
    let e = |i: usize| Vector6::from_fn(|k, _| if k == i { 1.0 } else { 0.0 });
    let numeric_g = Vector6::from_fn(|i, _| (f(&(h * e(i))) - f(&(-h * e(i)))) / (2.0 * h));
    let g_err = (numeric_g - gradient).norm() / gradient.norm();
    assert!(
        g_err < 1e-6,
        "gradient rel. error {g_err}\n{gradient}\n{numeric_g}"
    );
    let h2 = 5e-5;
    let numeric_h = Matrix6::from_fn(|i, j| {
        let (a, b) = (h2 * e(i), h2 * e(j));
        (f(&(a + b)) - f(&(a - b)) - f(&(b - a)) + f(&(-a - b))) / (4.0 * h2 * h2)
    });
    let h_err = (numeric_h - hessian).norm() / hessian.norm();
    assert!(
        h_err < 1e-4,
        "Hessian rel. error {h_err}\n{hessian}\n{numeric_h}"
    );
}
