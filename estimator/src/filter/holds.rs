//! Directions of the state that no update may change (Schmidt "consider" directions): what
//! the motion leaves unobservable is held at its prior instead of being fitted to model
//! error (see [`crate::update::Hold`]).

use super::Ekf;
use crate::ids::SensorId;
use crate::scalar::Scalar;
use crate::state::Layout;
use crate::update::Hold;
use crate::Error;
use nalgebra::Vector3;

impl<T: Scalar, const S: usize, const C: usize, const N: usize, const F: usize> Ekf<T, S, C, N, F> {
    /// Holds the component of sensor `s`'s extrinsic translation along `axis` (IMU frame;
    /// normalised here) at its current value and variance from now on, or releases it
    /// (`None`). Planar driving, for one, leaves the lever arm along the rotation axis
    /// unobservable. Errors (filter unchanged): unknown sensor, zero or non-finite axis.
    pub fn hold_translation_axis(
        &mut self,
        s: SensorId,
        axis: Option<Vector3<T>>,
    ) -> Result<(), Error> {
        let i = s.checked(S)?;
        let unit = match axis {
            None => None,
            Some(a) => {
                let norm = a.norm();
                if !norm.is_finite() || !a.iter().all(|x| x.is_finite()) {
                    return Err(Error::NonFinite);
                }
                if norm <= T::zero() {
                    return Err(Error::InvalidConfig);
                }
                Some(a / norm)
            }
        };
        self.held_translation[i] = unit;
        Ok(())
    }

    /// The held translation direction of sensor `s`, if any (unit, IMU frame).
    pub fn held_translation_axis(&self, s: SensorId) -> Option<Vector3<T>> {
        self.held_translation.get(s.index()).copied().flatten()
    }

    /// The holds every update applies: the first `count` entries of the array.
    pub(super) fn holds(&self) -> ([Hold<T>; S], usize) {
        let mut out = [Hold {
            block: 0,
            axis: Vector3::zeros(),
        }; S];
        let mut count = 0;
        for (s, held) in SensorId::all::<S>().into_iter().zip(&self.held_translation) {
            if let Some(axis) = held {
                out[count] = Hold {
                    block: Layout::<S, C>::extrinsic_translation(s).idx,
                    axis: *axis,
                };
                count += 1;
            }
        }
        (out, count)
    }
}
