//! Typed index ranges of the error state, fixed at compile time (PX4-style named blocks).
//! Sensor and frame blocks are found by their typed ids; the layout only computes offsets (the
//! filter checks an id against its own `S` / `F` before it uses one).

use crate::ids::{FrameId, SensorId};

/// A contiguous block of the error state: `idx..idx + dof`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Block {
    /// First index.
    pub idx: usize,
    /// Number of degrees of freedom.
    pub dof: usize,
}

impl Block {
    /// One past the last index.
    pub const fn end(&self) -> usize {
        self.idx + self.dof
    }
}

/// The IMU blocks, always first.
pub mod imu {
    use super::Block;
    /// Orientation error `dtheta` (right perturbation of `R_G_I`).
    pub const ORIENTATION: Block = Block { idx: 0, dof: 3 };
    /// Position error in G.
    pub const POSITION: Block = Block { idx: 3, dof: 3 };
    /// Velocity error in G.
    pub const VELOCITY: Block = Block { idx: 6, dof: 3 };
    /// Gyroscope bias error.
    pub const GYRO_BIAS: Block = Block { idx: 9, dof: 3 };
    /// Accelerometer bias error.
    pub const ACCEL_BIAS: Block = Block { idx: 12, dof: 3 };
    /// Dimension of the IMU error state.
    pub const DIM: usize = 15;
    const _: () = assert!(ORIENTATION.end() == POSITION.idx);
    const _: () = assert!(POSITION.end() == VELOCITY.idx);
    const _: () = assert!(VELOCITY.end() == GYRO_BIAS.idx);
    const _: () = assert!(GYRO_BIAS.end() == ACCEL_BIAS.idx);
    const _: () = assert!(ACCEL_BIAS.end() == DIM);
}

/// Error dimension of one sensor: extrinsic rotation (3), translation (3), time offset (1).
pub const SENSOR_DIM: usize = 7;
/// Error dimension of one clone: orientation (3), position (3).
pub const CLONE_DIM: usize = 6;
/// Error dimension of one static frame (e.g. a calibration target): orientation (3),
/// position (3).
pub const FRAME_DIM: usize = 6;

/// The layout of a filter with `S` sensors and `C` clones; static frames, when a filter has
/// them, follow at [`Layout::DIM`] (see [`Layout::frame_orientation`]).
#[derive(Clone, Copy, Debug)]
pub struct Layout<const S: usize, const C: usize>;

impl<const S: usize, const C: usize> Layout<S, C> {
    /// Dimension of the error state without static frames.
    pub const DIM: usize = imu::DIM + SENSOR_DIM * S + CLONE_DIM * C;

    /// Dimension of the error state with `frames` static frames.
    pub const fn dim_with_frames(frames: usize) -> usize {
        Self::DIM + FRAME_DIM * frames
    }

    const fn sensor_base(s: usize) -> usize {
        imu::DIM + SENSOR_DIM * s
    }

    /// Extrinsic rotation error of sensor `s`.
    pub const fn extrinsic_rotation(s: SensorId) -> Block {
        Block {
            idx: Self::sensor_base(s.index()),
            dof: 3,
        }
    }

    /// Extrinsic translation error of sensor `s`.
    pub const fn extrinsic_translation(s: SensorId) -> Block {
        Block {
            idx: Self::sensor_base(s.index()) + 3,
            dof: 3,
        }
    }

    /// Both extrinsic blocks of sensor `s` (rotation then translation).
    pub const fn extrinsic(s: SensorId) -> Block {
        Block {
            idx: Self::sensor_base(s.index()),
            dof: 6,
        }
    }

    /// Time-offset error of sensor `s`.
    pub const fn time_offset(s: SensorId) -> Block {
        Block {
            idx: Self::sensor_base(s.index()) + 6,
            dof: 1,
        }
    }

    /// Orientation error of clone slot `c`.
    pub const fn clone_orientation(c: usize) -> Block {
        Block {
            idx: Self::sensor_base(S) + CLONE_DIM * c,
            dof: 3,
        }
    }

    /// Position error of clone slot `c`.
    pub const fn clone_position(c: usize) -> Block {
        Block {
            idx: Self::sensor_base(S) + CLONE_DIM * c + 3,
            dof: 3,
        }
    }

    /// Orientation error `dtheta` of static frame `f` (right perturbation of `R_G_F`).
    pub const fn frame_orientation(f: FrameId) -> Block {
        Block {
            idx: Self::DIM + FRAME_DIM * f.index(),
            dof: 3,
        }
    }

    /// Position error of static frame `f` in G.
    pub const fn frame_position(f: FrameId) -> Block {
        Block {
            idx: Self::DIM + FRAME_DIM * f.index() + 3,
            dof: 3,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn blocks_tile_the_joint_layout() {
        type L = Layout<2, 3>;
        let mut next = imu::DIM;
        for s in SensorId::all::<2>() {
            assert_eq!(L::extrinsic_rotation(s).idx, next);
            assert_eq!(L::extrinsic_translation(s).idx, next + 3);
            assert_eq!(L::time_offset(s).idx, next + 6);
            next = L::time_offset(s).end();
        }
        for c in 0..3 {
            assert_eq!(L::clone_orientation(c).idx, next);
            next = L::clone_position(c).end();
        }
        assert_eq!(next, L::DIM);
        for f in FrameId::all::<2>() {
            assert_eq!(L::frame_orientation(f).idx, next);
            assert_eq!(L::frame_position(f).idx, next + 3);
            next = L::frame_position(f).end();
        }
        assert_eq!(next, L::dim_with_frames(2));
    }
}
