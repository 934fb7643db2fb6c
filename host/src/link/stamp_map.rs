//! Measurement stamps mapped onto the device clock (docs/protocol.md, "Clock sync"), for a
//! device whose filter runs on its own clock ([`msreg_protocol::TimeBase::DeviceClock`]).
//!
//! A stamp of the host's data clock is mapped once, with the clock-sync fit of the moment,
//! and remembered: an increment's start must be its anchor's stamp exactly, however the fit
//! moved since. Per stream (IMU, each pose sensor, camera) mapped stamps never go backwards
//! (a refit may move the offset by microseconds; the device would refuse a stamp before its
//! filter time).

use std::collections::HashMap;

use msreg_protocol::HostMsg;

/// Which monotonic stream a stamp belongs to.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
enum Stream {
    Imu,
    Pose(u8),
    Camera,
}

/// Maps host data-clock stamps to device-clock stamps through a caller's function.
#[derive(Debug, Default)]
pub struct StampMap {
    mapped: HashMap<(Stream, u64), u64>,
    last: HashMap<Stream, u64>,
}

impl StampMap {
    /// Empty.
    pub fn new() -> Self {
        Self::default()
    }

    fn map(&mut self, stream: Stream, stamp: u64, to_device: &dyn Fn(u64) -> u64) -> u64 {
        if let Some(&d) = self.mapped.get(&(stream, stamp)) {
            return d;
        }
        let floor = self.last.get(&stream).map_or(0, |l| l + 1);
        let d = to_device(stamp).max(floor);
        self.last.insert(stream, d);
        self.mapped.insert((stream, stamp), d);
        d
    }

    /// `msg` with every stamp mapped by `to_device` (host data clock ns -> device clock ns).
    /// An IMU batch keeps its sample offsets (the device's stamps are base + offset; a 50 ppm
    /// skew over a 40 ms batch is 2 us, below a sample period's jitter).
    pub fn message(&mut self, msg: &HostMsg, to_device: &dyn Fn(u64) -> u64) -> HostMsg {
        let mut m = *msg;
        match &mut m {
            HostMsg::ImuBatch(b) => {
                let last = b.samples.as_slice().last().map_or(0, |s| s.offset_ns);
                let base = self.map(Stream::Imu, b.base_stamp_ns, to_device);
                // The next batch must start after this one's last sample.
                let end = base + u64::from(last);
                self.last
                    .entry(Stream::Imu)
                    .and_modify(|l| *l = (*l).max(end))
                    .or_insert(end);
                b.base_stamp_ns = base;
            }
            HostMsg::Anchor(a) => {
                a.stamp_ns = self.map(Stream::Pose(a.sensor), a.stamp_ns, to_device)
            }
            HostMsg::RelativePose(r) => {
                r.stamp_from_ns = self.map(Stream::Pose(r.sensor), r.stamp_from_ns, to_device);
                r.stamp_to_ns = self.map(Stream::Pose(r.sensor), r.stamp_to_ns, to_device);
            }
            HostMsg::TargetPose(t) => t.stamp_ns = self.map(Stream::Camera, t.stamp_ns, to_device),
            HostMsg::CornerSet(c) => c.stamp_ns = self.map(Stream::Camera, c.stamp_ns, to_device),
            HostMsg::Hello(_) | HostMsg::Config(_) | HostMsg::GetStatus | HostMsg::TimeSync(_) => {}
        }
        m
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use msreg_protocol::{Anchor, Pose, RelativePose};

    fn increment(from: u64, to: u64) -> HostMsg {
        HostMsg::RelativePose(RelativePose {
            stamp_from_ns: from,
            stamp_to_ns: to,
            delta: Pose::default(),
            sigma_rotation_rad: [0.01; 3],
            sigma_translation_m: [0.01; 3],
            sensor: 0,
        })
    }

    #[test]
    fn an_increment_starts_exactly_at_its_anchor_after_the_fit_moved() {
        let mut map = StampMap::new();
        let anchor = map.message(
            &HostMsg::Anchor(Anchor {
                stamp_ns: 100,
                sensor: 0,
            }),
            &|s| s + 1_000,
        );
        // The fit moved 7 ns later: the start keeps the anchor's mapping, the end the new.
        let inc = map.message(&increment(100, 200), &|s| s + 1_007);
        let HostMsg::Anchor(a) = anchor else { panic!() };
        let HostMsg::RelativePose(r) = inc else {
            panic!()
        };
        assert_eq!(
            (a.stamp_ns, r.stamp_from_ns, r.stamp_to_ns),
            (1_100, 1_100, 1_207)
        );
        // A fit that moves back never maps a later stamp before an earlier one
        let back = map.message(&increment(200, 201), &|s| s + 900);
        let HostMsg::RelativePose(r) = back else {
            panic!()
        };
        assert_eq!((r.stamp_from_ns, r.stamp_to_ns), (1_207, 1_208));
    }
}
