//! `msreg simulate prior-map`'s simulator: the layout of docs/formats.md "Camera in a prior
//! map" reads back through the registration's reader; the ground truth, the survey
//! points, the prior and the three renderings are mutually consistent.

use msreg_host::dataset::read_t_world_cam;
use msreg_host::mi::prior_map::input::read_input;
use msreg_host::mi::prior_map::survey_errors;
use msreg_host::sim::prior_map::{simulate_prior_map, FisheyeModel, PriorMapSimConfig};
use nalgebra::Vector2;

#[test]
fn the_dataset_reads_back_and_is_consistent() {
    for (seed, model) in [(21, FisheyeModel::Equidistant), (22, FisheyeModel::Omni)] {
        let config = PriorMapSimConfig {
            model,
            prior_offset_m: Some(3.0),
            ..PriorMapSimConfig::small(seed)
        };
        let sim = simulate_prior_map(&config);
        let dir = tempfile::tempdir().expect("tempdir");
        sim.write(dir.path()).expect("written");
        let input = read_input(dir.path()).expect("reads back");
        let truth = read_t_world_cam(&dir.path().join("groundtruth/extrinsics.yaml"))
            .expect("ground truth");
        assert!((truth.translation.vector - sim.t_world_cam.translation.vector).norm() < 1e-9);
        assert!(truth.rotation.angle_to(&sim.t_world_cam.rotation) < 1e-9);
        // Camera 6-10 m up, looking down within a few degrees.
        let p = truth.translation.vector;
        assert!((6.0..=10.0).contains(&p.z), "height {}", p.z);
        let axis = truth.rotation * nalgebra::Vector3::z();
        assert!(axis.z < -0.99, "optical axis {axis:?}");
        // The prior: 3 m off horizontally, within 0.5 m vertically.
        let prior = nalgebra::Vector3::from(input.prior.position.expect("position"));
        assert!(((prior - p).xy().norm() - 3.0).abs() < 1e-9);
        assert!((prior.z - p.z).abs() <= 0.5);
        assert!(input.prior.correspondences.is_empty());
        // Survey pixels are the true projections (to the CSV's printed precision).
        assert!(
            input.survey.len() >= 8,
            "{} survey points",
            input.survey.len()
        );
        let errors = survey_errors(&input.camera, &truth, &input.survey);
        assert!(errors.iter().all(|e| *e < 1e-6), "{errors:?}");
        assert_eq!(input.map.len(), config.map_points);
        assert_eq!(input.camera.resolution, (400, 400));
        assert_eq!(
            *input.camera.projection() == msreg_estimator::camera::Projection::Pinhole,
            model == FisheyeModel::Equidistant
        );
        // The satellite geometry: the pixel of a point maps back to it.
        let sat = input.satellite.as_ref().expect("satellite");
        let w = Vector2::new(1.25, -3.5);
        assert!((sat.world_of(&sat.pixel_of(&w)) - w).norm() < 1e-9);
        assert_eq!(
            sat.image.width(),
            (40.0 / config.satellite_m_per_px) as usize
        );
    }
}

#[test]
fn markings_are_bright_in_all_three_renderings() {
    // A zebra bar of the east arm (x 8-10 m, y within 0.25 m of 0) against the asphalt gap
    // beside it (y 0.5 m): brighter in the LiDAR reflectivity, the satellite and the fisheye,
    // each with its own tone curve (means along 2 m strips).
    let sim = simulate_prior_map(&PriorMapSimConfig::small(23));
    let strip = |y: f64| (0..21).map(move |k| Vector2::new(8.0 + 0.1 * k as f64, y));
    let lidar = |y: f64| {
        let near: Vec<f32> = sim
            .map
            .points
            .iter()
            .filter(|p| (8.0..10.0).contains(&p.xyz.x) && (p.xyz.y - y).abs() < 0.15)
            .map(|p| p.intensity)
            .collect();
        assert!(near.len() >= 5, "{} points", near.len());
        near.iter().sum::<f32>() / near.len() as f32
    };
    assert!(
        lidar(0.0) > lidar(0.5) + 80.0,
        "{} vs {}",
        lidar(0.0),
        lidar(0.5)
    );
    let m = sim.config.satellite_m_per_px;
    let sat = |y: f64| {
        strip(y)
            .map(|w| {
                sim.satellite.sample(
                    (w.x - sim.satellite_top_left.x) / m,
                    (sim.satellite_top_left.y - w.y) / m,
                )
            })
            .sum::<f32>()
            / 21.0
    };
    // A shadow over the bar only would leave it 1.43 x brighter than unshadowed asphalt.
    assert!(sat(0.0) > 1.3 * sat(0.5), "{} vs {}", sat(0.0), sat(0.5));
    let t_cam_world = sim.t_world_cam.inverse();
    let image = |y: f64| {
        strip(y)
            .map(|w| {
                let pc = t_cam_world * nalgebra::Point3::new(w.x, w.y, 0.0);
                let q = sim.camera.project(&pc.coords).expect("projects").pixel;
                sim.image.sample(q.x, q.y)
            })
            .sum::<f32>()
            / 21.0
    };
    assert!(
        image(0.0) > image(0.5) + 60.0,
        "{} vs {}",
        image(0.0),
        image(0.5)
    );
}
