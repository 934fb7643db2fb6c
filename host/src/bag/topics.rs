//! Which topic feeds which sensor of the dataset: named on the command line, or found by
//! message type when exactly one topic has a type the sensor accepts.

use std::path::Path;

use super::error::BagError;
use super::source::TopicInfo;
use super::warnings::BagWarning;
use super::wire::Dialect;

/// The sensors a bag can fill, with the dataset directory each becomes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, serde::Serialize)]
pub enum Role {
    /// `imu0/`.
    Imu,
    /// `lidar0/`.
    Lidar,
    /// `cam0/`.
    Camera,
    /// `pose0/`.
    Pose,
}

impl Role {
    /// All roles.
    pub const ALL: [Role; 4] = [Role::Imu, Role::Lidar, Role::Camera, Role::Pose];

    /// The role's name on the command line (`imu`, `lidar`, `camera`, `pose`).
    pub fn name(self) -> &'static str {
        match self {
            Role::Imu => "imu",
            Role::Lidar => "lidar",
            Role::Camera => "camera",
            Role::Pose => "pose",
        }
    }

    /// The dataset sensor it becomes (`imu0`, `lidar0`, `cam0`, `pose0`).
    pub fn sensor(self) -> &'static str {
        match self {
            Role::Imu => "imu0",
            Role::Lidar => "lidar0",
            Role::Camera => "cam0",
            Role::Pose => "pose0",
        }
    }

    /// Message types the role accepts (ROS 1 spelling).
    pub fn types(self) -> &'static [&'static str] {
        match self {
            Role::Imu => &["sensor_msgs/Imu"],
            Role::Lidar => &["sensor_msgs/PointCloud2"],
            Role::Camera => &["sensor_msgs/Image", "sensor_msgs/CompressedImage"],
            Role::Pose => &[
                "nav_msgs/Odometry",
                "geometry_msgs/PoseStamped",
                "geometry_msgs/PoseWithCovarianceStamped",
            ],
        }
    }
}

/// How one role's topic is chosen.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub enum TopicChoice {
    /// The one topic of an accepted type, if there is exactly one (else skipped, warned).
    #[default]
    Auto,
    /// This topic (an error if absent or of another type).
    Topic(String),
    /// Not converted.
    Skip,
}

impl TopicChoice {
    /// `None` -> [`TopicChoice::Auto`], `"none"` -> [`TopicChoice::Skip`], else the topic.
    pub fn from_flag(flag: Option<&str>) -> Self {
        match flag {
            None => TopicChoice::Auto,
            Some("none") => TopicChoice::Skip,
            Some(topic) => TopicChoice::Topic(topic.to_string()),
        }
    }
}

/// The topic choice of every role (`msreg convert --imu T --lidar T --camera T --pose T`).
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct Topics {
    /// `imu0/` from `sensor_msgs/Imu`.
    pub imu: TopicChoice,
    /// `lidar0/` from `sensor_msgs/PointCloud2`.
    pub lidar: TopicChoice,
    /// `cam0/` from `sensor_msgs/Image` or `CompressedImage`.
    pub camera: TopicChoice,
    /// `pose0/` from `nav_msgs/Odometry`, `geometry_msgs/PoseStamped` or
    /// `PoseWithCovarianceStamped`.
    pub pose: TopicChoice,
}

impl Topics {
    /// The choice for `role`.
    pub fn choice(&self, role: Role) -> &TopicChoice {
        match role {
            Role::Imu => &self.imu,
            Role::Lidar => &self.lidar,
            Role::Camera => &self.camera,
            Role::Pose => &self.pose,
        }
    }
}

/// A topic chosen for a role.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Selected {
    /// The role.
    pub role: Role,
    /// The topic.
    pub topic: String,
    /// Its message type (ROS 1 spelling).
    pub msg_type: String,
    /// Its wire format.
    pub dialect: Dialect,
}

/// Resolves every role's choice against the bag's topics.
pub fn select(
    path: &Path,
    infos: &[TopicInfo],
    topics: &Topics,
    warnings: &mut Vec<BagWarning>,
) -> Result<Vec<Selected>, BagError> {
    let mut out = Vec::new();
    for role in Role::ALL {
        let info = match topics.choice(role) {
            TopicChoice::Skip => None,
            TopicChoice::Topic(name) => Some(named(path, infos, role, name)?),
            TopicChoice::Auto => {
                let candidates: Vec<&TopicInfo> = infos
                    .iter()
                    .filter(|t| role.types().contains(&t.msg_type.as_str()))
                    .collect();
                match candidates.as_slice() {
                    [one] => Some(*one),
                    [] => None,
                    many => {
                        warnings.push(BagWarning::AmbiguousTopic {
                            role: role.name(),
                            candidates: many.iter().map(|t| t.topic.clone()).collect(),
                        });
                        None
                    }
                }
            }
        };
        if let Some(info) = info {
            let dialect = info
                .dialect()
                .ok_or_else(|| BagError::UnsupportedEncoding {
                    path: path.to_path_buf(),
                    topic: info.topic.clone(),
                    encoding: info.encoding.clone(),
                    schema_encoding: info.schema_encoding.clone(),
                })?;
            out.push(Selected {
                role,
                topic: info.topic.clone(),
                msg_type: info.msg_type.clone(),
                dialect,
            });
        }
    }
    Ok(out)
}

fn named<'a>(
    path: &Path,
    infos: &'a [TopicInfo],
    role: Role,
    name: &str,
) -> Result<&'a TopicInfo, BagError> {
    let info = infos
        .iter()
        .find(|t| t.topic == name)
        .ok_or_else(|| BagError::TopicNotFound {
            path: path.to_path_buf(),
            topic: name.to_string(),
            available: infos.iter().map(TopicInfo::describe).collect(),
        })?;
    if !role.types().contains(&info.msg_type.as_str()) {
        return Err(BagError::WrongType {
            path: path.to_path_buf(),
            topic: name.to_string(),
            role: role.name(),
            found: info.msg_type.clone(),
            expected: role.types().to_vec(),
        });
    }
    Ok(info)
}
