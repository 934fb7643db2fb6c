use super::*;

const MODELS: [ModelKind; 5] = [
    ModelKind::PinholeRadtan,
    ModelKind::PinholeEquidistant,
    ModelKind::OmniRadtan,
    ModelKind::DoubleSphere,
    ModelKind::Eucm,
];

fn config(model: ModelKind, cameras: usize, seed: u64) -> CamerasSimConfig {
    CamerasSimConfig {
        seed,
        cameras,
        model,
        ..CamerasSimConfig::default()
    }
}

#[test]
fn the_rig_is_a_row_of_cameras_within_the_baselines() -> Result<(), SimError> {
    for seed in 0..5 {
        let sim = simulate_cameras(&config(ModelKind::PinholeRadtan, 4, seed))?;
        for n in 1..4 {
            let t = sim.t_cn_cnm1(n);
            // Centre of camN in cam(N-1): to the right by the baseline.
            let centre = t.inverse().translation.vector;
            assert!((0.05..=0.15).contains(&centre.x), "{centre}");
            assert!(
                centre.y.abs() <= 0.005 && centre.z.abs() <= 0.005,
                "{centre}"
            );
            assert!(t.rotation.angle() < 8f64.to_radians());
            let chained = sim.t_cn_cnm1(n) * sim.t_cn_c0[n - 1];
            assert!((chained.to_homogeneous() - sim.t_cn_c0[n].to_homogeneous()).amax() < 1e-12);
        }
    }
    Ok(())
}

#[test]
fn every_camera_has_its_own_lens_near_the_nominal_one() -> Result<(), SimError> {
    for model in MODELS {
        let sim = simulate_cameras(&config(model, 3, 7))?;
        let nominal = nominal_camera(model);
        for c in &sim.cameras {
            assert_eq!(c.kind(), model);
            assert!((c.fu / nominal.fu - 1.0).abs() <= 0.031);
            assert!((c.cu - nominal.cu).abs() <= 8.0 && (c.cv - nominal.cv).abs() <= 8.0);
        }
        assert!(sim.cameras[0] != sim.cameras[1]);
    }
    Ok(())
}

/// The target's corners reach every ninth of each camera's image (3 x 3 cells), the four
/// corner cells included, and a good part of the frames hold the whole target.
#[test]
fn the_sweep_covers_the_whole_image_with_every_model() -> Result<(), SimError> {
    for model in MODELS {
        let sim = simulate_cameras(&config(model, 2, 3))?;
        let [w, h] = sim.cameras[0].resolution.map(f64::from);
        for n in 0..2 {
            let mut cells = [0usize; 9];
            let mut whole = 0;
            for k in 0..sim.config.frames {
                let corners = sim.true_corners(n, k);
                let inside: Vec<Vector2<f64>> = corners
                    .iter()
                    .flatten()
                    .filter(|p| sim.cameras[n].in_image(p))
                    .copied()
                    .collect();
                whole += usize::from(inside.len() == corners.len());
                for p in inside {
                    let (i, j) = ((3.0 * p.x / w) as usize, (3.0 * p.y / h) as usize);
                    cells[3 * j.min(2) + i.min(2)] += 1;
                }
            }
            println!("{model:?} cam{n}: corners per cell {cells:?}, {whole}/100 whole targets");
            assert!(
                cells.iter().all(|&c| c >= 100),
                "{model:?} cam{n}: {cells:?}"
            );
            assert!(whole >= 35, "{model:?} cam{n}: {whole}");
        }
    }
    Ok(())
}

/// A hand's pace and no jumps: over the default 10 s, poses 1 ms apart differ by under
/// 1.5 mm and 0.15 deg (1.5 m/s, 2.6 rad/s), and the step changes smoothly (its change
/// between neighbouring milliseconds under 1 % of the bound).
#[test]
fn the_motion_is_smooth_and_hand_paced() -> Result<(), SimError> {
    for model in MODELS {
        let sim = simulate_cameras(&config(model, 1, 2))?;
        let step = |t: f64| {
            let d = sim.t_cam_target(0, t).inverse() * sim.t_cam_target(0, t + 1e-3);
            (d.translation.vector.norm(), d.rotation.angle())
        };
        let (mut top, mut jerk) = ((0.0f64, 0.0f64), (0.0f64, 0.0f64));
        for i in 0..10_000 {
            let t = f64::from(i) * 1e-3;
            let (a, b) = (step(t), step(t + 1e-3));
            top = (top.0.max(a.0), top.1.max(a.1));
            jerk = (jerk.0.max((a.0 - b.0).abs()), jerk.1.max((a.1 - b.1).abs()));
        }
        println!(
            "{model:?}: peak {:.2} m/s, {:.2} rad/s",
            top.0 * 1e3,
            top.1 * 1e3
        );
        assert!(
            top.0 < 1.5e-3 && top.1 < 0.15f64.to_radians(),
            "{model:?}: {top:?}"
        );
        assert!(
            jerk.0 < 1.5e-5 && jerk.1 < 1.5e-3f64.to_radians(),
            "{model:?}: {jerk:?}"
        );
    }
    Ok(())
}

#[test]
fn unsynced_cameras_have_their_own_stamps() -> Result<(), SimError> {
    let mut c = config(ModelKind::PinholeRadtan, 3, 1);
    c.unsynced_s = 0.004;
    let sim = simulate_cameras(&c)?;
    assert_eq!(sim.stamp_ns(2, 5) - sim.stamp_ns(0, 5), 8_000_000);
    assert_eq!(sim.stamp_ns(0, 1) - sim.stamp_ns(0, 0), 100_000_000);
    c.unsynced_s = 0.04;
    assert!(simulate_cameras(&c).is_err());
    Ok(())
}

#[test]
fn bad_options_are_refused() {
    let base = CamerasSimConfig::default();
    for bad in [
        CamerasSimConfig {
            cameras: 0,
            ..base.clone()
        },
        CamerasSimConfig {
            frames: 2,
            ..base.clone()
        },
        CamerasSimConfig {
            rate_hz: f64::NAN,
            ..base.clone()
        },
        CamerasSimConfig {
            baseline_m: [0.2, 0.1],
            ..base.clone()
        },
        CamerasSimConfig {
            exposure_s: Some(0.2),
            ..base.clone()
        },
    ] {
        assert!(matches!(
            simulate_cameras(&bad),
            Err(SimError::InvalidOption { .. })
        ));
    }
}

#[test]
fn the_groundtruth_file_carries_kalibr_keys_per_camera() -> Result<(), SimError> {
    let sim = simulate_cameras(&config(ModelKind::DoubleSphere, 2, 4))?;
    let yaml: serde_yaml::Value =
        serde_yaml::from_str(&sim.groundtruth_yaml()).expect("valid YAML");
    let cam1 = &yaml["cam1"];
    assert_eq!(cam1["camera_model"].as_str(), Some("ds"));
    assert_eq!(cam1["distortion_model"].as_str(), Some("none"));
    let intrinsics: Vec<f64> = serde_yaml::from_value(cam1["intrinsics"].clone()).expect("list");
    assert_eq!(intrinsics, sim.cameras[1].kalibr_intrinsics());
    let t: Vec<Vec<f64>> = serde_yaml::from_value(cam1["T_cn_cnm1"].clone()).expect("matrix");
    let m = sim.t_cn_cnm1(1).to_homogeneous();
    for (r, row) in t.iter().enumerate() {
        for (c, v) in row.iter().enumerate() {
            assert_eq!(v.to_bits(), m[(r, c)].to_bits());
        }
    }
    assert!(yaml["cam0"].get("T_cn_cnm1").is_none());
    let camera_yaml = sim.camera_yaml(1);
    assert!(camera_yaml.contains("camera_model: ds") && !camera_yaml.contains("intrinsics"));
    Ok(())
}
