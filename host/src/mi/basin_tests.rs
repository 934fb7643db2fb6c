//! Unit tests of the wider-basin search: the multi-candidate lattice, the parabola fit, the
//! flatness probe, the refinement holding DoFs, and the whole search on the simulated
//! ground problem ([`super::synthetic`]).

use nalgebra::Vector6;

use super::basin::{basin_search, parabola, probe, BasinOptions, ProbeSpec};
use super::scene::{MiScene, PoseParam};
use super::search::{
    grid_search_multi, refine, Constraint, GridAxis, Observability, RefineOptions,
};
use super::synthetic::synthetic_ground;
use crate::vision::GrayImage;

#[test]
fn multi_candidate_lattice_keeps_a_narrow_global_maximum_a_single_path_would_lose() {
    // A broad secondary maximum (height 1) at (-1.2, 0) and a narrow global one (1.2) at
    // (1.3, 0.4): the first level (spacing 1) scores the broad one higher.
    let f = |p: &[f64]| {
        let d2 = |a: f64, b: f64| (p[0] - a).powi(2) + (p[1] - b).powi(2);
        (-d2(-1.2, 0.0) / 2.0).exp() + 1.2 * (-d2(1.3, 0.4) / 0.08).exp()
    };
    let axes = [GridAxis {
        half_range: 2.0,
        steps: 2,
    }; 2];
    let first = grid_search_multi(&axes, 1, 1, |_, p| f(p));
    assert!((first.best[0].params[0] + 1.0).abs() < 1e-12, "{first:?}");
    let multi = grid_search_multi(&axes, 6, 3, |_, p| f(p));
    let best = &multi.best[0].params;
    assert!(
        (best[0] - 1.3).abs() < 0.05 && (best[1] - 0.4).abs() < 0.05,
        "{multi:?}"
    );
    // Kept candidates are distinct and sorted.
    assert!(multi.best.windows(2).all(|w| w[0].score >= w[1].score));
    // 25 at level 0, then at most 3 x 9 per level (shared lattice points counted once).
    assert!(multi.evaluations > 25 && multi.evaluations <= 25 + 5 * 27);
    let single = grid_search_multi(&axes, 6, 1, |_, p| f(p));
    assert!((single.best[0].params[0] + 1.2).abs() < 0.1, "{single:?}");
}

#[test]
fn parabola_recovers_an_exact_quadratic() {
    let o: Vec<f64> = (-4..=4).map(|i| i as f64 * 0.025).collect();
    let v: Vec<f64> = o.iter().map(|x| 0.3 - 2.0 * (x - 0.03).powi(2)).collect();
    let p = parabola(&o, &v);
    assert!((p.curvature + 2.0).abs() < 1e-9 && (p.vertex - 0.03).abs() < 1e-9);
    assert!(p.curvature_se < 1e-9, "{p:?}");
    let p = parabola(&o, &vec![1.0; o.len()]);
    assert!(p.curvature.abs() < 1e-12 && p.vertex.is_nan());
}

/// The curvature's standard error grows with the roughness about the parabola: a slight
/// bump under a rough slice is not significant (|c| < 3 se), the same bump on a smooth
/// one is.
#[test]
fn parabola_curvature_significance_follows_the_roughness() {
    let o: Vec<f64> = (-4..=4).map(|i| i as f64 * 0.025).collect();
    let bump = |x: f64| -0.05 * x * x;
    let rough: Vec<f64> = o
        .iter()
        .enumerate()
        .map(|(i, &x)| bump(x) + if i % 2 == 0 { 4e-4 } else { -4e-4 })
        .collect();
    let p = parabola(&o, &rough);
    assert!(p.curvature > -3.0 * p.curvature_se, "{p:?}");
    let smooth: Vec<f64> = o.iter().map(|&x| bump(x) + 1e-7 * x.sin()).collect();
    let p = parabola(&o, &smooth);
    assert!(p.curvature < -3.0 * p.curvature_se, "{p:?}");
}

#[test]
fn probe_is_flat_on_a_blank_image_and_not_at_the_simulated_optimum() {
    let g = synthetic_ground(7, 20_000);
    let param = PoseParam::SourceFromCam;
    let scene = MiScene::new(g.points.clone(), &g.intensities, &g.image, g.camera, 2.0);
    for dof in 0..6 {
        let half = if dof < 3 { 0.02 } else { 0.10 };
        let spec = ProbeSpec {
            dof,
            half,
            steps: 4,
            profile_rot_rad: 0.0,
        };
        let p = probe(&scene, param, &g.t_world_cam, &spec, 3.0);
        assert!(!p.flat && p.sigma_px < 0.5, "dof {dof}: {p:?}");
    }
    let blank = GrayImage::new(g.image.width(), g.image.height(), 0.5);
    let scene = MiScene::new(g.points, &g.intensities, &blank, g.camera, 2.0);
    let spec = ProbeSpec {
        dof: 5,
        half: 0.10,
        steps: 4,
        profile_rot_rad: 0.0,
    };
    let p = probe(&scene, param, &g.t_world_cam, &spec, 3.0);
    assert!(p.flat, "{p:?}");
}

#[test]
fn refinement_keeps_a_held_dof_at_its_start_and_reports_it_unconstrained() {
    let g = synthetic_ground(7, 20_000);
    let param = PoseParam::SourceFromCam;
    let scene = MiScene::new(g.points, &g.intensities, &g.image, g.camera, 2.0);
    let start = param.retract(
        &g.t_world_cam,
        &Vector6::new(0.004, -0.003, 0.006, 0.06, -0.05, 0.04),
    );
    let options = RefineOptions {
        held: [false, false, false, false, false, true],
        ..RefineOptions::default()
    };
    let r = refine(&scene, param, &start, &options);
    assert_eq!(r.x.translation.z.to_bits(), start.translation.z.to_bits());
    assert_eq!(r.held, options.held);
    assert_eq!(r.observability[5], Observability::Poor);
    // Its sigma is the initial guess's, uncorrelated with the others.
    assert_eq!(r.constraint[5], Constraint::HeldAtInitial);
    assert_eq!(
        r.covariance[(5, 5)].to_bits(),
        options.prior_sigma[5].powi(2).to_bits()
    );
    assert!((0..5).all(|k| r.covariance[(k, 5)] == 0.0));
    // The free DoFs still move towards the truth (x, y errors shrink from 6 / 5 cm).
    let d = r.x.translation.vector - g.t_world_cam.translation.vector;
    assert!(d.x.abs() < 0.03 && d.y.abs() < 0.03, "{d:?}");
}

#[test]
fn basin_search_then_refinement_recovers_the_simulated_camera_from_2_deg_and_10_cm() {
    let g = synthetic_ground(7, 40_000);
    let param = PoseParam::SourceFromCam;
    let scene = MiScene::new(g.points, &g.intensities, &g.image, g.camera, 2.0);
    let start = param.retract(
        &g.t_world_cam,
        &Vector6::new(0.02, -0.015, 0.025, 0.08, -0.06, 0.05),
    );
    // The default lattice over the three rotations; the translations are probed, and the
    // textured ground determines all three (none held).
    let options = BasinOptions {
        subsample: 4,
        ..BasinOptions::default()
    };
    let b = basin_search(&scene, &g.image, param, &start, &options, 3.0);
    assert_eq!(b.probes.len(), 3);
    assert!(b.held == [false; 6], "{:?}", b.probes);
    let r = refine(&scene, param, &b.candidates[0], &RefineOptions::default());
    let d = r.x.translation.vector - g.t_world_cam.translation.vector;
    let dr = (g.t_world_cam.rotation.inverse() * r.x.rotation).angle();
    eprintln!(
        "basin synthetic: {:?} m, {} deg",
        d.as_slice(),
        dr.to_degrees()
    );
    // Measured 7.2 mm / 0.052 deg; about 3x.
    assert!(d.norm() < 0.02 && dr.to_degrees() < 0.15, "{d:?} {dr}");
}
