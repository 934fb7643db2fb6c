//! Each export read back with a YAML parser: the documented keys are present and the
//! transforms recovered with each tool's convention equal the result's to 1e-12.

use msreg_host::dataset::{CalibrationResult, CameraIntrinsics, ExtrinsicEstimate, SectionName};
use msreg_host::export::{render, ExportError, ExportFormat};
use nalgebra::{Isometry3, Matrix4, Translation3, UnitQuaternion, Vector3};
use serde_yaml::Value;

fn iso(r: [f64; 3], t: [f64; 3]) -> Isometry3<f64> {
    Isometry3::from_parts(
        Translation3::new(t[0], t[1], t[2]),
        UnitQuaternion::from_scaled_axis(Vector3::from(r)),
    )
}

fn intr(model: &str, p: Vec<f64>, dm: &str, d: Vec<f64>) -> CameraIntrinsics {
    CameraIntrinsics {
        camera_model: model.into(),
        intrinsics: p,
        distortion_model: dm.into(),
        distortion_coeffs: d,
        resolution: [752, 480],
        sigma_intrinsics: vec![],
    }
}

/// Two cameras (pinhole-radtan, pinhole-equidistant), a LiDAR, a pose sensor, a second IMU.
fn rig() -> CalibrationResult {
    let mut r = CalibrationResult::new();
    let e = |t, s| ExtrinsicEstimate::exact(t, s);
    r.set_extrinsic(
        SectionName::cam(0),
        e(iso([0.1, -1.2, 0.3], [0.05, -0.02, 0.1]), 0.004),
    );
    r.set_extrinsic(
        SectionName::cam(1),
        e(iso([1.3, 0.2, -0.4], [-0.11, 0.03, 0.07]), 0.004),
    );
    r.section_mut(SectionName::cam(0)).intrinsics = Some(intr(
        "pinhole",
        vec![458.6, 457.3, 367.2, 248.3],
        "radtan",
        vec![-0.28, 0.07, 1.9e-4, 1.7e-5],
    ));
    r.section_mut(SectionName::cam(1)).intrinsics = Some(intr(
        "pinhole",
        vec![380.1, 380.2, 370.0, 240.5],
        "equidistant",
        vec![-0.01, 0.02, -0.003, 4e-4],
    ));
    r.set_extrinsic(
        SectionName::lidar(0),
        e(iso([0.0, 0.5, 2.9], [0.3, 0.0, -0.2]), -0.01),
    );
    r.set_extrinsic(
        SectionName::pose(0),
        e(iso([-0.7, 0.1, 0.2], [1.0, 2.0, 0.5]), 0.02),
    );
    r.set_extrinsic(
        SectionName::imu(1),
        e(iso([0.02, -0.03, 3.1], [0.01, 0.02, 0.0]), 0.001),
    );
    r
}

fn text(files: &[msreg_host::export::ExportFile], name: &str) -> String {
    files
        .iter()
        .find(|f| f.name == name)
        .unwrap_or_else(|| panic!("no {name}"))
        .text
        .clone()
}

fn rows(v: &Value) -> Isometry3<f64> {
    let rows = v.as_sequence().expect("matrix rows");
    assert_eq!(rows.len(), 4);
    let mut m = Matrix4::zeros();
    for (i, row) in rows.iter().enumerate() {
        let row = row.as_sequence().expect("row");
        assert_eq!(row.len(), 4);
        for (j, x) in row.iter().enumerate() {
            m[(i, j)] = x.as_f64().expect("number");
        }
    }
    msreg_host::dataset::isometry_from_matrix(&m).expect("rigid")
}

fn close(a: &Isometry3<f64>, b: &Isometry3<f64>) {
    let d = (a.to_homogeneous() - b.to_homogeneous()).abs().max();
    assert!(d < 1e-12, "transform differs by {d:e}");
}

fn strip_opencv(t: &str) -> String {
    let t = t.strip_prefix("%YAML:1.0\n").expect("%YAML:1.0 header");
    t.replace("!!opencv-matrix", "").replacen("---\n", "", 1)
}

fn t_imu0(r: &CalibrationResult, name: SectionName) -> Isometry3<f64> {
    msreg_host::export::t_imu0_sensor(&name, r).expect("the sensor is in the result")
}

#[test]
fn kalibr_and_openvins_round_trip() {
    let r = rig();
    for (format, cam_file, imu_file, key) in [
        (
            ExportFormat::Kalibr,
            "camchain-imucam.yaml",
            "imu.yaml",
            "T_cam_imu",
        ),
        (
            ExportFormat::OpenVins,
            "kalibr_imucam_chain.yaml",
            "kalibr_imu_chain.yaml",
            "T_imu_cam",
        ),
    ] {
        let files = render(&r, format).unwrap();
        let mut cam_text = text(&files, cam_file);
        if format == ExportFormat::OpenVins {
            cam_text = strip_opencv(&cam_text);
        }
        let y: Value = serde_yaml::from_str(&cam_text).unwrap();
        for i in 0..2u16 {
            let c = &y[format!("cam{i}").as_str()];
            for k in [
                "cam_overlaps",
                "camera_model",
                "distortion_coeffs",
                "distortion_model",
                "intrinsics",
                "resolution",
                "rostopic",
                "timeshift_cam_imu",
                key,
            ] {
                assert!(c.get(k).is_some(), "{format} cam{i} lacks {k}");
            }
            let want = r.extrinsic(&SectionName::cam(i)).unwrap().transform;
            let got = rows(&c[key]);
            close(
                &if key == "T_imu_cam" {
                    got.inverse()
                } else {
                    got
                },
                &want,
            );
            assert_eq!(c["timeshift_cam_imu"].as_f64(), Some(0.004));
            let k = r
                .section(&SectionName::cam(i))
                .unwrap()
                .intrinsics
                .clone()
                .unwrap();
            let p: Vec<f64> = c["intrinsics"]
                .as_sequence()
                .unwrap()
                .iter()
                .map(|v| v.as_f64().unwrap())
                .collect();
            assert_eq!(p, k.intrinsics);
        }
        let chain = rows(&y["cam1"]["T_cn_cnm1"]);
        let c0 = r.extrinsic(&SectionName::cam(0)).unwrap().transform;
        let c1 = r.extrinsic(&SectionName::cam(1)).unwrap().transform;
        close(&chain, &(c1 * c0.inverse()));
        let mut imu_text = text(&files, imu_file);
        if format == ExportFormat::OpenVins {
            imu_text = strip_opencv(&imu_text);
        }
        let imu: Value = serde_yaml::from_str(&imu_text).unwrap();
        close(
            &rows(&imu["imu1"]["T_i_b"]).inverse(),
            &t_imu0(&r, SectionName::imu(1)),
        );
        assert_eq!(imu["imu1"]["time_offset"].as_f64(), Some(0.001));
    }
}

#[test]
fn vins_fusion_round_trips() {
    let r = rig();
    let files = render(&r, ExportFormat::VinsFusion).unwrap();
    let y: Value = serde_yaml::from_str(&strip_opencv(&text(&files, "vins_config.yaml"))).unwrap();
    assert_eq!(y["num_of_cam"].as_u64(), Some(2));
    assert_eq!(y["td"].as_f64(), Some(0.004));
    assert!(y.get("estimate_td").is_some());
    for i in 0..2u16 {
        let m = &y[format!("body_T_cam{i}").as_str()];
        assert_eq!(
            (m["rows"].as_u64(), m["cols"].as_u64(), m["dt"].as_str()),
            (Some(4), Some(4), Some("d"))
        );
        let d: Vec<f64> = m["data"]
            .as_sequence()
            .unwrap()
            .iter()
            .map(|v| v.as_f64().unwrap())
            .collect();
        let got = msreg_host::dataset::isometry_from_matrix(&Matrix4::from_row_slice(&d)).unwrap();
        close(&got, &t_imu0(&r, SectionName::cam(i)));
    }
    let c1: Value = serde_yaml::from_str(&strip_opencv(&text(
        &files,
        y["cam1_calib"].as_str().unwrap(),
    )))
    .unwrap();
    assert_eq!(c1["model_type"].as_str(), Some("KANNALA_BRANDT"));
    assert_eq!(c1["projection_parameters"]["mu"].as_f64(), Some(380.1));
    assert_eq!(c1["projection_parameters"]["k5"].as_f64(), Some(4e-4));
    let c0: Value =
        serde_yaml::from_str(&strip_opencv(&text(&files, "cam0_pinhole.yaml"))).unwrap();
    assert_eq!(c0["distortion_parameters"]["p2"].as_f64(), Some(1.7e-5));
    assert_eq!(c0["projection_parameters"]["cy"].as_f64(), Some(248.3));
    let mut bare = r.clone();
    bare.section_mut(SectionName::cam(1)).intrinsics = None;
    match render(&bare, ExportFormat::VinsFusion) {
        Err(e @ ExportError::MissingKey { .. }) => {
            assert!(e.to_string().contains("cam1.intrinsics"))
        }
        other => panic!("{other:?}"),
    }
}

#[test]
fn tf_yaml_round_trips() {
    let r = rig();
    let files = render(&r, ExportFormat::Tf).unwrap();
    let y: Value = serde_yaml::from_str(&text(&files, "static_transforms.yaml")).unwrap();
    let list = y.as_sequence().unwrap();
    assert_eq!(list.len(), 5);
    for item in list {
        assert_eq!(item["parent"].as_str(), Some("imu0"));
        let name: SectionName = item["child"].as_str().unwrap().parse().unwrap();
        let t: Vec<f64> = item["translation"]
            .as_sequence()
            .unwrap()
            .iter()
            .map(|v| v.as_f64().unwrap())
            .collect();
        let q: Vec<f64> = item["rotation"]
            .as_sequence()
            .unwrap()
            .iter()
            .map(|v| v.as_f64().unwrap())
            .collect();
        let got = Isometry3::from_parts(
            Translation3::new(t[0], t[1], t[2]),
            UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(q[3], q[0], q[1], q[2])),
        );
        close(&got, &t_imu0(&r, name));
    }
    assert_eq!(
        text(&files, "static_transforms.sh")
            .matches("static_transform_publisher")
            .count(),
        5
    );
}

#[test]
fn urdf_origins_round_trip() {
    let r = rig();
    let u = text(&render(&r, ExportFormat::Urdf).unwrap(), "msreg_rig.urdf");
    let mut joints = 0;
    for chunk in u.split("<child link=\"").skip(1) {
        let name: SectionName = chunk[..chunk.find('"').unwrap()].parse().unwrap();
        let attr = |k: &str| -> Vec<f64> {
            let s = &chunk[chunk.find(&format!("{k}=\"")).unwrap() + k.len() + 2..];
            s[..s.find('"').unwrap()]
                .split(' ')
                .map(|x| x.parse().unwrap())
                .collect()
        };
        let (xyz, rpy) = (attr("xyz"), attr("rpy"));
        let got = Isometry3::from_parts(
            Translation3::new(xyz[0], xyz[1], xyz[2]),
            UnitQuaternion::from_euler_angles(rpy[0], rpy[1], rpy[2]),
        );
        close(&got, &t_imu0(&r, name));
        joints += 1;
    }
    assert_eq!(joints, 5);
}
