//! The two container formats behind one interface: a ROS 1 bag (rosbag crate) or an MCAP
//! file (mcap crate), both memory-mapped, listed as topics and streamed as raw messages.

use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;

use memmap2::Mmap;
use rosbag::{ChunkRecord, IndexRecord, MessageRecord, RosBag};

use super::error::BagError;
use super::wire::Dialect;

const ROS1_MAGIC: &[u8] = b"#ROSBAG V2.0\n";
const MCAP_MAGIC: &[u8] = b"\x89MCAP0\r\n";

/// The container format of a recording.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
pub enum BagFormat {
    /// ROS 1 `.bag` (format 2.0).
    Ros1,
    /// MCAP (ROS 2 or any other producer).
    Mcap,
}

/// One topic of a recording.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct TopicInfo {
    /// Topic name.
    pub topic: String,
    /// Message type in ROS 1 spelling (`sensor_msgs/Imu`; ROS 2's `/msg/` removed).
    pub msg_type: String,
    /// Message encoding (`ros1`, `cdr`, or whatever the MCAP channel says).
    pub encoding: String,
    /// Schema encoding (`ros1msg`, `ros2msg`, ...).
    pub schema_encoding: String,
    /// Messages on the topic, when the file's index says.
    pub count: Option<u64>,
}

impl TopicInfo {
    /// The wire format of the topic's messages, if msreg decodes it.
    pub fn dialect(&self) -> Option<Dialect> {
        match self.encoding.as_str() {
            "ros1" => Some(Dialect::Ros1),
            "cdr" => Some(Dialect::Cdr),
            _ => None,
        }
    }

    /// `topic (type)`, for messages.
    pub fn describe(&self) -> String {
        format!("{} ({})", self.topic, self.msg_type)
    }
}

/// `sensor_msgs/msg/Imu` -> `sensor_msgs/Imu`.
pub fn normalise_type(name: &str) -> String {
    name.replace("/msg/", "/")
}

/// An open recording.
pub enum BagFile {
    /// A ROS 1 bag.
    Ros1(RosBag),
    /// A memory-mapped MCAP file.
    Mcap(Mmap),
}

impl std::fmt::Debug for BagFile {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            BagFile::Ros1(_) => "BagFile::Ros1",
            BagFile::Mcap(_) => "BagFile::Mcap",
        })
    }
}

/// What [`BagFile::for_each`] hands over per message: topic, log (receive) time in ns,
/// serialised message.
pub type MessageSink<'s> = dyn FnMut(&str, u64, &[u8]) -> Result<(), BagError> + 's;

impl BagFile {
    /// Opens `path`, telling the format by its magic bytes.
    pub fn open(path: &Path) -> Result<Self, BagError> {
        let io = |source| BagError::Io {
            path: path.to_path_buf(),
            source,
        };
        let file = std::fs::File::open(path).map_err(io)?;
        // SAFETY: the map is read-only and lives as long as `self`; a bag that another
        // process truncates while it is read is outside what msreg supports (as with every
        // memory-mapped reader, the rosbag crate's own included).
        let map = unsafe { Mmap::map(&file) }.map_err(io)?;
        if map.starts_with(ROS1_MAGIC) {
            RosBag::new(path).map(BagFile::Ros1).map_err(io)
        } else if map.starts_with(MCAP_MAGIC) {
            Ok(BagFile::Mcap(map))
        } else {
            Err(BagError::UnknownFormat {
                path: path.to_path_buf(),
            })
        }
    }

    /// The container format.
    pub fn format(&self) -> BagFormat {
        match self {
            BagFile::Ros1(_) => BagFormat::Ros1,
            BagFile::Mcap(_) => BagFormat::Mcap,
        }
    }

    /// Every topic, sorted by name.
    pub fn topics(&self, path: &Path) -> Result<Vec<TopicInfo>, BagError> {
        match self {
            BagFile::Ros1(bag) => ros1_topics(bag, path),
            BagFile::Mcap(map) => mcap_topics(map, path),
        }
    }

    /// Streams every message of the `wanted` topics in file order to `sink`; `progress`
    /// gets the fraction read.
    pub fn for_each(
        &self,
        path: &Path,
        wanted: &BTreeSet<String>,
        sink: &mut MessageSink<'_>,
        progress: &mut dyn FnMut(f64),
    ) -> Result<(), BagError> {
        match self {
            BagFile::Ros1(bag) => ros1_for_each(bag, path, wanted, sink, progress),
            BagFile::Mcap(map) => mcap_for_each(map, path, wanted, sink, progress),
        }
    }
}

fn ros1_error(path: &Path) -> impl Fn(rosbag::Error) -> BagError + '_ {
    move |source| BagError::Ros1 {
        path: path.to_path_buf(),
        source,
    }
}

fn ros1_topics(bag: &RosBag, path: &Path) -> Result<Vec<TopicInfo>, BagError> {
    let mut by_conn: BTreeMap<u32, TopicInfo> = BTreeMap::new();
    let mut counts: BTreeMap<u32, u64> = BTreeMap::new();
    for record in bag.index_records() {
        match record.map_err(ros1_error(path))? {
            IndexRecord::Connection(c) => {
                by_conn.insert(
                    c.id,
                    TopicInfo {
                        topic: c.topic.to_string(),
                        msg_type: c.tp.to_string(),
                        encoding: "ros1".into(),
                        schema_encoding: "ros1msg".into(),
                        count: None,
                    },
                );
            }
            IndexRecord::ChunkInfo(info) => {
                for entry in info.entries() {
                    *counts.entry(entry.conn_id).or_default() += u64::from(entry.count);
                }
            }
            IndexRecord::IndexData(_) => {}
        }
    }
    // Several connections (publishers) may share a topic: merge them.
    let mut by_topic: BTreeMap<String, TopicInfo> = BTreeMap::new();
    for (id, info) in by_conn {
        let n = counts.get(&id).copied().unwrap_or(0);
        by_topic
            .entry(info.topic.clone())
            .and_modify(|t| t.count = Some(t.count.unwrap_or(0) + n))
            .or_insert(TopicInfo {
                count: Some(n),
                ..info
            });
    }
    Ok(by_topic.into_values().collect())
}

fn ros1_for_each(
    bag: &RosBag,
    path: &Path,
    wanted: &BTreeSet<String>,
    sink: &mut MessageSink<'_>,
    progress: &mut dyn FnMut(f64),
) -> Result<(), BagError> {
    let mut topic_of: BTreeMap<u32, String> = BTreeMap::new();
    for record in bag.index_records() {
        if let IndexRecord::Connection(c) = record.map_err(ros1_error(path))? {
            topic_of.insert(c.id, c.topic.to_string());
        }
    }
    let chunks = f64::from(bag.get_chunk_count().max(1));
    let mut done = 0.0;
    for record in bag.chunk_records() {
        let ChunkRecord::Chunk(chunk) = record.map_err(ros1_error(path))? else {
            continue;
        };
        for message in chunk.messages() {
            match message.map_err(ros1_error(path))? {
                MessageRecord::MessageData(m) => {
                    if let Some(topic) = topic_of.get(&m.conn_id).filter(|t| wanted.contains(*t)) {
                        sink(topic, m.time, m.data)?;
                    }
                }
                MessageRecord::Connection(c) => {
                    topic_of.insert(c.id, c.topic.to_string());
                }
            }
        }
        done += 1.0;
        progress((done / chunks).min(1.0));
    }
    Ok(())
}

fn mcap_error(path: &Path) -> impl Fn(mcap::McapError) -> BagError + '_ {
    move |source| BagError::Mcap {
        path: path.to_path_buf(),
        source,
    }
}

fn mcap_topic(channel: &mcap::Channel<'_>, count: Option<u64>) -> TopicInfo {
    let (name, schema_encoding) = channel
        .schema
        .as_ref()
        .map(|s| (normalise_type(&s.name), s.encoding.clone()))
        .unwrap_or_default();
    TopicInfo {
        topic: channel.topic.clone(),
        msg_type: name,
        encoding: channel.message_encoding.clone(),
        schema_encoding,
        count,
    }
}

fn mcap_topics(map: &[u8], path: &Path) -> Result<Vec<TopicInfo>, BagError> {
    let mut by_topic: BTreeMap<String, TopicInfo> = BTreeMap::new();
    if let Some(summary) = mcap::Summary::read(map).map_err(mcap_error(path))? {
        let counts = summary.stats.map(|s| s.channel_message_counts);
        for (id, channel) in &summary.channels {
            let count = counts.as_ref().map(|c| c.get(id).copied().unwrap_or(0));
            by_topic.insert(channel.topic.clone(), mcap_topic(channel, count));
        }
        return Ok(by_topic.into_values().collect());
    }
    // No summary section: one pass over the messages finds the channels.
    for message in mcap::MessageStream::new(map).map_err(mcap_error(path))? {
        let message = message.map_err(mcap_error(path))?;
        let entry = by_topic
            .entry(message.channel.topic.clone())
            .or_insert_with(|| mcap_topic(&message.channel, Some(0)));
        entry.count = entry.count.map(|c| c + 1);
    }
    Ok(by_topic.into_values().collect())
}

fn mcap_for_each(
    map: &[u8],
    path: &Path,
    wanted: &BTreeSet<String>,
    sink: &mut MessageSink<'_>,
    progress: &mut dyn FnMut(f64),
) -> Result<(), BagError> {
    let total = mcap::Summary::read(map)
        .ok()
        .flatten()
        .and_then(|s| s.stats.map(|s| s.message_count))
        .unwrap_or(0)
        .max(1) as f64;
    for (done, message) in mcap::MessageStream::new(map)
        .map_err(mcap_error(path))?
        .enumerate()
    {
        let message = message.map_err(mcap_error(path))?;
        if wanted.contains(&message.channel.topic) {
            sink(&message.channel.topic, message.log_time, &message.data)?;
        }
        if done % 256 == 0 {
            progress((done as f64 / total).min(1.0));
        }
    }
    progress(1.0);
    Ok(())
}
