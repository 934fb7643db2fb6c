//! A tiny deterministic noise source (xorshift32 + Irwin-Hall), so the embedded scenario
//! is the same on every run and on every target, without an RNG crate or `libm`.

use nalgebra::Vector3;

/// xorshift32 (Marsaglia 2003), period 2^32 - 1.
#[derive(Clone, Debug)]
pub struct Noise {
    state: u32,
}

impl Noise {
    /// A generator from a non-zero seed (0 is mapped to a fixed non-zero seed).
    pub const fn new(seed: u32) -> Self {
        Self {
            state: if seed == 0 { 0x9E37_79B9 } else { seed },
        }
    }

    fn next_u32(&mut self) -> u32 {
        let mut x = self.state;
        x ^= x << 13;
        x ^= x >> 17;
        x ^= x << 5;
        self.state = x;
        x
    }

    /// Uniform in [0, 1).
    fn uniform(&mut self) -> f32 {
        (self.next_u32() >> 8) as f32 * (1.0 / (1u32 << 24) as f32)
    }

    /// Approximately standard normal: the sum of 12 uniforms minus 6 (Irwin-Hall; unit
    /// variance, tails bounded at +-6 sigma, which is all a self-test needs).
    pub fn gaussian(&mut self) -> f32 {
        let mut sum = 0.0;
        for _ in 0..12 {
            sum += self.uniform();
        }
        sum - 6.0
    }

    /// A vector of three independent zero-mean samples with standard deviation `sigma`.
    pub fn vector3(&mut self, sigma: f32) -> Vector3<f32> {
        Vector3::new(self.gaussian(), self.gaussian(), self.gaussian()) * sigma
    }
}
