use super::*;
use msreg_estimator::camera::{
    equidistant::Equidistant, radtan::RadTan, Camera, Distortion, Intrinsics, Projection,
};

const K_RADTAN: [f64; 4] = [-0.3, 0.1, 0.001, -0.002];

fn camera(lens: Lens) -> SimCamera {
    SimCamera {
        lens,
        fu: 400.0,
        fv: 410.0,
        cu: 320.0,
        cv: 240.0,
        resolution: [640, 480],
    }
}

fn all_models() -> [SimCamera; 5] {
    [
        camera(Lens::PinholeRadtan { k: K_RADTAN }),
        camera(Lens::PinholeEquidistant {
            k: [0.1, -0.02, 0.003, -0.0004],
        }),
        camera(Lens::OmniRadtan {
            xi: 0.9,
            k: K_RADTAN,
        }),
        camera(Lens::DoubleSphere {
            xi: -0.2,
            alpha: 0.6,
        }),
        camera(Lens::Eucm {
            alpha: 0.6,
            beta: 1.1,
        }),
    ]
}

/// Values worked out by hand from the published formulas (module docs), in double
/// precision outside this code.
#[test]
fn projections_match_hand_computed_values() {
    let cases = [
        (Vector3::new(0.1, -0.2, 1.0), [359.338, 159.2956]),
        (
            Vector3::new(0.3, 0.4, 0.5),
            [518.810_257_009_592_4, 511.707_351_246_443],
        ),
        (
            Vector3::new(0.5, -0.25, 0.2),
            [552.758_717_449_317_4, 120.711_157_307_224_85],
        ),
        (
            Vector3::new(1.0, 0.5, -0.1),
            [1_023.353_206_554_627_8, 600.468_518_359_246_8],
        ),
        (
            Vector3::new(1.0, 0.5, -0.1),
            [920.495_885_518_220_7, 547.754_141_328_088],
        ),
    ];
    for (cam, (p, expected)) in all_models().iter().zip(cases) {
        let px = cam.project(&p).expect("valid point");
        let err = (px - Vector2::from(expected)).norm();
        assert!(err < 1e-9, "{:?}: {px} vs {expected:?}", cam.kind());
        // Scale invariance: every model projects rays, not points.
        let far = cam.project(&(p * 7.5)).expect("valid point");
        assert!((far - px).norm() < 1e-9, "{:?}", cam.kind());
    }
}

#[test]
fn the_principal_point_is_the_image_of_the_optical_axis() {
    for cam in all_models() {
        let px = cam.project(&Vector3::z()).expect("axis");
        assert!(
            (px - Vector2::new(320.0, 240.0)).norm() < 1e-12,
            "{:?}",
            cam.kind()
        );
    }
}

#[test]
fn points_outside_each_valid_set_are_refused() {
    let [pinhole, equi, omni, ds, eucm] = all_models();
    let behind = Vector3::new(0.0, 0.1, -1.0);
    assert!(pinhole.project(&Vector3::new(1.0, 0.0, 0.0)).is_none());
    assert!(pinhole.project(&behind).is_none());
    // Radtan with k1 = -0.3 alone folds back past r^2 = 1 / 0.9: a ray at 60 deg (r^2 = 3)
    // is refused, one at 40 deg (r^2 = 0.70) is not.
    let folding = camera(Lens::PinholeRadtan {
        k: [-0.3, 0.0, 0.0, 0.0],
    });
    assert!(folding
        .project(&Vector3::new(3f64.sqrt(), 0.0, 1.0))
        .is_none());
    assert!(folding.project(&Vector3::new(0.84, 0.0, 1.0)).is_some());
    assert!(equi.project(&Vector3::new(1.0, 0.0, 0.0)).is_some());
    // omni xi 0.9: valid while z_s > -0.9.
    assert!(omni.project(&Vector3::new(0.3, 0.0, -1.0)).is_none());
    assert!(omni.project(&Vector3::new(1.0, 0.0, -0.3)).is_some());
    for cam in [ds, eucm] {
        assert!(cam.project(&behind).is_none(), "{:?}", cam.kind());
    }
}

#[test]
fn unprojection_inverts_projection_over_each_field_of_view() {
    for cam in all_models() {
        let limit = cam.max_angle();
        let mut worst: f64 = 0.0;
        let mut count = 0;
        for i in 0..40 {
            for j in 0..24 {
                let t = limit * (0.98 * f64::from(i) / 39.0);
                let phi = f64::from(j) * std::f64::consts::TAU / 24.0;
                let ray = Vector3::new(t.sin() * phi.cos(), t.sin() * phi.sin(), t.cos());
                // Pixels the renderer could ask for: within 10^4 px of the centre (a pinhole's
                // radtan polynomial sends rays near 90 deg to 10^10 px and beyond).
                let Some(px) = cam.project(&ray).filter(|p| p.norm() < 1e4) else {
                    continue;
                };
                let back = cam.unproject_within(&px, limit).unwrap_or_else(|| {
                    panic!(
                        "{:?}: ray at {} deg not unprojected",
                        cam.kind(),
                        t.to_degrees()
                    )
                });
                worst = worst.max((back - ray).norm());
                count += 1;
            }
        }
        println!(
            "{:?}: max angle {:.1} deg, {count} rays, worst |ray error| {worst:.1e}",
            cam.kind(),
            limit.to_degrees()
        );
        assert!(count >= 40 * 24 / 2, "{:?}: {count}", cam.kind());
        assert!(worst < 1e-8, "{:?}: {worst}", cam.kind());
    }
}

#[test]
fn pixels_no_ray_reaches_are_not_unprojected() {
    let cam = camera(Lens::PinholeRadtan {
        k: [-0.3, 0.0, 0.0, 0.0],
    });
    // The radial map r (1 - 0.3 r^2) peaks at r = 1.054 (m = 0.703): beyond it, nothing.
    assert!(cam
        .unproject(&Vector2::new(320.0 + 400.0 * 3.0, 240.0))
        .is_none());
    assert!(cam.unproject(&Vector2::new(320.0, 240.0)).is_some());
}

/// A cross-check of two independent implementations: the estimator's camera code for the
/// three models it has agrees with the simulator's.
#[test]
fn pinhole_and_omni_agree_with_the_estimators_independent_code() {
    let intrinsics = Intrinsics {
        fu: 400.0,
        fv: 410.0,
        cu: 320.0,
        cv: 240.0,
    };
    let [k1, k2, p1, p2] = K_RADTAN;
    let radtan = Distortion::RadTan(RadTan {
        k1,
        k2,
        p1,
        p2,
        k3: 0.0,
    });
    let [e1, e2, e3, e4] = [0.1, -0.02, 0.003, -0.0004];
    let equi = Distortion::Equidistant(Equidistant {
        k1: e1,
        k2: e2,
        k3: e3,
        k4: e4,
    });
    let models = all_models();
    let pairs = [
        (models[0], Projection::Pinhole, radtan),
        (models[1], Projection::Pinhole, equi),
        (models[2], Projection::Omni { xi: 0.9 }, radtan),
    ];
    for (sim, projection, distortion) in pairs {
        let est = Camera::new(projection, intrinsics, distortion, (640, 480)).expect("valid");
        for p in [
            Vector3::new(0.1, -0.2, 1.0),
            Vector3::new(-0.3, 0.25, 0.8),
            Vector3::new(0.05, 0.02, 2.0),
        ] {
            let a = sim.project(&p).expect("sim");
            let b = est.project(&p).expect("estimator").pixel;
            assert!((a - b).norm() < 1e-9, "{:?}: {a} vs {b}", sim.kind());
        }
    }
}
