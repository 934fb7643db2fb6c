//! The error type of bag reading and conversion. Every variant names the bag (and the topic
//! and message index where there is one), so a user can find the offending record.

use std::path::PathBuf;

use crate::dataset::DatasetError;
use crate::pointcloud::PcdError;

/// Why a bag could not be read or converted.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum BagError {
    /// The file could not be opened or mapped.
    #[error("{}: {source}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// The underlying error.
        source: std::io::Error,
    },
    /// Neither a ROS 1 bag (`#ROSBAG V2.0`) nor an MCAP file (`\x89MCAP0`).
    #[error("{}: neither a ROS 1 bag (#ROSBAG V2.0) nor an MCAP file", path.display())]
    UnknownFormat {
        /// The file.
        path: PathBuf,
    },
    /// The ROS 1 bag structure is damaged.
    #[error("{}: ROS 1 bag: {source}", path.display())]
    Ros1 {
        /// The bag.
        path: PathBuf,
        /// The rosbag crate's error.
        source: rosbag::Error,
    },
    /// The MCAP structure is damaged.
    #[error("{}: MCAP: {source}", path.display())]
    Mcap {
        /// The file.
        path: PathBuf,
        /// The mcap crate's error.
        source: mcap::McapError,
    },
    /// A chosen topic's messages are in an encoding msreg does not decode
    /// (it decodes `ros1` and `cdr`).
    #[error(
        "{}: topic {topic}: message encoding `{encoding}` (schema encoding `{schema_encoding}`) \
         is not supported; msreg decodes ROS 1 (`ros1`) and ROS 2 CDR (`cdr`)",
        path.display()
    )]
    UnsupportedEncoding {
        /// The bag.
        path: PathBuf,
        /// The topic.
        topic: String,
        /// The channel's message encoding.
        encoding: String,
        /// The schema's encoding.
        schema_encoding: String,
    },
    /// A topic named on the command line is not in the bag.
    #[error("{}: no topic {topic}; the bag has: {}", path.display(), available.join(", "))]
    TopicNotFound {
        /// The bag.
        path: PathBuf,
        /// The topic asked for.
        topic: String,
        /// Every topic with its type.
        available: Vec<String>,
    },
    /// A topic named for a role carries a message type that role cannot use.
    #[error(
        "{}: topic {topic} is {found}, which cannot be the {role} (expected one of: {})",
        path.display(),
        expected.join(", ")
    )]
    WrongType {
        /// The bag.
        path: PathBuf,
        /// The topic.
        topic: String,
        /// The role (imu, lidar, camera, pose).
        role: &'static str,
        /// The topic's message type.
        found: String,
        /// The types the role accepts.
        expected: Vec<&'static str>,
    },
    /// A message could not be decoded.
    #[error("{}: topic {topic}, message {index}: {source}", path.display())]
    Decode {
        /// The bag.
        path: PathBuf,
        /// The topic.
        topic: String,
        /// 0-based index of the message on its topic.
        index: usize,
        /// What was wrong.
        source: DecodeError,
    },
    /// Nothing to convert: no topic chosen or auto-detected.
    #[error("{}: no IMU, LiDAR, camera or pose topic chosen or found; the bag has: {}", path.display(), available.join(", "))]
    NothingToConvert {
        /// The bag.
        path: PathBuf,
        /// Every topic with its type.
        available: Vec<String>,
    },
    /// Writing the dataset failed.
    #[error(transparent)]
    Dataset(#[from] DatasetError),
    /// Writing a PCD file failed.
    #[error(transparent)]
    Pcd(#[from] PcdError),
    /// Writing or decoding an image failed.
    #[error("{}: {source}", path.display())]
    Image {
        /// The image file being written, or the bag.
        path: PathBuf,
        /// The image crate's error.
        source: image::ImageError,
    },
}

/// Why one message could not be decoded.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum DecodeError {
    /// The message ends before a field.
    #[error("truncated: needs {need} bytes at offset {at}, has {len}")]
    Truncated {
        /// Byte offset of the field.
        at: usize,
        /// Bytes the field needs.
        need: usize,
        /// Message length.
        len: usize,
    },
    /// A string that is not UTF-8 (or, in CDR, lacks its terminating NUL).
    #[error("malformed string at offset {at}")]
    BadString {
        /// Byte offset of the string.
        at: usize,
    },
    /// A CDR encapsulation other than plain CDR / XCDR2 (little or big endian).
    #[error("unsupported CDR representation 0x{id:04x} (supported: CDR_LE/BE, CDR2_LE/BE)")]
    CdrRepresentation {
        /// The representation identifier of the encapsulation header.
        id: u16,
    },
    /// A `PointCloud2` without float `x`, `y`, `z` fields.
    #[error("PointCloud2 has no FLOAT32/FLOAT64 x, y, z fields")]
    NoXyz,
    /// A `PointField` datatype outside 1..=8.
    #[error("PointField {name}: unknown datatype {datatype}")]
    PointFieldType {
        /// The field.
        name: String,
        /// Its datatype code.
        datatype: u8,
    },
    /// Point or image data shorter than its declared geometry.
    #[error("data has {len} bytes, geometry needs {need}")]
    DataSize {
        /// Bytes present.
        len: usize,
        /// Bytes the geometry needs.
        need: usize,
    },
    /// A `sensor_msgs/Image` encoding msreg does not convert.
    #[error("image encoding `{encoding}` is not supported (mono8, mono16, rgb8, bgr8, rgba8, bgra8, 8UC1, 8UC3, 16UC1)")]
    ImageEncoding {
        /// The encoding.
        encoding: String,
    },
    /// A `sensor_msgs/CompressedImage` format that is neither JPEG nor PNG.
    #[error("compressed image format `{format}` is not supported (jpeg, png)")]
    CompressedFormat {
        /// The format.
        format: String,
    },
    /// The image payload did not decode.
    #[error("image payload: {source}")]
    ImagePayload {
        /// The image decoder's error.
        source: image::ImageError,
    },
}
