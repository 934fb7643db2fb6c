//! `msreg convert <bag|mcap> <dataset-dir>`: a ROS 1 bag or an MCAP file to the dataset
//! layout, with a progress bar, a summary table and the sanity-check warnings.

use std::path::PathBuf;

use anyhow::Context;
use clap::Args;
use msreg_host::bag::{self, ConvertOptions, ConvertSummary, PointTime, TopicChoice, Topics};
use msreg_host::command::progress_bar;
use msreg_host::dataset::{ImuNoiseYaml, PoseSensorYaml};

/// `msreg convert`.
#[derive(Debug, Args)]
pub struct ConvertArgs {
    /// ROS 1 `.bag` or `.mcap` file.
    pub bag: PathBuf,
    /// Dataset directory to write (created).
    pub dataset: PathBuf,
    /// Topics and the files a bag lacks.
    #[command(flatten)]
    pub flags: BagFlags,
}

/// The flags that say how to read a bag: one topic per sensor and the noise / camera files
/// a bag does not carry (CONVENTIONS.md). Meant to be flattened into every command that
/// takes a bag (`#[command(flatten)]`).
#[derive(Debug, Clone, Default, Args)]
pub struct BagFlags {
    /// IMU topic (sensor_msgs/Imu) -> imu0/; default: the only one; `none` skips.
    #[arg(long)]
    pub imu: Option<String>,
    /// LiDAR topic (sensor_msgs/PointCloud2) -> lidar0/; default: the only one.
    #[arg(long)]
    pub lidar: Option<String>,
    /// Camera topic (sensor_msgs/Image or CompressedImage) -> cam0/; default: the only one.
    #[arg(long)]
    pub camera: Option<String>,
    /// Pose topic (nav_msgs/Odometry, geometry_msgs/PoseStamped) -> pose0/; default: the
    /// only one.
    #[arg(long)]
    pub pose: Option<String>,
    /// Kalibr imu.yaml with the IMU's noise figures (a bag has none; default: docs/bags.md).
    #[arg(long)]
    pub imu_config: Option<PathBuf>,
    /// pose0/sensor.yaml with the pose sensor's increment noise.
    #[arg(long)]
    pub pose_config: Option<PathBuf>,
    /// Kalibr camera.yaml copied to cam0/camera.yaml.
    #[arg(long)]
    pub camera_config: Option<PathBuf>,
    /// Kalibr target.yaml copied to the dataset.
    #[arg(long)]
    pub target: Option<PathBuf>,
}

impl BagFlags {
    /// The library options these flags mean (reads the noise files).
    pub fn options(&self) -> anyhow::Result<ConvertOptions> {
        Ok(ConvertOptions {
            topics: Topics {
                imu: TopicChoice::from_flag(self.imu.as_deref()),
                lidar: TopicChoice::from_flag(self.lidar.as_deref()),
                camera: TopicChoice::from_flag(self.camera.as_deref()),
                pose: TopicChoice::from_flag(self.pose.as_deref()),
            },
            imu_noise: self
                .imu_config
                .as_ref()
                .map(ImuNoiseYaml::read)
                .transpose()?,
            pose_noise: self
                .pose_config
                .as_ref()
                .map(PoseSensorYaml::read)
                .transpose()?,
            camera_yaml: self.camera_config.clone(),
            target_yaml: self.target.clone(),
        })
    }
}

/// Runs the conversion and prints what it did (stderr).
pub fn run(args: &ConvertArgs) -> anyhow::Result<ConvertSummary> {
    let options = args.flags.options()?;
    let bar = progress_bar(1000, "{spinner} reading [{bar:40}] {percent}% {elapsed}");
    let summary = bag::convert_with(&args.bag, &options, &args.dataset, &mut |f| {
        bar.set_position((f * 1000.0) as u64)
    });
    bar.finish_and_clear();
    let summary = summary.with_context(|| format!("converting {}", args.bag.display()))?;
    eprint!("{}", table(&summary));
    for w in &summary.warnings {
        eprintln!("msreg: warning: {w}");
    }
    eprintln!("msreg: wrote {}", args.dataset.display());
    Ok(summary)
}

/// One line per stream: sensor, topic, type, records, rate, frame id, span.
fn table(summary: &ConvertSummary) -> String {
    let mut text = format!(
        "{:<7} {:<40} {:<28} {:>8} {:>9} {:<16} {:>8}\n",
        "sensor", "topic", "type", "records", "rate Hz", "frame_id", "span s"
    );
    for s in &summary.streams {
        let span = s.first_last_ns.1.saturating_sub(s.first_last_ns.0) as f64 * 1e-9;
        text.push_str(&format!(
            "{:<7} {:<40} {:<28} {:>8} {:>9.2} {:<16} {:>8.2}\n",
            s.role.sensor(),
            s.topic,
            s.msg_type,
            s.written,
            s.cadence.rate_hz,
            s.frame_id,
            span
        ));
    }
    if let Some(PointTime::Field {
        name,
        unit,
        absolute,
    }) = &summary.lidar_time
    {
        let kind = if *absolute { "absolute" } else { "relative" };
        text.push_str(&format!(
            "lidar0 per-point time: field `{name}`, {unit:?}, {kind}\n"
        ));
    }
    text
}
