//! The messages msreg converts, decoded by hand from either wire format ([`WireReader`]):
//! field order as in the `.msg` definitions of `sensor_msgs`, `nav_msgs`, `geometry_msgs`
//! (identical in ROS 1 and ROS 2 apart from `Header`).

use nalgebra::{Quaternion, Vector3};

use super::error::DecodeError;
use super::wire::{Header, WireReader};

/// `sensor_msgs/Imu`.
#[derive(Debug, Clone, PartialEq)]
pub struct ImuMsg {
    /// Header (stamp = sample time, frame_id = IMU frame).
    pub header: Header,
    /// Orientation estimate `(w, x, y, z)` (not used by msreg).
    pub orientation: Quaternion<f64>,
    /// Row-major 3x3; element 0 = -1 means "no orientation".
    pub orientation_covariance: [f64; 9],
    /// rad/s.
    pub angular_velocity: Vector3<f64>,
    /// Row-major 3x3 (rad/s)^2; 0 = unknown, element 0 = -1 means "no gyro".
    pub angular_velocity_covariance: [f64; 9],
    /// m/s^2 (specific force).
    pub linear_acceleration: Vector3<f64>,
    /// Row-major 3x3 (m/s^2)^2; 0 = unknown, element 0 = -1 means "no accelerometer".
    pub linear_acceleration_covariance: [f64; 9],
}

/// `geometry_msgs/Pose`: position and Hamilton orientation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PoseMsg {
    /// m.
    pub position: Vector3<f64>,
    /// `(w, x, y, z)` as stored (not normalised).
    pub orientation: Quaternion<f64>,
}

/// A pose message of any of the pose types: `nav_msgs/Odometry`,
/// `geometry_msgs/PoseStamped`, `geometry_msgs/PoseWithCovarianceStamped`.
#[derive(Debug, Clone, PartialEq)]
pub struct StampedPose {
    /// Header (frame_id = the odometry frame).
    pub header: Header,
    /// Odometry's `child_frame_id` (the moving frame), empty for the other types.
    pub child_frame_id: String,
    /// `T_frame_child`.
    pub pose: PoseMsg,
}

/// `sensor_msgs/PointField`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct PointField {
    /// Field name.
    pub name: String,
    /// Byte offset in the point.
    pub offset: u32,
    /// 1 INT8, 2 UINT8, 3 INT16, 4 UINT16, 5 INT32, 6 UINT32, 7 FLOAT32, 8 FLOAT64.
    pub datatype: u8,
    /// Elements.
    pub count: u32,
}

/// `sensor_msgs/PointCloud2`, data borrowed from the bag.
#[derive(Debug, Clone, PartialEq)]
pub struct PointCloud2Msg<'a> {
    /// Header (stamp: the driver's scan stamp).
    pub header: Header,
    /// Rows (1 = unorganised).
    pub height: u32,
    /// Points per row.
    pub width: u32,
    /// Point layout.
    pub fields: Vec<PointField>,
    /// Multi-byte values big-endian.
    pub is_bigendian: bool,
    /// Bytes per point.
    pub point_step: u32,
    /// Bytes per row.
    pub row_step: u32,
    /// The points.
    pub data: &'a [u8],
}

/// `sensor_msgs/Image`, data borrowed from the bag.
#[derive(Debug, Clone, PartialEq)]
pub struct ImageMsg<'a> {
    /// Header (stamp = exposure time).
    pub header: Header,
    /// Rows.
    pub height: u32,
    /// Columns.
    pub width: u32,
    /// Pixel encoding (`mono8`, `rgb8`, ...).
    pub encoding: String,
    /// Multi-byte pixels big-endian.
    pub is_bigendian: bool,
    /// Bytes per row.
    pub step: u32,
    /// Pixels.
    pub data: &'a [u8],
}

/// `sensor_msgs/CompressedImage`, data borrowed from the bag.
#[derive(Debug, Clone, PartialEq)]
pub struct CompressedImageMsg<'a> {
    /// Header.
    pub header: Header,
    /// `jpeg`, `png`, or image_transport's `"<encoding>; jpeg compressed <encoding>"`.
    pub format: String,
    /// The compressed file.
    pub data: &'a [u8],
}

fn vector3(r: &mut WireReader<'_>) -> Result<Vector3<f64>, DecodeError> {
    let [x, y, z] = r.f64s::<3>()?;
    Ok(Vector3::new(x, y, z))
}

fn quaternion(r: &mut WireReader<'_>) -> Result<Quaternion<f64>, DecodeError> {
    let [x, y, z, w] = r.f64s::<4>()?;
    Ok(Quaternion::new(w, x, y, z))
}

fn pose(r: &mut WireReader<'_>) -> Result<PoseMsg, DecodeError> {
    Ok(PoseMsg {
        position: vector3(r)?,
        orientation: quaternion(r)?,
    })
}

impl ImuMsg {
    /// Decodes a `sensor_msgs/Imu`.
    pub fn decode(r: &mut WireReader<'_>) -> Result<Self, DecodeError> {
        Ok(Self {
            header: r.header()?,
            orientation: quaternion(r)?,
            orientation_covariance: r.f64s()?,
            angular_velocity: vector3(r)?,
            angular_velocity_covariance: r.f64s()?,
            linear_acceleration: vector3(r)?,
            linear_acceleration_covariance: r.f64s()?,
        })
    }
}

impl StampedPose {
    /// Decodes `nav_msgs/Odometry` (pose part; the twist is not read).
    pub fn decode_odometry(r: &mut WireReader<'_>) -> Result<Self, DecodeError> {
        let header = r.header()?;
        let child_frame_id = r.string()?;
        Ok(Self {
            header,
            child_frame_id,
            pose: pose(r)?,
        })
    }

    /// Decodes `geometry_msgs/PoseStamped` or `PoseWithCovarianceStamped` (covariance
    /// not read).
    pub fn decode_pose_stamped(r: &mut WireReader<'_>) -> Result<Self, DecodeError> {
        Ok(Self {
            header: r.header()?,
            child_frame_id: String::new(),
            pose: pose(r)?,
        })
    }
}

impl<'a> PointCloud2Msg<'a> {
    /// Decodes a `sensor_msgs/PointCloud2`.
    pub fn decode(r: &mut WireReader<'a>) -> Result<Self, DecodeError> {
        let header = r.header()?;
        let height = r.u32()?;
        let width = r.u32()?;
        let n = r.seq_len()?;
        let mut fields = Vec::with_capacity(n.min(64));
        for _ in 0..n {
            fields.push(PointField {
                name: r.string()?,
                offset: r.u32()?,
                datatype: r.u8()?,
                count: r.u32()?,
            });
        }
        Ok(Self {
            header,
            height,
            width,
            fields,
            is_bigendian: r.u8()? != 0,
            point_step: r.u32()?,
            row_step: r.u32()?,
            data: r.bytes()?,
        })
    }
}

impl<'a> ImageMsg<'a> {
    /// Decodes a `sensor_msgs/Image`.
    pub fn decode(r: &mut WireReader<'a>) -> Result<Self, DecodeError> {
        Ok(Self {
            header: r.header()?,
            height: r.u32()?,
            width: r.u32()?,
            encoding: r.string()?,
            is_bigendian: r.u8()? != 0,
            step: r.u32()?,
            data: r.bytes()?,
        })
    }
}

impl<'a> CompressedImageMsg<'a> {
    /// Decodes a `sensor_msgs/CompressedImage`.
    pub fn decode(r: &mut WireReader<'a>) -> Result<Self, DecodeError> {
        Ok(Self {
            header: r.header()?,
            format: r.string()?,
            data: r.bytes()?,
        })
    }
}
