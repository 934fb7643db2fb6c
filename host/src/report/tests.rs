//! The page's structure without a browser: figures present with their ids, tags balanced,
//! nothing loaded from outside, the JSON embedded inertly.

use serde_json::{json, Value};

use super::{is_html, render_html, Kind};

/// A pose-IMU-like report: `n` updates converging to rz = 90 deg, t = (0.1, 0, 0) m.
fn filter_report(n: usize) -> Value {
    let history: Vec<Value> = (0..n)
        .map(|k| {
            let s = 1.0 / (1.0 + k as f64);
            json!({
                "t_s": 0.1 * k as f64,
                "rotation_vector": [0.0, 0.0, std::f64::consts::FRAC_PI_2 + 0.01 * s],
                "translation_m": [0.1 + 0.02 * s, 0.0, 0.0],
                "sigma_rot_deg": [s, s, s],
                "sigma_trans_m": [0.05 * s, 0.05 * s, 0.05 * s],
                "time_offset_s": 0.001,
                "sigma_time_offset_s": 0.01 * s,
                "nis": 6.0 + (k % 5) as f64 - 2.0,
                "accepted": k % 17 != 3,
            })
        })
        .collect();
    json!({
        "converged": true,
        "reasons": [],
        "scalar": "f64",
        "mean_nis_per_dof": 1.0,
        "excitation": [0.99, 0.98, 0.999, 0.95, 0.5, 0.97, 0.9],
        "events": [{"t_s": 2.0, "kind": "rotation_step", "statistic": 40.0, "magnitude": 0.02}],
        "timing_s": {"init": 0.1, "filter": 1.0},
        "poses_skipped": ["1000: before the first IMU sample </script><b>"],
        "history": history,
    })
}

/// Every `<tag` has its `</tag>` (void and self-closed elements excepted).
fn assert_balanced(html: &str, tag: &str) {
    let open =
        html.matches(&format!("<{tag}>")).count() + html.matches(&format!("<{tag} ")).count();
    let close = html.matches(&format!("</{tag}>")).count();
    assert_eq!(open, close, "<{tag}> opened {open} times, closed {close}");
}

#[test]
fn filter_report_page_has_every_figure_and_balanced_markup() {
    // Given a filter pipeline's report
    let report = filter_report(200);
    assert_eq!(Kind::of(&report), Kind::PoseImu);
    // When it is rendered
    let html = render_html(&report);
    // Then every figure is there, once
    for id in [
        "result",
        "fig-convergence",
        "fig-nis",
        "fig-residuals",
        "fig-excitation",
        "fig-sigmas",
        "events",
        "summary",
        "report-json",
    ] {
        assert_eq!(
            html.matches(&format!("id=\"{id}\"")).count(),
            1,
            "id {id} once"
        );
    }
    // 7 convergence panels, each with its band
    assert_eq!(html.matches("class=\"band\"").count(), 7);
    for tag in [
        "svg", "section", "table", "tr", "g", "p", "ul", "script", "clipPath",
    ] {
        assert_balanced(&html, tag);
    }
    // nothing external, and the only script is the inert JSON
    assert!(!html.contains("src=\"http") && !html.contains("href=\"http"));
    assert_eq!(html.matches("<script").count(), 1);
    assert!(html.contains("<script type=\"application/json\" id=\"report-json\">"));
    // text from the report is escaped
    assert!(html.contains("&lt;/script&gt;&lt;b&gt;"));
    assert!(html.starts_with("<!DOCTYPE html>"));
}

#[test]
fn result_table_holds_the_last_estimate_and_sigmas_in_display_units() {
    let html = render_html(&filter_report(10));
    // last point (s = 1/10): rz = 90 deg + 0.001 rad, sigma 0.1 deg; tx = 102 mm, sigma 5 mm;
    // t_d = 1 ms, sigma 1 ms
    let rz = (std::f64::consts::FRAC_PI_2 + 0.001).to_degrees();
    assert!(html.contains(&format!(
        "<td class=\"k\">rz</td><td>{rz:.4}</td><td>0.1000</td>"
    )));
    assert!(
        html.contains("<td class=\"k\">tx</td><td>102.0000</td><td>5.0000</td><td>15.0000</td>")
    );
    assert!(html.contains("<td class=\"k\">t_d</td><td>1.0000</td><td>1.0000</td>"));
}

#[test]
fn lidar_camera_matrix_becomes_a_rotation_vector_row() {
    // Given a target-based LiDAR-camera report with a 30 deg rotation about z
    let (s, c) = 30f64.to_radians().sin_cos();
    let report = json!({
        "method": "pbpc", "frames_total": 3, "frames_used": 3, "converged": false,
        "reason": "the solver hit its iteration limit",
        "t_cam_lidar": [[c, -s, 0.0, 0.5], [s, c, 0.0, -0.25], [0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 1.0]],
        "sigma_rot_deg": [0.1, 0.2, 0.3], "sigma_trans_m": [0.001, 0.002, 0.003],
        "frames": [{"frame": 0, "mlre_px": 0.5, "plane_rms_m": 0.01}, {"frame": 1, "mlre_px": 0.7, "plane_rms_m": 0.02}],
        "rejected": [{"frame": 2, "reason": "board missing"}],
    });
    assert_eq!(Kind::of(&report), Kind::LidarCamera);
    let html = render_html(&report);
    assert!(html.contains("<td class=\"k\">rz</td><td>30.0000</td><td>0.3000</td>"));
    assert!(html.contains("<td class=\"k\">ty</td><td>-250.0000</td><td>2.0000</td>"));
    assert!(html.contains("class=\"bad\"><b>NOT converged</b><br>the solver hit"));
    for id in ["fig-residuals", "fig-sigmas", "rejected", "frames"] {
        assert!(html.contains(&format!("id=\"{id}\"")), "{id}");
    }
    assert!(!html.contains("id=\"fig-convergence\""));
}

/// A prior-map report: a downward camera 8 m up, six MI slices, two peaking off centre.
fn prior_map_report() -> Value {
    let slice = |dof: &str, unit: &str, peak: f64| {
        let offsets: Vec<f64> = (-4..=4).map(|j| 0.25 * j as f64).collect();
        let mi: Vec<f64> = offsets
            .iter()
            .map(|d| 0.6 - 0.05 * (d - peak) * (d - peak))
            .collect();
        let quadratic: Vec<f64> = offsets.iter().map(|d| 0.6 - 0.08 * d * d).collect();
        json!({"dof": dof, "unit": unit, "offsets": offsets, "mi": mi,
               "quadratic": quadratic, "peak_offset": peak})
    };
    json!({
        "dataset": "ds", "image": "cam0/data/0.png", "points_used": 1000,
        "grid_evaluations": 1875, "iterations": 8, "converged": true, "mi": 0.6, "nmi": 1.1,
        "mi_hard": 0.5, "nmi_hard": 1.05, "n_eff": 900,
        "sigma_rot_deg": [0.01, 0.01, 0.006], "sigma_trans_m": [0.003, 0.003, 0.002],
        "survey_px_initial": [4.0, 6.0, 5.0], "survey_px": [0.05, 0.07, 0.04],
        "survey_median_px_initial": 5.0, "survey_median_px": 0.05,
        "t_world_cam": [[1.0, 0.0, 0.0, 2.0], [0.0, -1.0, 0.0, 3.0], [0.0, 0.0, -1.0, 8.0], [0.0, 0.0, 0.0, 1.0]],
        "mi_slices": [slice("rot_x_cam", "deg", 0.0), slice("rot_y_cam", "deg", 0.0),
                      slice("rot_z_cam", "deg", 0.25), slice("x_world", "m", 0.0),
                      slice("y_world", "m", -0.5), slice("z_world", "m", 0.0)],
    })
}

#[test]
fn prior_map_page_draws_the_mi_slices_and_the_survey_errors() {
    // Given a prior-map report
    let report = prior_map_report();
    assert_eq!(Kind::of(&report), Kind::PriorMap);
    // When it is rendered
    let html = render_html(&report);
    // Then the slices figure has six clipped panels, each with its curve, parabola and peak
    assert_eq!(html.matches("id=\"fig-mi-slices\"").count(), 1);
    for i in 0..6 {
        assert!(
            html.contains(&format!("id=\"clip-mi-slice-{i}\"")),
            "panel {i}"
        );
    }
    for dof in ["rot_x_cam", "rot_z_cam", "y_world", "z_world"] {
        assert!(html.contains(&format!("{dof} (MI, nats)")), "{dof}");
    }
    // the estimate is T_world_cam with its sigmas; the camera 8 m up
    assert!(html.contains("Result: T_world_cam"));
    assert!(html.contains("<td class=\"k\">tz</td><td>8000.0000</td><td>2.0000</td>"));
    // the survey errors are a histogram, the slices are not a table
    assert!(html.contains("surveyed points after MI"));
    assert!(!html.contains("id=\"mi_slices\""));
    for tag in ["svg", "g", "clipPath", "section"] {
        assert_balanced(&html, tag);
    }
}

#[test]
fn html_is_chosen_by_extension() {
    use std::path::Path;
    assert!(is_html(Path::new("r.html")) && is_html(Path::new("a/R.HTM")));
    assert!(!is_html(Path::new("r.json")) && !is_html(Path::new("html")));
}

#[test]
fn ticks_are_round_and_cover_the_range() {
    let t = super::svg::ticks(0.013, 0.87, 5);
    assert_eq!(t.len(), 4);
    assert!((t[0] - 0.2).abs() < 1e-12 && (t[3] - 0.8).abs() < 1e-12);
}

/// An infra report: a square loop, two cameras with 2 mm / 1 mm sigmas, one with its truth.
fn infra_report() -> Value {
    let trajectory: Vec<[f64; 2]> = (0..40)
        .map(|k| {
            let t = k as f64 / 40.0 * std::f64::consts::TAU;
            [10.0 * t.cos(), 5.0 * t.sin()]
        })
        .collect();
    let camera = |id: &str, x: f64, truth: Value| {
        json!({"id": id, "position_m": [x, 6.0, 3.0], "axis_xy_m": [x, 4.0],
               "footprint_xy_m": [[x - 2.0, 2.0], [x + 2.0, 2.0], [x + 2.0, 5.0], [x - 2.0, 5.0]],
               "covariance_xy_m2": [[4e-6, 0.0], [0.0, 1e-6]], "truth_m": truth})
    };
    json!({
        "stages": ["global bundle adjustment"],
        "cameras": [{"id": "c0", "solved": true, "reprojection_rmse_px": 0.3, "blob_rmse_px": 1.0}],
        "sampson": [],
        "top_view": {"plane_z_m": 0.0, "trajectory_xy_m": trajectory,
                     "cameras": [camera("c0", -3.0, json!([-2.999, 6.001, 3.0])),
                                 camera("c1", 3.0, Value::Null)]},
    })
}

#[test]
fn infra_page_has_the_top_view_with_ellipses_and_the_aligned_truth() {
    // Given an infra report with a top view
    let report = infra_report();
    assert_eq!(Kind::of(&report), Kind::Infra);
    // When it is rendered
    let html = render_html(&report);
    // Then the top view is there once, with the two footprints, both labels and the
    // magnification that brings the 6 mm 3-sigma semi-axis to at most 1.5 m (x200)
    assert_eq!(html.matches("id=\"fig-infra-topview\"").count(), 1);
    assert_eq!(html.matches("<polygon points=").count(), 2);
    assert!(html.contains(">c0</text>") && html.contains(">c1</text>"));
    assert!(html.contains("magnified x200"));
    // the truth only where the report has it
    assert_eq!(html.matches("truth (aligned)").count(), 1);
    assert_eq!(html.matches("fill=\"#2ca02c\"").count(), 2); // c0's dot and the legend
    for tag in ["svg", "g", "clipPath", "section"] {
        assert_balanced(&html, tag);
    }
    // and without a top view there is no figure
    let mut bare = report;
    bare.as_object_mut().unwrap().remove("top_view");
    assert!(!render_html(&bare).contains("fig-infra-topview"));
}
