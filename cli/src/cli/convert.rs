//! `msreg convert <bag|mcap> <dataset-dir>`: a ROS 1 bag or an MCAP file to the dataset
//! layout, with a progress bar, a summary table and the sanity-check warnings.

use std::path::{Path, PathBuf};

use super::outcome::progress_bar;
use anyhow::Context;
use clap::Args;
use msreg_host::bag::{self, ConvertOptions, ConvertSummary, PointTime, TopicChoice, Topics};
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
/// a bag does not carry (docs/formats.md). Flattened into `msreg convert` and `msreg
/// calibrate` (global there, so they may follow the pipeline's name).
#[derive(Debug, Clone, Default, Args)]
pub struct BagFlags {
    /// IMU topic (sensor_msgs/Imu) -> imu0/; default: the only one; `none` skips.
    #[arg(long, global = true)]
    pub imu: Option<String>,
    /// LiDAR topic (sensor_msgs/PointCloud2) -> lidar0/; default: the only one.
    #[arg(long, global = true)]
    pub lidar: Option<String>,
    /// Camera topic (sensor_msgs/Image or CompressedImage) -> cam0/; default: the only one.
    #[arg(long, global = true)]
    pub camera: Option<String>,
    /// Pose topic (nav_msgs/Odometry, geometry_msgs/PoseStamped) -> pose0/; default: the
    /// only one.
    #[arg(long, global = true)]
    pub pose: Option<String>,
    /// Kalibr imu.yaml with the IMU's noise figures (a bag has none; default: docs/bags.md).
    #[arg(long, global = true)]
    pub imu_config: Option<PathBuf>,
    /// pose0/sensor.yaml with the pose sensor's increment noise.
    #[arg(long, global = true)]
    pub pose_config: Option<PathBuf>,
    /// Kalibr camera.yaml copied to cam0/camera.yaml.
    #[arg(long, global = true)]
    pub camera_config: Option<PathBuf>,
    /// Kalibr target.yaml copied to the dataset.
    #[arg(long, global = true)]
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

impl BagFlags {
    /// True when any flag was given.
    fn any(&self) -> bool {
        [&self.imu, &self.lidar, &self.camera, &self.pose]
            .iter()
            .any(|f| f.is_some())
            || [
                &self.imu_config,
                &self.pose_config,
                &self.camera_config,
                &self.target,
            ]
            .iter()
            .any(|f| f.is_some())
    }
}

/// Whether `path` names a ROS 1 bag or an MCAP file (by its extension; the readers check
/// the magic bytes).
fn is_bag(path: &Path) -> bool {
    path.is_file()
        && path
            .extension()
            .and_then(|e| e.to_str())
            .is_some_and(|e| e.eq_ignore_ascii_case("bag") || e.eq_ignore_ascii_case("mcap"))
}

/// For `msreg calibrate`: when `dataset` is a bag, converts it into a temporary dataset
/// (printing the conversion table and warnings, as `msreg convert` does) and points
/// `dataset` there. The returned guard removes the temporary dataset when dropped. Topic
/// or config flags given with a dataset directory are an error: they would be ignored.
pub fn dataset_from_bag(
    dataset: &mut PathBuf,
    flags: &BagFlags,
) -> anyhow::Result<Option<tempfile::TempDir>> {
    if !is_bag(dataset) {
        if flags.any() {
            anyhow::bail!(
                "{}: the topic and config flags (--imu, --pose, --imu-config, ...) apply to a \
                 .bag or .mcap file; this is not one (convert a bag with `msreg convert`)",
                dataset.display()
            );
        }
        return Ok(None);
    }
    let scratch = tempfile::Builder::new().prefix("msreg-bag-").tempdir()?;
    let args = ConvertArgs {
        bag: dataset.clone(),
        dataset: scratch.path().join("dataset"),
        flags: flags.clone(),
    };
    run(&args)?;
    eprintln!(
        "msreg: reading {} through that temporary dataset (keep one with `msreg convert`)",
        dataset.display()
    );
    *dataset = args.dataset;
    Ok(Some(scratch))
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
