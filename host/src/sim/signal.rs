//! Scalar signals with exact first and second time derivatives: sums of
//! sinusoids faded in by a C2 smooth step. The trajectory is built from
//! these so the IMU can be synthesised from analytic derivatives rather than
//! finite differences.

use std::f64::consts::TAU;

/// A value with its first and second time derivatives.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Jet {
    /// f(t).
    pub v: f64,
    /// f'(t).
    pub d1: f64,
    /// f''(t).
    pub d2: f64,
}

impl Jet {
    /// A constant.
    pub fn constant(v: f64) -> Self {
        Self {
            v,
            d1: 0.0,
            d2: 0.0,
        }
    }
}

impl std::ops::Mul for Jet {
    type Output = Self;

    /// Product rule up to second order.
    fn mul(self, other: Self) -> Self {
        Self {
            v: self.v * other.v,
            d1: self.d1 * other.v + self.v * other.d1,
            d2: self.d2 * other.v + 2.0 * self.d1 * other.d1 + self.v * other.d2,
        }
    }
}

impl std::ops::Add for Jet {
    type Output = Self;

    fn add(self, other: Self) -> Self {
        Self {
            v: self.v + other.v,
            d1: self.d1 + other.d1,
            d2: self.d2 + other.d2,
        }
    }
}

/// `amplitude * sin(2 pi frequency_hz t + phase)`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sinusoid {
    /// Amplitude.
    pub amplitude: f64,
    /// Frequency (Hz).
    pub frequency_hz: f64,
    /// Phase (rad).
    pub phase: f64,
}

impl Sinusoid {
    /// Value and derivatives at `t` (s).
    pub fn eval(&self, t: f64) -> Jet {
        let w = TAU * self.frequency_hz;
        let (s, c) = (w * t + self.phase).sin_cos();
        Jet {
            v: self.amplitude * s,
            d1: self.amplitude * w * c,
            d2: -self.amplitude * w * w * s,
        }
    }
}

/// The quintic smooth step `6x^5 - 15x^4 + 10x^3`, `x = (t - start_s) / duration_s`
/// clamped to [0, 1]: 0 before, 1 after, C2 at both ends.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SmoothStep {
    /// Time where the step starts rising (s).
    pub start_s: f64,
    /// Rise time (s), > 0.
    pub duration_s: f64,
}

impl SmoothStep {
    /// Value and derivatives at `t` (s).
    pub fn eval(&self, t: f64) -> Jet {
        let x = (t - self.start_s) / self.duration_s;
        if x <= 0.0 {
            return Jet::constant(0.0);
        }
        if x >= 1.0 {
            return Jet::constant(1.0);
        }
        let d = self.duration_s;
        Jet {
            v: x * x * x * (10.0 + x * (-15.0 + 6.0 * x)),
            d1: 30.0 * x * x * (x - 1.0) * (x - 1.0) / d,
            d2: 60.0 * x * (x - 1.0) * (2.0 * x - 1.0) / (d * d),
        }
    }
}

/// `base + envelope(t) * sum(sinusoids)`: constant while the envelope is 0,
/// then smoothly excited.
#[derive(Debug, Clone, PartialEq)]
pub struct EnvelopedSignal {
    /// Value during the stationary period.
    pub base: f64,
    /// The excitation.
    pub sinusoids: Vec<Sinusoid>,
    /// Fades the excitation in.
    pub envelope: SmoothStep,
}

impl EnvelopedSignal {
    /// Value and exact derivatives at `t` (s).
    pub fn eval(&self, t: f64) -> Jet {
        let offset = self
            .sinusoids
            .iter()
            .fold(Jet::default(), |sum, s| sum + s.eval(t));
        Jet::constant(self.base) + self.envelope.eval(t) * offset
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn check_derivatives(f: impl Fn(f64) -> Jet, t: f64) {
        let h = 1e-5;
        let (a, b, c) = (f(t - h), f(t), f(t + h));
        let d1 = (c.v - a.v) / (2.0 * h);
        let d2 = (c.d1 - a.d1) / (2.0 * h);
        assert!(
            (d1 - b.d1).abs() < 1e-7 * (1.0 + b.d1.abs()),
            "d1 at {t}: {d1} vs {}",
            b.d1
        );
        assert!(
            (d2 - b.d2).abs() < 1e-6 * (1.0 + b.d2.abs()),
            "d2 at {t}: {d2} vs {}",
            b.d2
        );
    }

    #[test]
    fn smooth_step_derivatives_match_finite_differences() {
        let step = SmoothStep {
            start_s: 1.0,
            duration_s: 0.7,
        };
        for t in [0.5, 1.1, 1.3, 1.35, 1.6, 2.5] {
            check_derivatives(|t| step.eval(t), t);
        }
        assert!(step.eval(1.0).v.abs() < 1e-15);
        assert!((step.eval(1.7).v - 1.0).abs() < 1e-15);
    }

    #[test]
    fn enveloped_signal_derivatives_include_the_envelope_terms() {
        let signal = EnvelopedSignal {
            base: 0.3,
            sinusoids: vec![
                Sinusoid {
                    amplitude: 0.4,
                    frequency_hz: 0.9,
                    phase: 1.0,
                },
                Sinusoid {
                    amplitude: -0.1,
                    frequency_hz: 0.25,
                    phase: -2.0,
                },
            ],
            envelope: SmoothStep {
                start_s: 1.0,
                duration_s: 1.0,
            },
        };
        for t in [0.2, 1.2, 1.5, 1.9, 4.0] {
            check_derivatives(|t| signal.eval(t), t);
        }
        assert!((signal.eval(0.5).v - 0.3).abs() < 1e-15);
    }
}
