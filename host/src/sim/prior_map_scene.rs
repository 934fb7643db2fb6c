//! The ground of the prior-map scenario: a four-way intersection on the plane z = 0 of
//! the world `W` (x east, y north). Two 14 m roads cross at the origin; asphalt with
//! multi-scale value noise, repair patches and manholes; lane markings (centre lines,
//! dashed lane lines, edge lines, stop lines, zebra crossings); concrete sidewalks with
//! tile joints; grass beyond. Every surface has a visible albedo (camera, satellite) and a
//! near-infrared one (the LiDAR reflectivity), which differ: grass is dark in the visible
//! and bright in the near infrared, markings are retro-reflective.

use nalgebra::Vector2;
use rand::Rng;
use rand_chacha::ChaCha8Rng;

/// Half width of each road (m).
pub const ROAD_HALF_WIDTH_M: f64 = 7.0;
/// Outer edge of the sidewalks (m from the road axis).
const SIDEWALK_OUTER_M: f64 = 11.0;
/// Albedo of paint.
const PAINT: f64 = 0.92;

/// A rotated rectangle of asphalt repair.
#[derive(Clone, Copy, Debug)]
pub struct Patch {
    /// Centre in W (m).
    pub centre: Vector2<f64>,
    /// Half sizes along its own axes (m).
    pub half: Vector2<f64>,
    /// Rotation (rad).
    pub angle: f64,
    /// Visible albedo.
    pub albedo: f64,
}

impl Patch {
    /// The four corners in W.
    pub fn corners(&self) -> [Vector2<f64>; 4] {
        let (s, c) = self.angle.sin_cos();
        let ax = Vector2::new(c, s) * self.half.x;
        let ay = Vector2::new(-s, c) * self.half.y;
        [
            self.centre - ax - ay,
            self.centre + ax - ay,
            self.centre + ax + ay,
            self.centre - ax + ay,
        ]
    }

    fn contains(&self, p: Vector2<f64>) -> bool {
        let d = p - self.centre;
        let (s, c) = self.angle.sin_cos();
        (c * d.x + s * d.y).abs() < self.half.x && (-s * d.x + c * d.y).abs() < self.half.y
    }
}

/// Albedos of one ground point.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Surface {
    /// Visible albedo in [0, 1] (camera and satellite).
    pub visible: f64,
    /// Near-infrared albedo in [0, 1] (LiDAR reflectivity).
    pub nir: f64,
}

/// The intersection.
#[derive(Clone, Debug)]
pub struct Intersection {
    /// Asphalt repair patches.
    pub patches: Vec<Patch>,
    /// Manholes: centre and radius (m).
    pub manholes: Vec<(Vector2<f64>, f64)>,
    noise_seed: u64,
}

/// A hash of a lattice cell to [0, 1).
fn lattice(seed: u64, i: i64, j: i64) -> f64 {
    let mut h = seed ^ (i as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15);
    h ^= (j as u64).wrapping_mul(0xC2B2_AE3D_27D4_EB4F);
    h = (h ^ (h >> 31)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    h = (h ^ (h >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    (h >> 11) as f64 / (1u64 << 53) as f64
}

/// Smooth value noise in [0, 1) with cells of `cell` m.
fn value_noise(seed: u64, x: f64, y: f64, cell: f64) -> f64 {
    let (fx, fy) = (x / cell, y / cell);
    let (i, j) = (fx.floor(), fy.floor());
    let smooth = |t: f64| t * t * (3.0 - 2.0 * t);
    let (tx, ty) = (smooth(fx - i), smooth(fy - j));
    let (i, j) = (i as i64, j as i64);
    let a = lattice(seed, i, j) + (lattice(seed, i + 1, j) - lattice(seed, i, j)) * tx;
    let b = lattice(seed, i, j + 1) + (lattice(seed, i + 1, j + 1) - lattice(seed, i, j + 1)) * tx;
    a + (b - a) * ty
}

/// Markings of a road along the first coordinate `s`, `t` across it (both m); the
/// intersection box is |s| < `SIDEWALK_OUTER_M`.
fn road_marking(s: f64, t: f64) -> bool {
    let a = s.abs();
    if a < ROAD_HALF_WIDTH_M {
        return false;
    }
    // Zebra crossing between the sidewalks' extension: bars 0.5 m wide every 1 m.
    if a < SIDEWALK_OUTER_M - 0.5 && a > ROAD_HALF_WIDTH_M + 0.5 {
        return t.abs() < ROAD_HALF_WIDTH_M - 0.4 && (t + 0.25).rem_euclid(1.0) < 0.5;
    }
    if a < SIDEWALK_OUTER_M + 1.0 {
        return false;
    }
    // Stop line on the inbound half (right-hand traffic).
    let inbound = (s > 0.0 && t > 0.0) || (s < 0.0 && t < 0.0);
    if a < SIDEWALK_OUTER_M + 1.5 && inbound && t.abs() < ROAD_HALF_WIDTH_M - 0.3 {
        return true;
    }
    let dash = (a - SIDEWALK_OUTER_M - 3.0).rem_euclid(9.0) < 3.0;
    let centre = (t.abs() - 0.12).abs() < 0.06;
    let lane = (t.abs() - 3.5).abs() < 0.075 && dash;
    let edge = (t.abs() - (ROAD_HALF_WIDTH_M - 0.35)).abs() < 0.1;
    centre || lane || edge
}

impl Intersection {
    /// A random intersection: patch and manhole layout from `rng`.
    pub fn random(rng: &mut ChaCha8Rng, half_size_m: f64) -> Self {
        let on_road = |rng: &mut ChaCha8Rng| {
            let along = rng.gen_range(-half_size_m..half_size_m);
            let across = rng.gen_range(-ROAD_HALF_WIDTH_M + 0.8..ROAD_HALF_WIDTH_M - 0.8);
            if rng.gen_bool(0.5) {
                Vector2::new(along, across)
            } else {
                Vector2::new(across, along)
            }
        };
        let patches = (0..(half_size_m * 2.0) as usize)
            .map(|_| Patch {
                centre: on_road(rng),
                half: Vector2::new(rng.gen_range(0.3..1.5), rng.gen_range(0.2..0.9)),
                angle: rng.gen_range(0.0..std::f64::consts::PI),
                albedo: if rng.gen_bool(0.5) {
                    rng.gen_range(0.08..0.14)
                } else {
                    rng.gen_range(0.3..0.4)
                },
            })
            .collect();
        let manholes = (0..(half_size_m / 2.0) as usize)
            .map(|_| (on_road(rng), rng.gen_range(0.3..0.45)))
            .collect();
        Self {
            patches,
            manholes,
            noise_seed: rng.gen(),
        }
    }

    /// Albedos at world (x, y).
    pub fn surface(&self, x: f64, y: f64) -> Surface {
        let p = Vector2::new(x, y);
        let seed = self.noise_seed;
        let (ax, ay) = (x.abs(), y.abs());
        let road = ax < ROAD_HALF_WIDTH_M || ay < ROAD_HALF_WIDTH_M;
        if !road {
            let fine = value_noise(seed ^ 1, x, y, 0.4) - 0.5;
            let coarse = value_noise(seed ^ 2, x, y, 2.5) - 0.5;
            if ax < SIDEWALK_OUTER_M || ay < SIDEWALK_OUTER_M {
                // Concrete tiles of 1.5 m with dark joints; a darker curb stone.
                let joint = (x.rem_euclid(1.5) < 0.05) || (y.rem_euclid(1.5) < 0.05);
                let curb = ax.min(ay) < ROAD_HALF_WIDTH_M + 0.25;
                let v = if curb {
                    0.45
                } else if joint {
                    0.3
                } else {
                    0.58 + 0.1 * fine + 0.08 * coarse
                };
                return Surface { visible: v, nir: v };
            }
            let v = 0.28 + 0.25 * fine + 0.2 * coarse;
            return Surface {
                visible: v.clamp(0.02, 1.0),
                nir: (0.75 + 0.2 * fine).clamp(0.0, 1.0),
            };
        }
        if road_marking(x, y) || road_marking(y, x) {
            return Surface {
                visible: PAINT,
                nir: 0.98,
            };
        }
        for (c, r) in &self.manholes {
            let d = (p - c).norm();
            if d < *r {
                let ring = d > r - 0.06 || ((p - c).x * 12.0).sin() > 0.6;
                let v = if ring { 0.38 } else { 0.1 };
                return Surface { visible: v, nir: v };
            }
        }
        let mut v = 0.22
            + 0.09 * (value_noise(seed ^ 3, x, y, 0.25) - 0.5)
            + 0.12 * (value_noise(seed ^ 4, x, y, 0.9) - 0.5)
            + 0.1 * (value_noise(seed ^ 5, x, y, 4.0) - 0.5);
        if let Some(patch) = self.patches.iter().find(|q| q.contains(p)) {
            v = patch.albedo + 0.05 * (value_noise(seed ^ 6, x, y, 0.3) - 0.5);
        }
        Surface {
            visible: v.clamp(0.02, 1.0),
            nir: (0.5 * v + 0.05).clamp(0.0, 1.0),
        }
    }

    /// Distinct points for a survey: patch corners and manhole centres (z = 0).
    pub fn survey_candidates(&self) -> Vec<Vector2<f64>> {
        self.patches
            .iter()
            .flat_map(Patch::corners)
            .chain(self.manholes.iter().map(|(c, _)| *c))
            .collect()
    }
}

/// Soft rectangular shadows: each `(centre, half size, angle)` darkens by `depth`, with
/// edges blurred over `soft` m.
#[derive(Clone, Debug)]
pub struct Shadows {
    /// The shadow boxes.
    pub boxes: Vec<Patch>,
    /// Fraction of light removed inside.
    pub depth: f64,
    /// Edge softness (m).
    pub soft: f64,
}

impl Shadows {
    /// `n` random shadow boxes (buildings, trees) within `half_size_m` of the centre.
    pub fn random(rng: &mut ChaCha8Rng, n: usize, half_size_m: f64, depth: f64) -> Self {
        let boxes = (0..n)
            .map(|_| Patch {
                centre: Vector2::new(
                    rng.gen_range(-half_size_m..half_size_m),
                    rng.gen_range(-half_size_m..half_size_m),
                ),
                half: Vector2::new(rng.gen_range(1.5..5.0), rng.gen_range(1.0..3.0)),
                angle: rng.gen_range(0.0..std::f64::consts::PI),
                albedo: 0.0,
            })
            .collect();
        Self {
            boxes,
            depth,
            soft: 0.3,
        }
    }

    /// Light factor in (0, 1] at world (x, y).
    pub fn light(&self, x: f64, y: f64) -> f64 {
        let mut shade: f64 = 0.0;
        for b in &self.boxes {
            let d = Vector2::new(x, y) - b.centre;
            let (s, c) = b.angle.sin_cos();
            let ex = (c * d.x + s * d.y).abs() - b.half.x;
            let ey = (-s * d.x + c * d.y).abs() - b.half.y;
            let outside = ex.max(ey);
            let t = (0.5 - outside / self.soft).clamp(0.0, 1.0);
            shade = shade.max(t);
        }
        1.0 - self.depth * shade
    }
}
