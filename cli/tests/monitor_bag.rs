//! `msreg monitor <mcap|bag> --imu T --pose0 T --pose1 T --initial calibration.yaml`: a
//! simulated drive written by this test as an MCAP file (CDR) and as a ROS 1 bag, monitored
//! straight from the file, finds the same knock on the same sensor as the drive's directory.

#[path = "../../host/tests/bag_common/mod.rs"]
mod bag_common;

use std::path::Path;

use bag_common::{imu_msg, odometry_msg, write_mcap, write_ros1_bag, Recorded};
use msreg_host::bag::wire::Dialect;
use msreg_host::dataset::{read_imu_csv, read_pose_csv};

#[path = "support/run.rs"]
mod run;
use run::msreg;

type TestResult = Result<(), Box<dyn std::error::Error>>;

const TOPICS: [&str; 3] = ["/vehicle/imu", "/lidar/odometry", "/camera/vo"];

/// The drive's IMU and both odometries as messages of `dialect`, in the order a recorder logs
/// them (each arrives 2 ms after its stamp).
fn messages(drive: &Path, dialect: Dialect) -> Result<Vec<Recorded>, Box<dyn std::error::Error>> {
    let mut out = Vec::new();
    for (seq, r) in read_imu_csv(drive.join("imu0/data.csv"))?
        .iter()
        .enumerate()
    {
        out.push(Recorded {
            topic: TOPICS[0].into(),
            msg_type: "sensor_msgs/Imu".into(),
            log_time_ns: r.stamp_ns + 2_000_000,
            data: imu_msg(dialect, seq as u32, r, "imu_link", [1e-6, 1e-4]),
        });
    }
    for k in 0..2 {
        for (seq, p) in read_pose_csv(drive.join(format!("pose{k}/data.csv")))?
            .iter()
            .enumerate()
        {
            out.push(Recorded {
                topic: TOPICS[1 + k].into(),
                msg_type: "nav_msgs/Odometry".into(),
                log_time_ns: p.stamp_ns + 2_000_000,
                data: odometry_msg(dialect, seq as u32, p, "odom", &format!("sensor{k}")),
            });
        }
    }
    out.sort_by_key(|m| m.log_time_ns);
    Ok(out)
}

/// The first alarm of the run: `(t_s, sensor)` from its JSON report.
fn first_alarm(report: &Path) -> Result<(f64, String), Box<dyn std::error::Error>> {
    let json: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(report)?)?;
    let a = &json["alarms"][0];
    Ok((
        a["t_s"].as_f64().ok_or("no alarm")?,
        a["sensor"].as_str().ok_or("no sensor")?.to_string(),
    ))
}

#[test]
fn monitor_reads_a_drive_from_mcap_and_ros1_bag() -> TestResult {
    let tmp = tempfile::tempdir()?;
    let drive = tmp.path().join("drive");
    let d = drive.to_str().ok_or("utf-8")?;
    let o = msreg(&["simulate", "drive", d, "--seed", "122", "--duration", "40"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let dir_report = tmp.path().join("dir.json");
    let o = msreg(&[
        "monitor",
        d,
        "--report",
        dir_report.to_str().ok_or("utf-8")?,
    ]);
    assert_eq!(o.status.code(), Some(3));
    let (t_dir, sensor_dir) = first_alarm(&dir_report)?;
    assert_eq!(sensor_dir, "pose1");
    let file = |rel: &str| drive.join(rel).to_str().map(String::from).ok_or("utf-8");
    let (initial, imu_yaml) = (file("calibration.yaml")?, file("imu0/imu.yaml")?);
    let (s0, s1) = (file("pose0/sensor.yaml")?, file("pose1/sensor.yaml")?);
    for (name, dialect) in [("drive.mcap", Dialect::Cdr), ("drive.bag", Dialect::Ros1)] {
        let bag = tmp.path().join(name);
        let msgs = messages(&drive, dialect)?;
        match dialect {
            Dialect::Cdr => write_mcap(&bag, &msgs, "cdr"),
            Dialect::Ros1 => write_ros1_bag(&bag, &msgs),
        }
        let report = tmp.path().join(format!("{name}.json"));
        let o = msreg(&[
            "monitor",
            bag.to_str().ok_or("utf-8")?,
            "--imu",
            TOPICS[0],
            "--pose0",
            TOPICS[1],
            "--pose1",
            TOPICS[2],
            "--initial",
            &initial,
            "--imu-config",
            &imu_yaml,
            "--pose0-config",
            &s0,
            "--pose1-config",
            &s1,
            "--report",
            report.to_str().ok_or("utf-8")?,
        ]);
        let (out, err) = (
            String::from_utf8_lossy(&o.stdout),
            String::from_utf8_lossy(&o.stderr),
        );
        assert_eq!(o.status.code(), Some(3), "{name}: {out}\n{err}");
        assert!(
            out.contains("VERDICT MOVED: re-mount or check the bracket of pose1 (/camera/vo)"),
            "{name}: {out}"
        );
        // The same knock on the same sensor as the directory (the CSV the simulator wrote
        // and the bag carry the same stamps and poses, to the CSV's printed digits).
        let (t, sensor) = first_alarm(&report)?;
        println!("{name}: first alarm {sensor} at {t:.3} s (directory: {t_dir:.3} s)");
        assert_eq!(sensor, "pose1", "{name}");
        assert!((t - t_dir).abs() < 0.2, "{name}: {t} s vs {t_dir} s");
    }
    Ok(())
}

#[test]
fn a_bag_without_its_pose_topics_or_calibration_exits_2() -> TestResult {
    let tmp = tempfile::tempdir()?;
    let drive = tmp.path().join("drive");
    let d = drive.to_str().ok_or("utf-8")?;
    let o = msreg(&["simulate", "drive", d, "--seed", "3", "--duration", "5"]);
    assert!(o.status.success());
    let bag = tmp.path().join("drive.mcap");
    write_mcap(&bag, &messages(&drive, Dialect::Cdr)?, "cdr");
    let b = bag.to_str().ok_or("utf-8")?;
    let initial = drive.join("calibration.yaml");
    let i = initial.to_str().ok_or("utf-8")?;
    for (args, says) in [
        (
            vec!["monitor", b, "--pose0", TOPICS[1], "--pose1", TOPICS[2]],
            "--initial",
        ),
        (
            vec!["monitor", b, "--initial", i, "--pose1", TOPICS[2]],
            "--pose0",
        ),
        (
            // --pose1 is optional (one pose sensor), its noise file without it is not.
            vec![
                "monitor",
                b,
                "--initial",
                i,
                "--pose0",
                TOPICS[1],
                "--pose1-config",
                i,
            ],
            "--pose1-config without --pose1",
        ),
        (
            vec![
                "monitor",
                b,
                "--initial",
                i,
                "--pose0",
                TOPICS[1],
                "--pose1",
                "/nope",
            ],
            "/nope",
        ),
        (
            vec!["monitor", d, "--pose0", TOPICS[1]],
            "apply to a .bag or .mcap",
        ),
    ] {
        let o = msreg(&args);
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{args:?}: {err}");
        assert!(err.contains(says), "{args:?}: {err}");
    }
    Ok(())
}
