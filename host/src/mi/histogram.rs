//! Joint histograms of (point intensity, image intensity), both normalised to [0, 1].
//!
//! - [`hard_mi`]: plain binning, MI = H(A) + H(B) - H(A,B) and
//!   NMI = (H(A) + H(B)) / H(A,B) (Studholme), in nats.
//! - [`BSplineHistogram`]: every sample spreads over 4 x 4 bins with cubic B-spline
//!   weights (Parzen window, Mattes et al. 2003), so the MI is a smooth function of the
//!   image intensities and has an analytic derivative.

/// MI and NMI of one evaluation.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct MiScore {
    /// Mutual information, nats.
    pub mi: f64,
    /// Normalised MI `(H(A) + H(B)) / H(A,B)`, in [1, 2].
    pub nmi: f64,
    /// Samples counted.
    pub samples: usize,
}

fn entropy(p: impl Iterator<Item = f64>) -> f64 {
    p.filter(|&x| x > 0.0).map(|x| -x * x.ln()).sum()
}

/// MI and NMI of `(a, b)` pairs in [0, 1] with `bins` x `bins` hard bins.
pub fn hard_mi(pairs: &[(f32, f32)], bins: usize) -> MiScore {
    let bins = bins.max(2);
    let mut joint = vec![0.0f64; bins * bins];
    let bin = |x: f32| ((x.clamp(0.0, 1.0) * bins as f32) as usize).min(bins - 1);
    for &(a, b) in pairs {
        joint[bin(a) * bins + bin(b)] += 1.0;
    }
    score_of(&joint, bins, pairs.len())
}

/// MI / NMI of a joint histogram (row = point intensity bin, column = image bin).
pub(crate) fn score_of(joint: &[f64], bins: usize, samples: usize) -> MiScore {
    let total: f64 = joint.iter().sum();
    if total <= 0.0 {
        return MiScore::default();
    }
    let pa = (0..bins).map(|a| joint[a * bins..(a + 1) * bins].iter().sum::<f64>() / total);
    let pb = (0..bins).map(|b| (0..bins).map(|a| joint[a * bins + b]).sum::<f64>() / total);
    let (ha, hb) = (entropy(pa), entropy(pb));
    let hab = entropy(joint.iter().map(|&x| x / total));
    MiScore {
        mi: ha + hb - hab,
        nmi: if hab > 0.0 { (ha + hb) / hab } else { 1.0 },
        samples,
    }
}

/// Cubic B-spline `beta3(t)` and its derivative.
#[inline]
pub fn bspline3(t: f64) -> (f64, f64) {
    let s = t.abs();
    let sign = if t < 0.0 { -1.0 } else { 1.0 };
    if s < 1.0 {
        (
            2.0 / 3.0 - s * s + 0.5 * s * s * s,
            sign * (-2.0 * s + 1.5 * s * s),
        )
    } else if s < 2.0 {
        let r = 2.0 - s;
        (r * r * r / 6.0, -sign * 0.5 * r * r)
    } else {
        (0.0, 0.0)
    }
}

/// The four bins a B-spline sample touches: first index and weights/derivatives.
#[derive(Clone, Copy, Debug)]
pub struct Spread {
    /// Index of the first of four bins (may be -1 at the low end: skipped).
    pub first: isize,
    /// Weights of the four bins.
    pub w: [f64; 4],
    /// `d weight / d (continuous bin coordinate)`.
    pub dw: [f64; 4],
}

/// A smoothed joint histogram with `bins` bins per axis.
#[derive(Clone, Debug, PartialEq)]
pub struct BSplineHistogram {
    /// Bins per axis (>= 5).
    pub bins: usize,
    /// Row-major `bins x bins` weights (row = point intensity).
    pub joint: Vec<f64>,
    /// Sum of weights (= number of samples: B-splines are a partition of unity).
    pub total: f64,
}

impl BSplineHistogram {
    /// An empty histogram.
    pub fn new(bins: usize) -> Self {
        let bins = bins.max(5);
        Self {
            bins,
            joint: vec![0.0; bins * bins],
            total: 0.0,
        }
    }

    /// Continuous-bin coordinates per unit of intensity.
    pub fn scale(&self) -> f64 {
        (self.bins - 3) as f64
    }

    /// The bins a value in [0, 1] spreads into: the cubic B-spline at `1 + t`, `t`,
    /// `t - 1` and `t - 2` (`t` the fractional bin coordinate) in closed form.
    #[inline]
    pub fn spread(&self, x: f32) -> Spread {
        let c = 1.0 + f64::from(x.clamp(0.0, 1.0)) * self.scale();
        // c >= 1 (or NaN), so truncation is its floor: one instruction where `floor` is a
        // libm call (x86-64 without SSE4.1); the same values.
        let whole = c as isize;
        let first = whole - 1;
        let t = c - whole as f64;
        let u = 1.0 - t;
        let (t2, u2) = (t * t, u * u);
        Spread {
            first,
            w: [
                u2 * u / 6.0,
                2.0 / 3.0 - t2 + 0.5 * t2 * t,
                2.0 / 3.0 - u2 + 0.5 * u2 * u,
                t2 * t / 6.0,
            ],
            dw: [-0.5 * u2, -2.0 * t + 1.5 * t2, 2.0 * u - 1.5 * u2, 0.5 * t2],
        }
    }

    /// Adds one `(point, image)` sample.
    #[inline]
    pub fn add(&mut self, a: f32, b: f32) {
        let (sa, sb) = (self.spread(a), self.spread(b));
        let n = self.bins as isize;
        for i in 0..4 {
            let ra = sa.first + i as isize;
            if ra < 0 || ra >= n || sa.w[i] == 0.0 {
                continue;
            }
            for j in 0..4 {
                let cb = sb.first + j as isize;
                if cb >= 0 && cb < n {
                    self.joint[ra as usize * self.bins + cb as usize] += sa.w[i] * sb.w[j];
                }
            }
        }
        self.total += 1.0;
    }

    /// Adds another histogram of the same size (parallel reduction).
    pub fn merge(mut self, other: &Self) -> Self {
        for (x, y) in self.joint.iter_mut().zip(&other.joint) {
            *x += y;
        }
        self.total += other.total;
        self
    }

    /// MI and NMI of the smoothed histogram.
    pub fn score(&self) -> MiScore {
        score_of(&self.joint, self.bins, self.total as usize)
    }

    /// `log(p(a,b) / p(b))` per bin (0 where empty): with the point marginal fixed,
    /// `dMI = sum_ab dp(a,b) log(p(a,b) / p(b))`.
    pub fn gradient_weights(&self) -> Vec<f64> {
        let n = self.bins;
        let pb: Vec<f64> = (0..n)
            .map(|b| (0..n).map(|a| self.joint[a * n + b]).sum::<f64>())
            .collect();
        let mut out = vec![0.0; n * n];
        for a in 0..n {
            for b in 0..n {
                let j = self.joint[a * n + b];
                if j > 0.0 && pb[b] > 0.0 {
                    out[a * n + b] = (j / pb[b]).ln();
                }
            }
        }
        out
    }

    /// `d MI / d b` of one sample `(a, b)` given [`Self::gradient_weights`], per unit of
    /// image intensity, before division by the total.
    #[inline]
    pub fn sample_derivative(&self, weights: &[f64], a: f32, b: f32) -> f64 {
        let (sa, sb) = (self.spread(a), self.spread(b));
        let n = self.bins as isize;
        let mut s = 0.0;
        for i in 0..4 {
            let ra = sa.first + i as isize;
            if ra < 0 || ra >= n || sa.w[i] == 0.0 {
                continue;
            }
            for j in 0..4 {
                let cb = sb.first + j as isize;
                if cb >= 0 && cb < n {
                    s += sa.w[i] * sb.dw[j] * weights[ra as usize * self.bins + cb as usize];
                }
            }
        }
        s * self.scale()
    }
}

/// One [`BSplineHistogram`] per point group (e.g. ground and off-ground LiDAR returns,
/// whose reflectivity relates to the image differently). The score is the
/// sample-weighted mean `sum_k n_k MI_k / sum_k n_k` (the conditional MI `I(A; B | G)`):
/// `N` times it is the log-likelihood ratio of per-group joint models against
/// independence, the sum of the groups' own, so no weight is chosen.
#[derive(Clone, Debug, PartialEq)]
pub struct GroupedHistogram {
    /// The histogram of each group.
    pub groups: Vec<BSplineHistogram>,
}

impl GroupedHistogram {
    /// `groups` empty histograms (at least one).
    pub fn new(groups: usize, bins: usize) -> Self {
        Self {
            groups: vec![BSplineHistogram::new(bins); groups.max(1)],
        }
    }

    /// Adds one sample of group `g` (clamped to the last group).
    #[inline]
    pub fn add(&mut self, g: u8, a: f32, b: f32) {
        let k = usize::from(g).min(self.groups.len() - 1);
        self.groups[k].add(a, b);
    }

    /// Adds another grouped histogram of the same shape (parallel reduction).
    pub fn merge(self, other: &Self) -> Self {
        let groups = self
            .groups
            .into_iter()
            .zip(&other.groups)
            .map(|(x, y)| x.merge(y))
            .collect();
        Self { groups }
    }

    /// Samples over all groups.
    pub fn total(&self) -> f64 {
        self.groups.iter().map(|h| h.total).sum()
    }

    /// The sample-weighted MI and NMI (a single group: its own score).
    pub fn score(&self) -> MiScore {
        if let [only] = self.groups.as_slice() {
            return only.score();
        }
        weighted_score(self.groups.iter().map(|h| h.score()))
    }
}

/// `sum n_k s_k / sum n_k` of MI and NMI, samples summed.
pub fn weighted_score(scores: impl Iterator<Item = MiScore>) -> MiScore {
    let (mut mi, mut nmi, mut n) = (0.0, 0.0, 0usize);
    for s in scores {
        mi += s.mi * s.samples as f64;
        nmi += s.nmi * s.samples as f64;
        n += s.samples;
    }
    let d = n.max(1) as f64;
    MiScore {
        mi: mi / d,
        nmi: nmi / d,
        samples: n,
    }
}
