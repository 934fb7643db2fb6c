//! `--report run.html` of every pipeline, from short simulated runs of the `msreg` binary,
//! opened in headless Chromium (Debian `chromium`, installed by tools/test.sh): the page
//! renders without a console message (it has no script; anything logged is an error), the
//! browser's DOM holds every figure, and the JSON report of the same run carries what the
//! figures were drawn from. Without Chromium the browser half prints a skip notice.

use std::path::{Path, PathBuf};
use std::process::Command;

use serde_json::Value;

#[path = "support/run.rs"]
mod run;
use run::msreg;

fn run_ok(args: &[&str]) {
    let out = msreg(args);
    assert!(
        out.status.success(),
        "msreg {}: {}",
        args.join(" "),
        String::from_utf8_lossy(&out.stderr)
    );
}

/// Calibrates with `--report r.html`; returns the page and the JSON report embedded in it.
fn reports(dir: &Path, calibrate: &[&str]) -> (Value, String) {
    let html = dir.join("r.html");
    let mut args = calibrate.to_vec();
    let r = html.to_string_lossy().into_owned();
    let out = dir.join("result.yaml").to_string_lossy().into_owned();
    args.extend(["-o", &out, "--report", &r]);
    // Exit 1 (ran, did not converge) still writes the report.
    let o = msreg(&args);
    assert!(
        matches!(o.status.code(), Some(0 | 1)),
        "msreg {}: {}",
        args.join(" "),
        String::from_utf8_lossy(&o.stderr)
    );
    let page = std::fs::read_to_string(html).expect("html");
    let start = "<script type=\"application/json\" id=\"report-json\">";
    let json = page
        .split_once(start)
        .and_then(|(_, rest)| rest.split_once("</script>"))
        .map(|(json, _)| json)
        .expect("embedded JSON");
    (
        serde_json::from_str(json).expect("embedded JSON parses"),
        page,
    )
}

fn chromium() -> Option<PathBuf> {
    ["chromium", "chromium-browser", "google-chrome"]
        .iter()
        .find_map(|name| {
            let ok = Command::new(name).arg("--version").output().ok()?;
            ok.status.success().then(|| PathBuf::from(name))
        })
}

/// The DOM after loading `page` in headless Chromium and the console lines it logged.
fn browse(browser: &Path, page: &Path, profile: &Path) -> (String, Vec<String>) {
    let url = format!("file://{}", page.canonicalize().expect("page").display());
    let out = Command::new(browser)
        .args([
            "--headless",
            "--no-sandbox",
            "--disable-gpu",
            "--no-first-run",
            "--host-resolver-rules=MAP * ~NOTFOUND",
            "--enable-logging=stderr",
            "--log-level=0",
        ])
        .arg(format!("--user-data-dir={}", profile.display()))
        .args(["--dump-dom", &url])
        .output()
        .expect("chromium runs");
    assert!(out.status.success(), "chromium failed on {url}");
    let console = String::from_utf8_lossy(&out.stderr)
        .lines()
        .filter(|l| l.contains(":CONSOLE"))
        .map(str::to_string)
        .collect();
    (String::from_utf8_lossy(&out.stdout).into_owned(), console)
}

/// Asserts the page renders cleanly in the browser with `ids` in its DOM; skips (with a
/// notice) without a browser.
fn assert_renders(name: &str, dir: &Path, ids: &[&str]) {
    let Some(browser) = chromium() else {
        eprintln!("SKIP report_html {name}: no chromium on PATH (tools/test.sh installs it)");
        return;
    };
    let (dom, console) = browse(&browser, &dir.join("r.html"), &dir.join("profile"));
    assert!(console.is_empty(), "{name}: console messages {console:?}");
    for id in ids {
        assert!(
            dom.contains(&format!("id=\"{id}\"")),
            "{name}: no element {id} in the browser's DOM"
        );
    }
    // The browser parsed every SVG as SVG (an unbalanced tag would merge or drop some).
    let source = std::fs::read_to_string(dir.join("r.html")).expect("html");
    for tag in ["<svg", "<polyline", "<polygon", "<circle"] {
        assert_eq!(
            dom.matches(tag).count(),
            source.matches(tag).count(),
            "{name}: {tag} count differs in the DOM"
        );
    }
}

fn assert_ids(name: &str, html: &str, ids: &[&str]) {
    for id in ids {
        assert!(html.contains(&format!("id=\"{id}\"")), "{name}: no {id}");
    }
}

/// The NIS figure divides by the DoF the renderer infers per update: they reproduce the
/// report's own mean NIS per DoF.
fn assert_nis_dofs_match(name: &str, report: &Value) {
    let history = report["history"].as_array().expect("history");
    let reprojection = report["update"].as_str() == Some("reprojection");
    let frames = report["frames"].as_array().cloned().unwrap_or_default();
    let (mut nis, mut dof) = (0.0, 0.0);
    for h in history {
        nis += h["nis"].as_f64().expect("nis");
        // Every history point stores its dof; the inference below is the renderer's
        // fallback for older reports, checked against the stored value.
        let stored = h["dof"].as_u64().expect("dof") as f64;
        dof += stored;
        let inferred = if reprojection {
            let t = h["t_s"].as_f64().expect("t");
            let f = frames
                .iter()
                .min_by(|a, b| {
                    let d = |f: &Value| (f["t_s"].as_f64().unwrap_or(f64::NAN) - t).abs();
                    d(a).total_cmp(&d(b))
                })
                .expect("frame");
            2.0 * f["corners"].as_f64().expect("corners")
        } else {
            6.0
        };
        assert!(
            (stored - inferred).abs() < 0.5,
            "{name}: stored {stored}, inferred {inferred} dof"
        );
    }
    let mean = report["mean_nis_per_dof"].as_f64().expect("mean");
    assert!(
        (nis / dof - mean).abs() <= 1e-9 * mean.abs().max(1.0),
        "{name}: NIS/dof {} vs report {mean}",
        nis / dof
    );
}

/// The aligned truth is this close to each estimated camera in `infra_report_renders`
/// (3x the worst measured, 14.8 mm of 6 cameras, simulation seed 0).
const TRUTH_GAP_M: f64 = 0.045;

const FILTER_IDS: [&str; 8] = [
    "status",
    "result",
    "fig-convergence",
    "fig-nis",
    "fig-residuals",
    "fig-excitation",
    "fig-sigmas",
    "events",
];

#[test]
fn pose_imu_report_renders() {
    let tmp = tempfile::tempdir().expect("tempdir");
    let ds = tmp.path().join("ds").to_string_lossy().into_owned();
    run_ok(&["simulate", "pose-imu", &ds, "--duration", "20"]);
    let (json, html) = reports(tmp.path(), &["calibrate", "pose-imu", &ds]);
    assert_ids("pose-imu", &html, &FILTER_IDS);
    assert_nis_dofs_match("pose-imu", &json);
    assert_renders("pose-imu", tmp.path(), &FILTER_IDS);
}

#[test]
fn camera_imu_report_renders_with_the_reprojection_sample() {
    let tmp = tempfile::tempdir().expect("tempdir");
    let ds = tmp.path().join("ds").to_string_lossy().into_owned();
    run_ok(&["simulate", "camera-imu", &ds, "--duration", "12"]);
    let (json, html) = reports(tmp.path(), &["calibrate", "camera-imu", &ds]);
    assert!(json["sample"]["detected"]
        .as_array()
        .is_some_and(|a| !a.is_empty()));
    let ids: Vec<&str> = FILTER_IDS
        .iter()
        .copied()
        .chain(["fig-reprojection"])
        .collect();
    assert_ids("camera-imu", &html, &ids);
    assert_nis_dofs_match("camera-imu", &json);
    assert_renders("camera-imu", tmp.path(), &ids);
}

#[test]
fn lidar_imu_report_renders() {
    let tmp = tempfile::tempdir().expect("tempdir");
    let ds = tmp.path().join("ds").to_string_lossy().into_owned();
    run_ok(&["simulate", "lidar-imu", &ds, "--duration", "12"]);
    let (json, html) = reports(tmp.path(), &["calibrate", "lidar-imu", &ds]);
    assert_ids("lidar-imu", &html, &FILTER_IDS);
    assert_nis_dofs_match("lidar-imu", &json);
    assert_renders("lidar-imu", tmp.path(), &FILTER_IDS);
}

#[test]
fn lidar_camera_and_targetless_reports_render_with_overlays() {
    let tmp = tempfile::tempdir().expect("tempdir");
    let ds = tmp.path().join("ds").to_string_lossy().into_owned();
    run_ok(&["simulate", "lidar-camera", &ds, "--poses", "6"]);
    let target = tmp.path().join("target");
    std::fs::create_dir_all(&target).expect("mkdir");
    let (_, html) = reports(&target, &["calibrate", "lidar-camera", &ds]);
    let ids = [
        "status",
        "result",
        "fig-residuals",
        "fig-sigmas",
        "overlay-0",
    ];
    assert_ids("lidar-camera", &html, &ids);
    assert_renders("lidar-camera", &target, &ids);

    let mi = tmp.path().join("mi");
    std::fs::create_dir_all(&mi).expect("mkdir");
    let initial = target.join("result.yaml").to_string_lossy().into_owned();
    let (_, html) = reports(
        &mi,
        &[
            "calibrate",
            "lidar-camera",
            &ds,
            "--targetless",
            "--initial",
            &initial,
        ],
    );
    let ids = [
        "status",
        "result",
        "fig-sigmas",
        "overlay-0",
        "overlay-1",
        "observability",
    ];
    assert_ids("targetless", &html, &ids);
    assert_renders("targetless", &mi, &ids);
}

#[test]
fn infra_report_renders() {
    let tmp = tempfile::tempdir().expect("tempdir");
    let ds = tmp.path().join("ds").to_string_lossy().into_owned();
    run_ok(&["simulate", "infra", &ds, "--cameras", "6"]);
    let (report, html) = reports(tmp.path(), &["calibrate", "infra", &ds]);
    // The simulated dataset's truth is in the top view, aligned onto the estimate.
    let cams = report["top_view"]["cameras"].as_array().expect("top view");
    assert_eq!(cams.len(), 6);
    for c in cams {
        let (p, t) = (&c["position_m"], &c["truth_m"]);
        let d: f64 = (0..3)
            .map(|k| (p[k].as_f64().unwrap() - t[k].as_f64().expect("truth")).powi(2))
            .sum::<f64>()
            .sqrt();
        eprintln!(
            "infra top view: {} truth {:.1} mm from the estimate",
            c["id"],
            1e3 * d
        );
        assert!(d < TRUTH_GAP_M, "{}: {d} m", c["id"]);
    }
    let ids = ["fig-residuals", "fig-infra-topview", "cameras"];
    assert_ids("infra", &html, &ids);
    assert_renders("infra", tmp.path(), &ids);
}

#[test]
fn prior_map_report_renders_with_mi_slices_and_overlays() {
    let tmp = tempfile::tempdir().expect("tempdir");
    let ds = tmp.path().join("ds").to_string_lossy().into_owned();
    run_ok(&["simulate", "prior-map", &ds, "--seed", "12", "--small"]);
    let (json, html) = reports(tmp.path(), &["calibrate", "prior-map", &ds]);
    let ids = [
        "status",
        "result",
        "fig-residuals",
        "fig-sigmas",
        "fig-mi-slices",
        "overlay-0",
        "overlay-1",
    ];
    assert_ids("prior-map", &html, &ids);
    // The figure draws what the report holds: six slices, each peaking at the estimate
    // within one step (the refinement's optimum).
    let slices = json["mi_slices"].as_array().expect("mi_slices");
    assert_eq!(slices.len(), 6);
    for s in slices {
        let offsets = s["offsets"].as_array().expect("offsets");
        let step = offsets[1].as_f64().expect("o") - offsets[0].as_f64().expect("o");
        let peak = s["peak_offset"].as_f64().expect("peak");
        assert!(peak.abs() <= step * 1.0001, "{}: peak {peak}", s["dof"]);
    }
    assert_renders("prior-map", tmp.path(), &ids);
}

#[test]
fn monitor_report_renders_with_its_timeline() {
    let tmp = tempfile::tempdir().expect("tempdir");
    let ds = tmp.path().join("ds").to_string_lossy().into_owned();
    run_ok(&["simulate", "drive", &ds, "--duration", "40"]);
    let html = tmp.path().join("r.html");
    let o = msreg(&["monitor", &ds, "--report", &html.to_string_lossy()]);
    // The default drive knocks pose1 at 30 s: the monitor says so with exit code 3.
    assert_eq!(
        o.status.code(),
        Some(3),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
    let page = std::fs::read_to_string(&html).expect("html");
    let ids = ["fig-monitor-timeline", "alarms", "summary", "report-json"];
    assert_ids("monitor", &page, &ids);
    assert!(page.contains("msreg: on-vehicle calibration monitoring"));
    // The knocked camera's alarm is in the page, as a table row and in the timeline.
    assert!(page.contains("rotation_step"), "no alarm in the page");
    assert_renders("monitor", tmp.path(), &ids);
}

#[test]
fn joint_report_renders_both_sensors() {
    let tmp = tempfile::tempdir().expect("tempdir");
    let ds = tmp.path().join("ds").to_string_lossy().into_owned();
    run_ok(&[
        "simulate",
        "joint",
        &ds,
        "--duration",
        "12",
        "--rings",
        "16",
        "--columns",
        "512",
    ]);
    let (json, html) = reports(tmp.path(), &["calibrate", "joint", &ds]);
    let ids = [
        "status-cam0",
        "status-lidar0",
        "result-cam0-T_cam_imu",
        "result-lidar0-T_imu_lidar",
        "fig-convergence-cam0",
        "fig-nis-cam0",
        "fig-convergence-lidar0",
        "fig-nis-lidar0",
        "summary",
    ];
    assert_ids("joint", &html, &ids);
    assert!(html.contains("msreg: joint LiDAR-IMU-camera calibration"));
    // Each element id once: the two sensors' sections are scoped.
    for id in ids {
        assert_eq!(html.matches(&format!("id=\"{id}\"")).count(), 1, "{id}");
    }
    // The camera's updates are images of corners: their dof is twice the corners, stored
    // per history point, and reproduces the filter's mean NIS per dof.
    for sensor in ["camera", "lidar"] {
        let r = &json[sensor];
        let history = r["history"].as_array().expect("history");
        let (nis, dof) = history.iter().fold((0.0, 0.0), |(n, d), h| {
            (
                n + h["nis"].as_f64().expect("nis"),
                d + h["dof"].as_f64().expect("dof"),
            )
        });
        let mean = r["mean_nis_per_dof"].as_f64().expect("mean");
        assert!((nis / dof - mean).abs() <= 1e-9 * mean.max(1.0), "{sensor}");
    }
    assert!(json["camera"]["history"][0]["dof"].as_u64().expect("dof") > 6);
    assert_renders("joint", tmp.path(), &ids);
}
