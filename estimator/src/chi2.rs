//! Chi-square quantiles for innovation gating and NIS checks, without std.
//!
//! Exact quantiles (scipy, 4 decimals) are tabulated for 1-30 degrees of freedom at the
//! confidences of [`Confidence`]; larger dof (windowed NIS sums) use the Wilson-Hilferty
//! approximation, whose relative error is below 0.5 % there.

use crate::scalar::Scalar;

/// Confidence levels with tabulated quantiles.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Confidence {
    /// 90 %.
    P90,
    /// 95 %.
    P95,
    /// 99 %.
    P99,
    /// 99.5 %.
    P995,
    /// 99.9 %.
    P999,
    /// 99.99 %.
    P9999,
    /// 99.999 %.
    P99999,
}

impl Confidence {
    fn column(self) -> usize {
        self as usize
    }

    /// The confidence as a probability (0.999 for 99.9 %).
    pub fn probability(self) -> f64 {
        [0.90, 0.95, 0.99, 0.995, 0.999, 0.9999, 0.99999][self.column()]
    }

    /// The standard normal quantile at this confidence.
    pub fn normal_quantile(self) -> f64 {
        [
            1.281552, 1.644854, 2.326348, 2.575829, 3.090232, 3.719016, 4.264891,
        ][self.column()]
    }
}

const TABLE_DOF: usize = 30;

#[rustfmt::skip]
const TABLE: [[f64; 7]; TABLE_DOF] = [
    [2.7055, 3.8415, 6.6349, 7.8794, 10.8276, 15.1367, 19.5114],
    [4.6052, 5.9915, 9.2103, 10.5966, 13.8155, 18.4207, 23.0259],
    [6.2514, 7.8147, 11.3449, 12.8382, 16.2662, 21.1075, 25.9017],
    [7.7794, 9.4877, 13.2767, 14.8603, 18.4668, 23.5127, 28.4733],
    [9.2364, 11.0705, 15.0863, 16.7496, 20.5150, 25.7448, 30.8562],
    [10.6446, 12.5916, 16.8119, 18.5476, 22.4577, 27.8563, 33.1071],
    [12.0170, 14.0671, 18.4753, 20.2777, 24.3219, 29.8775, 35.2585],
    [13.3616, 15.5073, 20.0902, 21.9550, 26.1245, 31.8276, 37.3316],
    [14.6837, 16.9190, 21.6660, 23.5894, 27.8772, 33.7199, 39.3407],
    [15.9872, 18.3070, 23.2093, 25.1882, 29.5883, 35.5640, 41.2962],
    [17.2750, 19.6751, 24.7250, 26.7568, 31.2641, 37.3670, 43.2060],
    [18.5493, 21.0261, 26.2170, 28.2995, 32.9095, 39.1344, 45.0761],
    [19.8119, 22.3620, 27.6882, 29.8195, 34.5282, 40.8707, 46.9116],
    [21.0641, 23.6848, 29.1412, 31.3193, 36.1233, 42.5793, 48.7161],
    [22.3071, 24.9958, 30.5779, 32.8013, 37.6973, 44.2632, 50.4930],
    [23.5418, 26.2962, 31.9999, 34.2672, 39.2524, 45.9249, 52.2450],
    [24.7690, 27.5871, 33.4087, 35.7185, 40.7902, 47.5664, 53.9743],
    [25.9894, 28.8693, 34.8053, 37.1565, 42.3124, 49.1894, 55.6829],
    [27.2036, 30.1435, 36.1909, 38.5823, 43.8202, 50.7955, 57.3725],
    [28.4120, 31.4104, 37.5662, 39.9968, 45.3147, 52.3860, 59.0446],
    [29.6151, 32.6706, 38.9322, 41.4011, 46.7970, 53.9620, 60.7003],
    [30.8133, 33.9244, 40.2894, 42.7957, 48.2679, 55.5246, 62.3410],
    [32.0069, 35.1725, 41.6384, 44.1813, 49.7282, 57.0746, 63.9675],
    [33.1962, 36.4150, 42.9798, 45.5585, 51.1786, 58.6130, 65.5808],
    [34.3816, 37.6525, 44.3141, 46.9279, 52.6197, 60.1403, 67.1818],
    [35.5632, 38.8851, 45.6417, 48.2899, 54.0520, 61.6573, 68.7710],
    [36.7412, 40.1133, 46.9629, 49.6449, 55.4760, 63.1645, 70.3492],
    [37.9159, 41.3371, 48.2782, 50.9934, 56.8923, 64.6624, 71.9170],
    [39.0875, 42.5570, 49.5879, 52.3356, 58.3012, 66.1517, 73.4749],
    [40.2560, 43.7730, 50.8922, 53.6720, 59.7031, 67.6326, 75.0234],
];

/// Upper quantile: `P(chi2(dof) <= q) = confidence`. `dof = 0` gives 0.
pub fn quantile<T: Scalar>(dof: usize, confidence: Confidence) -> T {
    T::lit(quantile_f64(
        dof,
        confidence.normal_quantile(),
        confidence.column(),
    ))
}

/// Lower quantile: `P(chi2(dof) <= q) = 1 - confidence` (Wilson-Hilferty; meant for the
/// large dof of windowed NIS sums).
pub fn lower_quantile<T: Scalar>(dof: usize, confidence: Confidence) -> T {
    T::lit(wilson_hilferty(dof, -confidence.normal_quantile()))
}

fn quantile_f64(dof: usize, z: f64, column: usize) -> f64 {
    match dof {
        0 => 0.0,
        d if d <= TABLE_DOF => TABLE[d - 1][column],
        d => wilson_hilferty(d, z),
    }
}

fn wilson_hilferty(dof: usize, z: f64) -> f64 {
    if dof == 0 {
        return 0.0;
    }
    let k = dof as f64;
    let c = 2.0 / (9.0 * k);
    let base = 1.0 - c + z * libm::sqrt(c);
    let base = if base > 0.0 { base } else { 0.0 };
    k * base * base * base
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn table_values() {
        assert!((quantile::<f64>(1, Confidence::P95) - 3.8415).abs() < 1e-4);
        assert!((quantile::<f64>(6, Confidence::P99) - 16.8119).abs() < 1e-4);
    }

    #[test]
    fn wilson_hilferty_continues_the_table() {
        // scipy: chi2.ppf(0.95, 31) = 44.9853, chi2.ppf(0.999, 300) = 381.4239
        assert!((quantile::<f64>(31, Confidence::P95) - 44.9853).abs() / 44.9853 < 5e-3);
        assert!((quantile::<f64>(300, Confidence::P999) - 381.4239).abs() / 381.4239 < 5e-3);
        // scipy: chi2.ppf(0.001, 300) = 229.9634
        let lo = lower_quantile::<f64>(300, Confidence::P999);
        assert!(lo > 220.0 && lo < 236.0, "{lo}");
    }
}
