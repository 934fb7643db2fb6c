//! The joint sequence: the IMU and LiDAR odometry of [`Scenario`] (400 Hz, 10 Hz) on the
//! same [`Trajectory`], plus a camera imaging the 42 corners of a 6x7 checkerboard at 20 Hz
//! and the LiDAR's points on that board, reduced to their plane moments, at 10 Hz.
//!
//! Every measurement is generated from the geometry alone: a corner is the board point seen
//! through the true camera pose at its true sampling instant, projected by the camera model,
//! plus pixel noise; a LiDAR board point is a point of the board plate, moved along its ray
//! by range noise, in the LiDAR frame at the scan's instant. The estimator's residuals are
//! never used.
//!
//! Events come in stamp order, each measurement right after the IMU sample at or past its
//! stamp (the order a device with no transport latency sees). Whether it can be fused yet
//! depends on the filter's time-offset estimate: the feeder of [`super::selftest`] holds it
//! until `Ekf::is_due` says so. Measurements are stamped up to one IMU period before the
//! last sample, so any time offset under that period lets every one be fused.

use heapless::Deque;
use msreg_estimator::camera::{radtan::RadTan, Camera, Distortion, Intrinsics, Projection};
use msreg_estimator::na::{Isometry3, Translation3, UnitQuaternion, Vector2, Vector3};
use msreg_estimator::update::board_plane::BoardPlane;
use msreg_estimator::{CornerObservation, Error};

use crate::noise::Noise;
use crate::scenario::{Event, ImuReading, PoseIncrement, Scenario, ScenarioConfig};
use crate::trajectory::Trajectory;

/// Rows and columns of inner corners of the board (the simulator's 6x7).
pub const BOARD: (usize, usize) = (6, 7);
/// Corners per image.
pub const CORNERS: usize = BOARD.0 * BOARD.1;
/// Corner spacing, m.
pub const SQUARE: f32 = 0.1;
/// LiDAR points on the board per scan: rows x columns of a grid over the plate.
pub const PLATE_POINTS: (usize, usize) = (6, 8);

/// The camera of the joint sequence: a EuRoC-like pinhole with radial-tangential distortion
/// (the same model the benchmark's reprojection row uses).
pub fn euroc_camera() -> Option<Camera<f32>> {
    Camera::new(
        Projection::Pinhole,
        Intrinsics {
            fu: 458.7,
            fv: 457.3,
            cu: 367.2,
            cv: 248.4,
        },
        Distortion::RadTan(RadTan {
            k1: -0.283,
            k2: 0.074,
            p1: 2.0e-4,
            p2: 1.8e-5,
            k3: 0.0,
        }),
        (752, 480),
    )
    .ok()
}

/// Board corner `k` (row-major) in the target frame T (the board is T's plane `z = 0`).
pub fn corner_in_target(k: usize) -> Vector3<f32> {
    let (r, c) = (k / BOARD.1, k % BOARD.1);
    Vector3::new(r as f32 * SQUARE, c as f32 * SQUARE, 0.0)
}

/// Everything that defines the joint sequence beyond the IMU / LiDAR stream of `base`.
#[derive(Clone, Copy, Debug)]
pub struct JointConfig {
    /// IMU and LiDAR odometry (sensor S of `base` is the LiDAR; its time offset is zero).
    pub base: ScenarioConfig,
    /// Camera period, ns (a multiple of the IMU period).
    pub image_period_ns: u64,
    /// Board-plane period, ns (one plane per LiDAR scan).
    pub plane_period_ns: u64,
    /// True `T_I_C`.
    pub t_i_c: Isometry3<f32>,
    /// True camera time offset `t_d`, s: an image stamped `t` was exposed at IMU time
    /// `t + t_d`.
    pub camera_time_offset: f32,
    /// Pixel noise, 1-sigma per axis.
    pub pixel_sigma: f32,
    /// LiDAR range noise, 1-sigma, m.
    pub range_sigma: f32,
    /// True `T_G_T`: the board in the world.
    pub t_g_t: Isometry3<f32>,
    /// Seed of the camera / LiDAR-point noise.
    pub seed: u32,
}

impl JointConfig {
    /// 3 s of 400 Hz IMU, 10 Hz LiDAR poses and board planes, 20 Hz images, on
    /// [`ScenarioConfig::default_run`]; the camera looks along the IMU's x axis, 1.3 mm of
    /// true time offset, the board 2 m ahead of the camera at the trajectory's mid pose.
    pub fn default_run() -> Self {
        let base = ScenarioConfig::default_run();
        let t_i_c = Isometry3::from_parts(
            Translation3::new(0.06, -0.02, 0.01),
            UnitQuaternion::from_euler_angles(-1.55, 0.03, -1.60),
        );
        let t_c_t_mid = Isometry3::from_parts(
            Translation3::new(-0.25, -0.3, 2.0),
            UnitQuaternion::from_euler_angles(0.1, -0.15, 0.05),
        );
        Self {
            base,
            image_period_ns: 50_000_000,
            plane_period_ns: base.pose_period_ns,
            t_i_c,
            camera_time_offset: 1.3e-3,
            pixel_sigma: 0.5,
            range_sigma: 0.01,
            t_g_t: mid_pose(&Trajectory::handheld()) * t_i_c * t_c_t_mid,
            seed: 0x5EED_0C01,
        }
    }

    /// Stamps `start + k * period` that are emitted: up to one IMU period before the end.
    fn count(&self, period_ns: u64) -> u64 {
        (self.base.duration_ns - self.base.imu_period_ns) / period_ns + 1
    }

    /// LiDAR relative-pose updates in the sequence (poses emitted, less the anchor).
    pub fn increment_count(&self) -> u64 {
        self.count(self.base.pose_period_ns) - 1
    }

    /// Images in the sequence.
    pub fn image_count(&self) -> u64 {
        self.count(self.image_period_ns)
    }

    /// Board planes in the sequence.
    pub fn plane_count(&self) -> u64 {
        self.count(self.plane_period_ns)
    }
}

/// `T_G_I` halfway through every bump of the trajectory (each coordinate at half its peak):
/// the attitude the board is placed in front of, so it stays in view.
fn mid_pose(trajectory: &Trajectory) -> Isometry3<f32> {
    let [r, p, y] = trajectory.angles.map(|b| 0.5 * b.amplitude);
    let [x, yy, z] = trajectory.position.map(|b| 0.5 * b.amplitude);
    Isometry3::from_parts(
        Translation3::new(x, yy, z),
        UnitQuaternion::from_euler_angles(r, p, y),
    )
}

/// One camera image: the board's corners.
#[derive(Clone, Copy, Debug)]
pub struct Image {
    /// Stamp, ns (camera clock).
    pub stamp_ns: u64,
    /// The corners, in the board's row-major order.
    pub corners: [CornerObservation<f32>; CORNERS],
    /// Corners that fell outside the image (or behind the camera); 0 in a valid sequence.
    pub outside: u32,
}

/// One item of the joint sequence.
// An image (42 corners) is far larger than the rest; without a heap there is no boxing.
#[allow(clippy::large_enum_variant)]
#[derive(Clone, Copy, Debug)]
pub enum JointEvent {
    /// An IMU sample.
    Imu(ImuReading),
    /// The LiDAR odometry's first pose.
    LidarAnchor {
        /// Stamp, ns.
        stamp_ns: u64,
    },
    /// A LiDAR odometry increment.
    LidarIncrement(PoseIncrement),
    /// A camera image of the board.
    Image(Image),
    /// The board plane of one LiDAR scan.
    Plane(BoardPlane<f32>),
    /// A scan's board points that did not make a plane (`BoardPlane::from_points` failed);
    /// never in a valid sequence.
    BadPlane {
        /// Stamp, ns.
        stamp_ns: u64,
        /// Why the points were refused.
        error: Error,
    },
}

/// The joint sequence as an iterator of [`JointEvent`]s.
#[derive(Clone, Debug)]
pub struct JointScenario {
    config: JointConfig,
    camera: Camera<f32>,
    inner: Scenario,
    noise: Noise,
    /// Events ready to hand out.
    ready: Deque<JointEvent, 4>,
    next_image: u64,
    next_plane: u64,
    dropped: u32,
}

impl JointScenario {
    /// The sequence of `config`; `None` if the camera model is invalid.
    pub fn new(config: JointConfig) -> Option<Self> {
        Some(Self {
            config,
            camera: euroc_camera()?,
            inner: Scenario::new(config.base),
            noise: Noise::new(config.seed),
            ready: Deque::new(),
            next_image: 0,
            next_plane: 0,
            dropped: 0,
        })
    }

    /// The configuration this sequence was made from.
    pub fn config(&self) -> &JointConfig {
        &self.config
    }

    /// True `T_C_T` at IMU time `t` s after the start.
    pub fn camera_to_board(&self, t: f32) -> Isometry3<f32> {
        let t_g_c = self.inner.trajectory().kinematics(t).t_g_i * self.config.t_i_c;
        t_g_c.inv_mul(&self.config.t_g_t)
    }

    /// The latest measurement stamp: one IMU period before the last sample.
    fn last_measurement_ns(&self) -> u64 {
        let b = &self.config.base;
        b.start_ns + b.duration_ns - b.imu_period_ns
    }

    fn seconds(&self, stamp_ns: u64) -> f32 {
        (stamp_ns - self.config.base.start_ns) as f32 * 1e-9
    }

    fn image(&mut self, stamp_ns: u64) -> Image {
        let t_c_t = self.camera_to_board(self.seconds(stamp_ns) + self.config.camera_time_offset);
        let (w, h) = self.camera.resolution;
        let mut image = Image {
            stamp_ns,
            corners: [CornerObservation {
                point_in_target: Vector3::zeros(),
                pixel: Vector2::zeros(),
            }; CORNERS],
            outside: 0,
        };
        for (k, corner) in image.corners.iter_mut().enumerate() {
            corner.point_in_target = corner_in_target(k);
            let sigma = self.config.pixel_sigma;
            let noise = Vector2::new(self.noise.gaussian(), self.noise.gaussian()) * sigma;
            let seen = self
                .camera
                .project(&t_c_t.transform_point(&corner.point_in_target.into()).coords);
            let Some(projected) = seen else {
                image.outside += 1;
                continue;
            };
            corner.pixel = projected.pixel + noise;
            let (u, v) = (corner.pixel.x, corner.pixel.y);
            if !(0.0..w as f32).contains(&u) || !(0.0..h as f32).contains(&v) {
                image.outside += 1;
            }
        }
        image
    }

    /// The board points of the LiDAR scan at `stamp_ns` (LiDAR time offset zero), with range
    /// noise along each ray, reduced to plane moments.
    fn plane(&mut self, stamp_ns: u64) -> JointEvent {
        let t = self.seconds(stamp_ns);
        let t_g_l = self.inner.trajectory().kinematics(t).t_g_i * self.config.base.t_i_s;
        let t_l_t = t_g_l.inv_mul(&self.config.t_g_t);
        let mut points = [Vector3::zeros(); PLATE_POINTS.0 * PLATE_POINTS.1];
        for (k, p) in points.iter_mut().enumerate() {
            let (r, c) = (k / PLATE_POINTS.1, k % PLATE_POINTS.1);
            // The plate reaches one square beyond the outer corners.
            let on_plate = Vector3::new(
                -SQUARE + r as f32 * (BOARD.0 as f32 + 1.0) * SQUARE / (PLATE_POINTS.0 - 1) as f32,
                -SQUARE + c as f32 * (BOARD.1 as f32 + 1.0) * SQUARE / (PLATE_POINTS.1 - 1) as f32,
                0.0,
            );
            let exact = t_l_t.transform_point(&on_plate.into()).coords;
            let range = exact.norm();
            *p = exact * ((range + self.config.range_sigma * self.noise.gaussian()) / range);
        }
        match BoardPlane::from_points(stamp_ns, &points, self.config.range_sigma) {
            Ok(plane) => JointEvent::Plane(plane),
            Err(error) => JointEvent::BadPlane { stamp_ns, error },
        }
    }

    /// After the IMU sample at `imu_ns`: queues the image and the plane stamped at or before
    /// it (LiDAR odometry follows from the inner sequence, right after its IMU sample).
    fn queue_due(&mut self, imu_ns: u64) {
        let c = self.config;
        let image_ns = c.base.start_ns + self.next_image * c.image_period_ns;
        if self.next_image < c.image_count() && image_ns <= imu_ns {
            self.next_image += 1;
            let image = self.image(image_ns);
            self.push(JointEvent::Image(image));
        }
        let plane_ns = c.base.start_ns + self.next_plane * c.plane_period_ns;
        if self.next_plane < c.plane_count() && plane_ns <= imu_ns {
            self.next_plane += 1;
            let plane = self.plane(plane_ns);
            self.push(plane);
        }
    }

    /// Events lost to a full queue; 0 in a valid sequence (the queue is drained before the
    /// next inner event; it holds one IMU sample and at most one image and plane).
    pub fn dropped(&self) -> u32 {
        self.dropped
    }

    fn push(&mut self, event: JointEvent) {
        if self.ready.push_back(event).is_err() {
            self.dropped += 1;
        }
    }
}

impl Iterator for JointScenario {
    type Item = JointEvent;

    fn next(&mut self) -> Option<JointEvent> {
        loop {
            if let Some(e) = self.ready.pop_front() {
                return Some(e);
            }
            match self.inner.next()? {
                Event::Imu(m) => {
                    self.push(JointEvent::Imu(m));
                    self.queue_due(m.stamp_ns);
                }
                // The scan at the last IMU stamp is left out, as images and planes are.
                Event::Anchor { stamp_ns } => self.push(JointEvent::LidarAnchor { stamp_ns }),
                Event::Increment(inc) if inc.stamp_to_ns <= self.last_measurement_ns() => {
                    self.push(JointEvent::LidarIncrement(inc))
                }
                Event::Increment(_) => {}
            }
        }
    }
}
