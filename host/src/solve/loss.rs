//! Robust losses `rho(s)` of a squared (whitened) residual `s = w r^2`, applied the way
//! Ceres does for scalar residuals: iteratively re-weighted least squares with the weight
//! `rho'(s)`, so an outlier's pull on the normal equations is bounded (Huber) or vanishes
//! (Cauchy) instead of growing with its residual.

/// A robust loss on a squared residual `s`; `scale` is where it departs from `s`.
#[derive(Clone, Copy, Debug, PartialEq, Default)]
pub enum Loss {
    /// `rho(s) = s`: ordinary least squares.
    #[default]
    Squared,
    /// `rho(s) = s` for `s <= c^2`, else `2 c sqrt(s) - c^2`: linear tails.
    Huber(f64),
    /// `rho(s) = c^2 ln(1 + s / c^2)`: logarithmic tails, outliers almost ignored.
    Cauchy(f64),
}

impl Loss {
    /// `rho(s)`.
    pub fn rho(self, s: f64) -> f64 {
        match self {
            Self::Squared => s,
            Self::Huber(c) => {
                let c2 = c * c;
                if s <= c2 {
                    s
                } else {
                    2.0 * c * s.sqrt() - c2
                }
            }
            Self::Cauchy(c) => {
                let c2 = c * c;
                c2 * (s / c2).ln_1p()
            }
        }
    }

    /// `rho'(s)`, the IRLS weight of a residual whose square is `s`.
    pub fn weight(self, s: f64) -> f64 {
        match self {
            Self::Squared => 1.0,
            Self::Huber(c) => {
                if s <= c * c {
                    1.0
                } else {
                    c / s.sqrt()
                }
            }
            Self::Cauchy(c) => 1.0 / (1.0 + s / (c * c)),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn weight_is_the_derivative_of_rho() {
        for loss in [Loss::Squared, Loss::Huber(0.7), Loss::Cauchy(0.3)] {
            for s in [0.01, 0.2, 0.49, 0.6, 3.0, 40.0] {
                let h = 1e-6 * s;
                let numeric = (loss.rho(s + h) - loss.rho(s - h)) / (2.0 * h);
                assert!(
                    (numeric - loss.weight(s)).abs() < 1e-6,
                    "{loss:?} s={s}: {numeric} vs {}",
                    loss.weight(s)
                );
            }
        }
    }

    #[test]
    fn robust_losses_grow_slower_than_squares() {
        assert!(Loss::Huber(1.0).rho(100.0) < 100.0 / 4.0);
        assert!(Loss::Cauchy(1.0).rho(100.0) < 5.0);
        assert!((Loss::Huber(1.0).rho(0.5) - 0.5).abs() < 1e-15);
    }
}
