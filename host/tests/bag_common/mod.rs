//! Test-side writers of bags: a field-by-field encoder of the ROS 1 wire format and CDR
//! (the mirror of `msreg_host::bag::wire`, written independently from the message
//! definitions), the messages the converter reads, an MCAP writer (the mcap crate's) and a
//! hand-rolled ROS 1 bag writer (format 2.0, uncompressed chunks, with the index section
//! the rosbag crate reads).
#![allow(dead_code)]

use std::collections::BTreeMap;
use std::path::Path;

use msreg_host::bag::wire::Dialect;
use msreg_host::dataset::{ImuRecord, PoseRecord};
use msreg_host::pointcloud::PointCloud;

/// Encodes fields in one dialect.
pub struct WireWriter {
    pub buf: Vec<u8>,
    dialect: Dialect,
}

impl WireWriter {
    pub fn new(dialect: Dialect) -> Self {
        let buf = match dialect {
            Dialect::Cdr => vec![0x00, 0x01, 0x00, 0x00], // CDR_LE, options 0
            Dialect::Ros1 => Vec::new(),
        };
        Self { buf, dialect }
    }

    fn align(&mut self, n: usize) {
        if self.dialect == Dialect::Cdr {
            while (self.buf.len() - 4) % n != 0 {
                self.buf.push(0);
            }
        }
    }

    pub fn u8(&mut self, v: u8) {
        self.buf.push(v);
    }

    pub fn u32(&mut self, v: u32) {
        self.align(4);
        self.buf.extend_from_slice(&v.to_le_bytes());
    }

    pub fn f64(&mut self, v: f64) {
        self.align(8);
        self.buf.extend_from_slice(&v.to_le_bytes());
    }

    pub fn string(&mut self, s: &str) {
        match self.dialect {
            Dialect::Cdr => {
                self.u32(s.len() as u32 + 1);
                self.buf.extend_from_slice(s.as_bytes());
                self.buf.push(0);
            }
            Dialect::Ros1 => {
                self.u32(s.len() as u32);
                self.buf.extend_from_slice(s.as_bytes());
            }
        }
    }

    pub fn bytes(&mut self, b: &[u8]) {
        self.u32(b.len() as u32);
        self.buf.extend_from_slice(b);
    }

    pub fn header(&mut self, seq: u32, stamp_ns: u64, frame_id: &str) {
        if self.dialect == Dialect::Ros1 {
            self.u32(seq);
        }
        self.u32((stamp_ns / 1_000_000_000) as u32);
        self.u32((stamp_ns % 1_000_000_000) as u32);
        self.string(frame_id);
    }
}

/// `sensor_msgs/Imu` with the given covariance diagonals.
pub fn imu_msg(d: Dialect, seq: u32, r: &ImuRecord, frame: &str, cov: [f64; 2]) -> Vec<u8> {
    let mut w = WireWriter::new(d);
    w.header(seq, r.stamp_ns, frame);
    for v in [0.0, 0.0, 0.0, 1.0] {
        w.f64(v);
    }
    for i in 0..9 {
        w.f64(if i == 0 { -1.0 } else { 0.0 });
    }
    for (v, c) in [(r.gyro, cov[0]), (r.accel, cov[1])] {
        for x in v.iter() {
            w.f64(*x);
        }
        for i in 0..9 {
            w.f64(if i % 4 == 0 { c } else { 0.0 });
        }
    }
    w.buf
}

/// `nav_msgs/Odometry` with a zero twist.
pub fn odometry_msg(d: Dialect, seq: u32, p: &PoseRecord, frame: &str, child: &str) -> Vec<u8> {
    let mut w = WireWriter::new(d);
    w.header(seq, p.stamp_ns, frame);
    w.string(child);
    for x in p.position.iter() {
        w.f64(*x);
    }
    let q = p.rotation.quaternion();
    for v in [q.i, q.j, q.k, q.w] {
        w.f64(v);
    }
    for _ in 0..36 + 6 + 36 {
        w.f64(0.0);
    }
    w.buf
}

/// `geometry_msgs/PoseStamped`.
pub fn pose_stamped_msg(d: Dialect, seq: u32, p: &PoseRecord, frame: &str) -> Vec<u8> {
    let mut w = WireWriter::new(d);
    w.header(seq, p.stamp_ns, frame);
    for x in p.position.iter() {
        w.f64(*x);
    }
    let q = p.rotation.quaternion();
    for v in [q.i, q.j, q.k, q.w] {
        w.f64(v);
    }
    w.buf
}

/// `sensor_msgs/Image` `mono8` of `pixels` (`width` per row), rows padded to `step`.
pub fn mono8_image_msg(
    d: Dialect,
    stamp_ns: u64,
    frame: &str,
    (width, step): (u32, u32),
    pixels: &[u8],
) -> Vec<u8> {
    let mut w = WireWriter::new(d);
    w.header(0, stamp_ns, frame);
    let height = pixels.len() as u32 / width;
    w.u32(height);
    w.u32(width);
    w.string("mono8");
    w.u8(0);
    w.u32(step);
    let mut data = Vec::new();
    for row in pixels.chunks(width as usize) {
        data.extend_from_slice(row);
        data.resize(data.len() + (step - width) as usize, 0xEE);
    }
    w.bytes(&data);
    w.buf
}

/// A `PointField` list entry.
fn point_field(w: &mut WireWriter, name: &str, offset: u32, datatype: u8) {
    w.string(name);
    w.u32(offset);
    w.u8(datatype);
    w.u32(1);
}

/// `sensor_msgs/PointCloud2` with the PCD fields: x y z intensity (FLOAT32), t (UINT32 ns
/// from the header stamp), ring (UINT16); unorganised, little-endian, 22-byte points.
pub fn cloud_msg(d: Dialect, seq: u32, stamp_ns: u64, frame: &str, cloud: &PointCloud) -> Vec<u8> {
    let mut w = WireWriter::new(d);
    w.header(seq, stamp_ns, frame);
    w.u32(1);
    w.u32(cloud.points.len() as u32);
    w.u32(6);
    for (name, offset, datatype) in [
        ("x", 0, 7),
        ("y", 4, 7),
        ("z", 8, 7),
        ("intensity", 12, 7),
        ("t", 16, 6),
        ("ring", 20, 4),
    ] {
        point_field(&mut w, name, offset, datatype);
    }
    w.u8(0);
    w.u32(22);
    w.u32(22 * cloud.points.len() as u32);
    let mut data = Vec::with_capacity(22 * cloud.points.len());
    for p in &cloud.points {
        for c in p.xyz.iter() {
            data.extend_from_slice(&(*c as f32).to_le_bytes());
        }
        data.extend_from_slice(&p.intensity.to_le_bytes());
        data.extend_from_slice(&p.t_ns.to_le_bytes());
        data.extend_from_slice(&p.ring.to_le_bytes());
    }
    w.bytes(&data);
    w.u8(1);
    w.buf
}

/// One message to write: topic, ROS 1 type name, log time, bytes.
pub struct Recorded {
    pub topic: String,
    pub msg_type: String,
    pub log_time_ns: u64,
    pub data: Vec<u8>,
}

/// Writes `messages` (in the given order) as an MCAP file with `message_encoding` (`cdr`
/// with `ros2msg` schemas, named `pkg/msg/Type`).
pub fn write_mcap(path: &Path, messages: &[Recorded], message_encoding: &str) {
    let file = std::io::BufWriter::new(std::fs::File::create(path).expect("create mcap"));
    let mut writer = mcap::Writer::new(file).expect("mcap writer");
    let mut channels: BTreeMap<String, u16> = BTreeMap::new();
    for (seq, m) in messages.iter().enumerate() {
        let channel = match channels.get(&m.topic) {
            Some(&id) => id,
            None => {
                let schema_name = m.msg_type.replacen('/', "/msg/", 1);
                let schema = writer
                    .add_schema(&schema_name, "ros2msg", b"")
                    .expect("schema");
                let id = writer
                    .add_channel(schema, &m.topic, message_encoding, &BTreeMap::new())
                    .expect("channel");
                channels.insert(m.topic.clone(), id);
                id
            }
        };
        let header = mcap::records::MessageHeader {
            channel_id: channel,
            sequence: seq as u32,
            log_time: m.log_time_ns,
            publish_time: m.log_time_ns,
        };
        writer
            .write_to_known_channel(&header, &m.data)
            .expect("write message");
    }
    writer.finish().expect("finish mcap");
}

fn field(buf: &mut Vec<u8>, name: &str, value: &[u8]) {
    buf.extend_from_slice(&((name.len() + 1 + value.len()) as u32).to_le_bytes());
    buf.extend_from_slice(name.as_bytes());
    buf.push(b'=');
    buf.extend_from_slice(value);
}

/// A record: header length, header fields, data length, data.
fn record(out: &mut Vec<u8>, fields: &[(&str, Vec<u8>)], data: &[u8]) {
    let mut header = Vec::new();
    for (name, value) in fields {
        field(&mut header, name, value);
    }
    out.extend_from_slice(&(header.len() as u32).to_le_bytes());
    out.extend_from_slice(&header);
    out.extend_from_slice(&(data.len() as u32).to_le_bytes());
    out.extend_from_slice(data);
}

fn time_bytes(ns: u64) -> Vec<u8> {
    let mut v = ((ns / 1_000_000_000) as u32).to_le_bytes().to_vec();
    v.extend_from_slice(&((ns % 1_000_000_000) as u32).to_le_bytes());
    v
}

fn connection(out: &mut Vec<u8>, id: u32, topic: &str, msg_type: &str) {
    let mut data = Vec::new();
    field(&mut data, "topic", topic.as_bytes());
    field(&mut data, "type", msg_type.as_bytes());
    field(&mut data, "md5sum", b"00000000000000000000000000000000");
    field(&mut data, "message_definition", b"");
    record(
        out,
        &[
            ("op", vec![0x07]),
            ("conn", id.to_le_bytes().to_vec()),
            ("topic", topic.as_bytes().to_vec()),
        ],
        &data,
    );
}

/// Connections (topic, type) in order of first appearance.
fn connections(messages: &[Recorded]) -> Vec<(String, String)> {
    let mut conns: Vec<(String, String)> = Vec::new();
    for m in messages {
        if !conns.iter().any(|(t, _)| *t == m.topic) {
            conns.push((m.topic.clone(), m.msg_type.clone()));
        }
    }
    conns
}

/// Per-connection index entries: (time, offset in the chunk data).
type ChunkIndex = BTreeMap<u32, Vec<(u64, u32)>>;

/// The chunk data (connections, then messages) and its index.
fn chunk_data(conns: &[(String, String)], messages: &[Recorded]) -> (Vec<u8>, ChunkIndex) {
    let conn_id = |topic: &str| conns.iter().position(|(t, _)| t == topic).unwrap_or(0) as u32;
    let mut chunk = Vec::new();
    for (id, (topic, ty)) in conns.iter().enumerate() {
        connection(&mut chunk, id as u32, topic, ty);
    }
    let mut index = ChunkIndex::new();
    for m in messages {
        let id = conn_id(&m.topic);
        index
            .entry(id)
            .or_default()
            .push((m.log_time_ns, chunk.len() as u32));
        record(
            &mut chunk,
            &[
                ("op", vec![0x02]),
                ("conn", id.to_le_bytes().to_vec()),
                ("time", time_bytes(m.log_time_ns)),
            ],
            &m.data,
        );
    }
    (chunk, index)
}

/// The chunk record followed by its index-data records.
fn chunk_section(chunk: &[u8], index: &ChunkIndex) -> Vec<u8> {
    let mut body = Vec::new();
    record(
        &mut body,
        &[
            ("op", vec![0x05]),
            ("compression", b"none".to_vec()),
            ("size", (chunk.len() as u32).to_le_bytes().to_vec()),
        ],
        chunk,
    );
    for (id, entries) in index {
        let mut data = Vec::new();
        for (t, off) in entries {
            data.extend_from_slice(&time_bytes(*t));
            data.extend_from_slice(&off.to_le_bytes());
        }
        record(
            &mut body,
            &[
                ("op", vec![0x04]),
                ("ver", 1u32.to_le_bytes().to_vec()),
                ("conn", id.to_le_bytes().to_vec()),
                ("count", (entries.len() as u32).to_le_bytes().to_vec()),
            ],
            &data,
        );
    }
    body
}

/// The index section: connections and one chunk-info record.
fn index_section(
    conns: &[(String, String)],
    index: &ChunkIndex,
    chunk_pos: u64,
    (start, end): (u64, u64),
) -> Vec<u8> {
    let mut out = Vec::new();
    for (id, (topic, ty)) in conns.iter().enumerate() {
        connection(&mut out, id as u32, topic, ty);
    }
    let mut info = Vec::new();
    for (id, entries) in index {
        info.extend_from_slice(&id.to_le_bytes());
        info.extend_from_slice(&(entries.len() as u32).to_le_bytes());
    }
    record(
        &mut out,
        &[
            ("op", vec![0x06]),
            ("ver", 1u32.to_le_bytes().to_vec()),
            ("chunk_pos", chunk_pos.to_le_bytes().to_vec()),
            ("start_time", time_bytes(start)),
            ("end_time", time_bytes(end)),
            ("count", (index.len() as u32).to_le_bytes().to_vec()),
        ],
        &info,
    );
    out
}

/// Writes `messages` as a ROS 1 bag (format 2.0) with one uncompressed chunk.
pub fn write_ros1_bag(path: &Path, messages: &[Recorded]) {
    let conns = connections(messages);
    let (chunk, index) = chunk_data(&conns, messages);
    let body = chunk_section(&chunk, &index);
    let start = messages.iter().map(|m| m.log_time_ns).min().unwrap_or(0);
    let end = messages.iter().map(|m| m.log_time_ns).max().unwrap_or(0);
    // File: magic, bag header record padded to 4096 bytes, chunk section, index section.
    let magic = b"#ROSBAG V2.0\n";
    let header_len = 4096;
    let body_start = magic.len() + header_len;
    let index_pos = (body_start + body.len()) as u64;
    let index_records = index_section(&conns, &index, body_start as u64, (start, end));
    let mut header = Vec::new();
    record(
        &mut header,
        &[
            ("op", vec![0x03]),
            ("index_pos", index_pos.to_le_bytes().to_vec()),
            ("conn_count", (conns.len() as u32).to_le_bytes().to_vec()),
            ("chunk_count", 1u32.to_le_bytes().to_vec()),
        ],
        &[],
    );
    // Pad the header record's data so the record is exactly `header_len` bytes.
    let pad = header_len - header.len();
    header.truncate(header.len() - 4);
    header.extend_from_slice(&(pad as u32).to_le_bytes());
    header.extend(std::iter::repeat_n(b' ', pad));
    let mut file = magic.to_vec();
    file.extend_from_slice(&header);
    file.extend_from_slice(&body);
    file.extend_from_slice(&index_records);
    std::fs::write(path, file).expect("write bag");
}
