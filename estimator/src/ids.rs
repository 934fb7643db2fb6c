//! Typed ids of the filter's exteroceptive sensors and static frames.
//!
//! A [`SensorId`] or [`FrameId`] can only be built against a layout size and only when it is
//! in range: at run time through a checked constructor that returns a typed error
//! ([`SensorId::new`], [`Ekf::sensor_id`](crate::Ekf::sensor_id), the wire's `u8` through
//! [`SensorId::from_wire`]), or as a constant through [`SensorId::at`], whose range check
//! fails the build, never a run. Neither type can be mistaken for the other or for a clone
//! slot, and the measurement updates take them instead of bare indices.
//!
//! The ids do not carry the layout in their type (a pipeline's measurement feed serves
//! filters of several layouts), so an id made for a larger layout can still reach a smaller
//! filter: every filter entry point checks `index < S` (or `< F`) and answers
//! [`Error::UnknownSensor`] / [`Error::UnknownFrame`] with the state untouched.
//!
//! What the types rule out at compile time: a frame id where a sensor id is expected,
//!
//! ```compile_fail
//! use msreg_estimator::{FrameId, PoseImuEkf};
//! fn extrinsic_of_a_frame(ekf: &PoseImuEkf<f64>) {
//!     let _ = ekf.extrinsic(FrameId::at::<0, 1>());
//! }
//! ```
//!
//! a bare index,
//!
//! ```compile_fail
//! use msreg_estimator::PoseImuEkf;
//! fn extrinsic_of_an_index(ekf: &PoseImuEkf<f64>) {
//!     let _ = ekf.extrinsic(0);
//! }
//! ```
//!
//! and a constant out of its layout's range:
//!
//! ```compile_fail
//! use msreg_estimator::SensorId;
//! const THIRD_OF_TWO: SensorId = SensorId::at::<2, 2>();
//! fn main() {
//!     let _ = THIRD_OF_TWO;
//! }
//! ```
//!
//! while the same constant in range builds:
//!
//! ```
//! use msreg_estimator::SensorId;
//! const SECOND_OF_TWO: SensorId = SensorId::at::<1, 2>();
//! assert_eq!(SECOND_OF_TWO.index(), 1);
//! ```

use crate::Error;
use core::fmt;

/// Index of an exteroceptive sensor (its extrinsic and time-offset block) in a filter layout.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct SensorId(u8);

/// Index of a static frame (e.g. a calibration target) in a filter layout.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct FrameId(u8);

/// Whether `index` is below `count` and fits the `u8` every id is stored (and sent) as.
const fn in_range(index: usize, count: usize) -> bool {
    index < count && index <= u8::MAX as usize
}

macro_rules! id_impl {
    ($id:ident, $error:expr, $what:literal, $count:literal) => {
        impl $id {
            #[doc = concat!("The ", $what, " `index` of a layout with `", $count, "` of them; ")]
            #[doc = concat!("`", stringify!($error), "` when it is not below `", $count, "`.")]
            pub const fn new<const COUNT: usize>(index: usize) -> Result<Self, Error> {
                if in_range(index, COUNT) {
                    Ok(Self(index as u8))
                } else {
                    Err($error)
                }
            }

            #[doc = concat!("The ", $what, " `INDEX` of a layout with `", $count, "` of them, ")]
            /// for constants: the range check runs at compile time (an out-of-range `INDEX`
            /// fails the build when the constant is evaluated); there is no run-time panic path.
            pub const fn at<const INDEX: usize, const COUNT: usize>() -> Self {
                const { assert!(in_range(INDEX, COUNT), "id out of the layout's range") };
                Self(INDEX as u8)
            }

            #[doc = concat!("The ", $what, " `index` received as a wire `u8`, checked against ")]
            #[doc = concat!("a layout with `", $count, "` of them.")]
            pub const fn from_wire<const COUNT: usize>(index: u8) -> Result<Self, Error> {
                Self::new::<COUNT>(index as usize)
            }

            #[doc = concat!("Every ", $what, " of a layout with `", $count, "` of them, in order ")]
            /// (a layout wider than a `u8` fails the build).
            pub fn all<const COUNT: usize>() -> [Self; COUNT] {
                const { assert!(COUNT <= u8::MAX as usize + 1, "layout wider than a u8") };
                core::array::from_fn(|i| Self(i as u8))
            }

            /// The index in the layout.
            pub const fn index(self) -> usize {
                self.0 as usize
            }

            /// The index as sent on the wire.
            pub const fn wire(self) -> u8 {
                self.0
            }

            /// The index when it is below `count` (the layout this id is used with).
            pub(crate) fn checked(self, count: usize) -> Result<usize, Error> {
                if self.index() < count {
                    Ok(self.index())
                } else {
                    Err($error)
                }
            }
        }

        impl fmt::Display for $id {
            fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
                write!(f, "{}", self.0)
            }
        }

        impl From<$id> for usize {
            fn from(id: $id) -> usize {
                id.index()
            }
        }

        impl From<$id> for u8 {
            fn from(id: $id) -> u8 {
                id.wire()
            }
        }
    };
}

id_impl!(SensorId, Error::UnknownSensor, "sensor", "S");
id_impl!(FrameId, Error::UnknownFrame, "static frame", "F");

#[cfg(test)]
mod tests {
    use super::*;

    const SECOND_OF_TWO: SensorId = SensorId::at::<1, 2>();
    const TARGET: FrameId = FrameId::at::<0, 1>();

    #[test]
    fn checked_constructors_reject_out_of_range_with_typed_errors() {
        assert_eq!(SensorId::new::<2>(1), Ok(SECOND_OF_TWO));
        assert_eq!(SensorId::new::<2>(2), Err(Error::UnknownSensor));
        assert_eq!(SensorId::new::<0>(0), Err(Error::UnknownSensor));
        assert_eq!(SensorId::new::<300>(256), Err(Error::UnknownSensor));
        assert_eq!(FrameId::new::<1>(0), Ok(TARGET));
        assert_eq!(FrameId::new::<1>(1), Err(Error::UnknownFrame));
        assert_eq!(FrameId::new::<0>(0), Err(Error::UnknownFrame));
        assert_eq!(SensorId::from_wire::<2>(1), Ok(SECOND_OF_TWO));
        assert_eq!(SensorId::from_wire::<2>(7), Err(Error::UnknownSensor));
        assert_eq!(FrameId::from_wire::<1>(255), Err(Error::UnknownFrame));
    }

    #[test]
    fn ids_keep_their_index_and_enumerate_a_layout() {
        assert_eq!(SECOND_OF_TWO.index(), 1);
        assert_eq!(SECOND_OF_TWO.wire(), 1);
        assert_eq!(usize::from(TARGET), 0);
        assert_eq!(SensorId::all::<3>().map(SensorId::index), [0, 1, 2]);
        assert_eq!(FrameId::all::<0>(), []);
        assert_eq!(SECOND_OF_TWO.checked(2), Ok(1));
        assert_eq!(SECOND_OF_TWO.checked(1), Err(Error::UnknownSensor));
        assert_eq!(TARGET.checked(0), Err(Error::UnknownFrame));
    }
}
