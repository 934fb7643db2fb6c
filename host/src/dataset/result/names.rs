//! Sensor and section names of a rig: `imuN`, `camN`, `lidarN`, `poseN` and the
//! camera-LiDAR pairs `camN_lidarM` (docs/formats.md sections 2 and 3), and the names of
//! the degrees of freedom a section may list as `held`.

use std::fmt;
use std::str::FromStr;

/// What a sensor is. The order is the order of sections in a result file.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum SensorKind {
    /// A camera, `camN`.
    Camera,
    /// A LiDAR, `lidarN`.
    Lidar,
    /// A generic 6-DoF pose sensor (odometry, motion capture, VO), `poseN`.
    Pose,
    /// An IMU, `imuN`; `imu0` is the reference IMU of every IMU-based extrinsic.
    Imu,
}

impl SensorKind {
    /// Every kind, in section order.
    pub const ALL: [SensorKind; 4] = [Self::Camera, Self::Lidar, Self::Pose, Self::Imu];

    /// The name prefix (`cam`, `lidar`, `pose`, `imu`), also the dataset folder's.
    pub fn prefix(self) -> &'static str {
        match self {
            Self::Camera => "cam",
            Self::Lidar => "lidar",
            Self::Pose => "pose",
            Self::Imu => "imu",
        }
    }
}

/// One sensor of the rig: its kind and index (`cam1`, `lidar0`, ...).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct SensorId {
    /// What the sensor is.
    pub kind: SensorKind,
    /// Its index among the sensors of its kind.
    pub index: u16,
}

impl SensorId {
    /// `camN`.
    pub const fn cam(index: u16) -> Self {
        Self {
            kind: SensorKind::Camera,
            index,
        }
    }
    /// `lidarN`.
    pub const fn lidar(index: u16) -> Self {
        Self {
            kind: SensorKind::Lidar,
            index,
        }
    }
    /// `poseN`.
    pub const fn pose(index: u16) -> Self {
        Self {
            kind: SensorKind::Pose,
            index,
        }
    }
    /// `imuN`.
    pub const fn imu(index: u16) -> Self {
        Self {
            kind: SensorKind::Imu,
            index,
        }
    }
}

impl fmt::Display for SensorId {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}{}", self.kind.prefix(), self.index)
    }
}

/// A name that is not `imuN`, `camN`, `lidarN`, `poseN` or `camN_lidarM`.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("`{0}` is not a sensor or section name (imuN, camN, lidarN, poseN, camN_lidarM)")]
pub struct BadName(pub String);

impl FromStr for SensorId {
    type Err = BadName;

    fn from_str(s: &str) -> Result<Self, BadName> {
        SensorKind::ALL
            .iter()
            .find_map(|&kind| {
                let digits = s.strip_prefix(kind.prefix())?;
                let canonical = !digits.is_empty()
                    && digits.bytes().all(|b| b.is_ascii_digit())
                    && (digits == "0" || !digits.starts_with('0'));
                let index = canonical.then(|| digits.parse().ok()).flatten()?;
                Some(SensorId { kind, index })
            })
            .ok_or_else(|| BadName(s.to_string()))
    }
}

/// The name of one section of a result file: a sensor, or a camera-LiDAR pair.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum SectionName {
    /// `camN`, `lidarN`, `poseN` or `imuN`.
    Sensor(SensorId),
    /// `camN_lidarM`: a target-based or targetless LiDAR-camera result, `T_cam_lidar`.
    CameraLidar {
        /// The camera's index N.
        cam: u16,
        /// The LiDAR's index M.
        lidar: u16,
    },
}

impl SectionName {
    /// `cam0`.
    pub const CAM0: SectionName = SectionName::Sensor(SensorId::cam(0));
    /// `lidar0`.
    pub const LIDAR0: SectionName = SectionName::Sensor(SensorId::lidar(0));
    /// `pose0`.
    pub const POSE0: SectionName = SectionName::Sensor(SensorId::pose(0));
    /// `cam0_lidar0`.
    pub const CAM0_LIDAR0: SectionName = SectionName::CameraLidar { cam: 0, lidar: 0 };

    /// The section of one sensor.
    pub const fn sensor(id: SensorId) -> Self {
        SectionName::Sensor(id)
    }

    /// `camN`.
    pub const fn cam(index: u16) -> Self {
        SectionName::Sensor(SensorId::cam(index))
    }

    /// `lidarN`.
    pub const fn lidar(index: u16) -> Self {
        SectionName::Sensor(SensorId::lidar(index))
    }

    /// `poseN`.
    pub const fn pose(index: u16) -> Self {
        SectionName::Sensor(SensorId::pose(index))
    }

    /// `imuN`.
    pub const fn imu(index: u16) -> Self {
        SectionName::Sensor(SensorId::imu(index))
    }

    /// The section's own transform key and what it means, with its time-shift key
    /// (`None`: no extrinsic in this section, as for the reference IMU `imu0`).
    pub fn keys(&self) -> Option<ExtrinsicKeys> {
        let keys = |transform, timeshift, meaning| {
            Some(ExtrinsicKeys {
                transform,
                timeshift,
                meaning,
            })
        };
        match *self {
            SectionName::CameraLidar { .. } => {
                keys("T_cam_lidar", None, "p_cam = T_cam_lidar * p_lidar")
            }
            SectionName::Sensor(id) => match id.kind {
                SensorKind::Camera => keys(
                    "T_cam_imu",
                    Some("timeshift_cam_imu"),
                    "p_cam = T_cam_imu * p_imu0",
                ),
                SensorKind::Lidar => keys(
                    "T_imu_lidar",
                    Some("timeshift_lidar_imu"),
                    "p_imu0 = T_imu_lidar * p_lidar",
                ),
                SensorKind::Pose => keys(
                    "T_imu_pose",
                    Some("timeshift_pose_imu"),
                    "p_imu0 = T_imu_pose * p_pose",
                ),
                SensorKind::Imu if id.index == 0 => None,
                SensorKind::Imu => keys(
                    "T_imu0_imu",
                    Some("timeshift_imu_imu0"),
                    "p_imu0 = T_imu0_imu * p_imu",
                ),
            },
        }
    }

    /// The sensor, for a sensor section.
    pub fn sensor_id(&self) -> Option<SensorId> {
        match *self {
            SectionName::Sensor(id) => Some(id),
            SectionName::CameraLidar { .. } => None,
        }
    }

    /// True for `camN` with N >= 1: the section may carry Kalibr's `T_cn_cnm1`.
    pub fn has_camera_chain(&self) -> bool {
        matches!(self, SectionName::Sensor(SensorId { kind: SensorKind::Camera, index }) if *index >= 1)
    }
}

/// The keys of a section's extrinsic.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ExtrinsicKeys {
    /// The transform's key (`T_cam_imu`, `T_imu_lidar`, ...).
    pub transform: &'static str,
    /// The time shift's key, where the section has one.
    pub timeshift: Option<&'static str>,
    /// What the transform maps, for the comment beside it.
    pub meaning: &'static str,
}

/// Every transform key a section may carry, for telling a misplaced one from an unknown one.
pub(super) const TRANSFORM_KEYS: [&str; 5] = [
    "T_cam_imu",
    "T_imu_lidar",
    "T_imu_pose",
    "T_imu0_imu",
    "T_cam_lidar",
];

impl fmt::Display for SectionName {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            SectionName::Sensor(id) => id.fmt(f),
            SectionName::CameraLidar { cam, lidar } => write!(f, "cam{cam}_lidar{lidar}"),
        }
    }
}

impl FromStr for SectionName {
    type Err = BadName;

    fn from_str(s: &str) -> Result<Self, BadName> {
        let bad = || BadName(s.to_string());
        if let Some((cam, lidar)) = s.split_once('_') {
            let (cam, lidar) = (cam.parse::<SensorId>(), lidar.parse::<SensorId>());
            return match (cam, lidar) {
                (Ok(c), Ok(l)) if c.kind == SensorKind::Camera && l.kind == SensorKind::Lidar => {
                    Ok(SectionName::CameraLidar {
                        cam: c.index,
                        lidar: l.index,
                    })
                }
                _ => Err(bad()),
            };
        }
        s.parse().map(SectionName::Sensor)
    }
}

/// A degree of freedom a section may list as `held` (at its prior, not determined by the
/// data): `rotation_x|y|z`, `translation_x|y|z`, `timeshift`, `intrinsics`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Dof {
    /// Rotation about the x axis (the rotation vector's first component).
    RotationX,
    /// Rotation about the y axis.
    RotationY,
    /// Rotation about the z axis.
    RotationZ,
    /// Translation along x.
    TranslationX,
    /// Translation along y.
    TranslationY,
    /// Translation along z.
    TranslationZ,
    /// The time shift.
    Timeshift,
    /// The camera intrinsics.
    Intrinsics,
}

impl Dof {
    /// Every name, in the order of the enum.
    pub const ALL: [Dof; 8] = [
        Dof::RotationX,
        Dof::RotationY,
        Dof::RotationZ,
        Dof::TranslationX,
        Dof::TranslationY,
        Dof::TranslationZ,
        Dof::Timeshift,
        Dof::Intrinsics,
    ];

    /// The name written in `held:`.
    pub fn as_str(self) -> &'static str {
        match self {
            Dof::RotationX => "rotation_x",
            Dof::RotationY => "rotation_y",
            Dof::RotationZ => "rotation_z",
            Dof::TranslationX => "translation_x",
            Dof::TranslationY => "translation_y",
            Dof::TranslationZ => "translation_z",
            Dof::Timeshift => "timeshift",
            Dof::Intrinsics => "intrinsics",
        }
    }

    /// The extrinsic DoF of tangent-space index `i` (`[rotation; translation]`, 0..6).
    pub fn extrinsic(i: usize) -> Option<Dof> {
        Self::ALL.get(i).copied().filter(|_| i < 6)
    }
}

impl FromStr for Dof {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, String> {
        Self::ALL
            .into_iter()
            .find(|d| d.as_str() == s)
            .ok_or_else(|| {
                let names: Vec<&str> = Self::ALL.iter().map(|d| d.as_str()).collect();
                format!("`{s}` is not a degree of freedom ({})", names.join(", "))
            })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_round_trip_and_bad_names_are_refused() {
        for s in [
            "cam0",
            "cam12",
            "lidar3",
            "pose1",
            "imu0",
            "imu2",
            "cam1_lidar0",
        ] {
            let name: SectionName = s.parse().expect(s);
            assert_eq!(name.to_string(), s);
        }
        for s in [
            "cam",
            "cam01",
            "camera0",
            "lidar0_cam0",
            "cam0_pose1",
            "pose-1",
            "",
            "imu0x",
        ] {
            assert!(s.parse::<SectionName>().is_err(), "{s}");
        }
        assert_eq!(SectionName::imu(0).keys(), None);
        assert_eq!(
            SectionName::imu(1).keys().map(|k| k.transform),
            Some("T_imu0_imu")
        );
        assert!(SectionName::cam(1).has_camera_chain() && !SectionName::CAM0.has_camera_chain());
        let mut sorted = [
            SectionName::CAM0_LIDAR0,
            SectionName::pose(0),
            SectionName::cam(1),
            SectionName::imu(1),
            SectionName::LIDAR0,
            SectionName::CAM0,
        ];
        sorted.sort();
        let names: Vec<String> = sorted.iter().map(ToString::to_string).collect();
        assert_eq!(
            names,
            ["cam0", "cam1", "lidar0", "pose0", "imu1", "cam0_lidar0"]
        );
    }

    #[test]
    fn dof_names_round_trip() {
        for d in Dof::ALL {
            assert_eq!(d.as_str().parse::<Dof>(), Ok(d));
        }
        assert!("rotation_w".parse::<Dof>().is_err());
        assert_eq!(Dof::extrinsic(5), Some(Dof::TranslationZ));
        assert_eq!(Dof::extrinsic(6), None);
    }
}
