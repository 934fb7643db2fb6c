//! Voxel-grid filter and the fast integer-voxel hash map it shares with NDT.

use std::collections::HashMap;
use std::hash::{BuildHasherDefault, Hash, Hasher};

use nalgebra::Vector3;

use super::{Point, PointCloud};

/// Integer coordinates of a cubic voxel: `floor(p / size)` per axis.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct VoxelKey(pub [i32; 3]);

impl VoxelKey {
    /// The voxel of side `inv_size.recip()` containing `p` (`inv_size` = 1 / side).
    #[inline]
    pub fn of(p: &Vector3<f64>, inv_size: f64) -> Self {
        // `as` saturates, so far-away points land in the outermost voxel
        // instead of wrapping around.
        Self([
            (p.x * inv_size).floor() as i32,
            (p.y * inv_size).floor() as i32,
            (p.z * inv_size).floor() as i32,
        ])
    }

    /// The key shifted by `d` voxels.
    #[inline]
    pub fn offset(self, d: [i32; 3]) -> Self {
        let k = self.0;
        Self([
            k[0].wrapping_add(d[0]),
            k[1].wrapping_add(d[1]),
            k[2].wrapping_add(d[2]),
        ])
    }
}

impl Hash for VoxelKey {
    #[inline]
    fn hash<H: Hasher>(&self, state: &mut H) {
        let [x, y, z] = self.0.map(|v| u64::from(v as u32));
        state.write_u64(x ^ y.rotate_left(21) ^ z.rotate_left(42));
    }
}

/// Multiplicative hasher for [`VoxelKey`] (std's SipHash costs more than
/// the rest of an NDT score evaluation).
#[derive(Debug, Default, Clone, Copy)]
pub struct VoxelHasher(u64);

impl Hasher for VoxelHasher {
    #[inline]
    fn finish(&self) -> u64 {
        let h = self.0.wrapping_mul(0x9E37_79B9_7F4A_7C15);
        h ^ (h >> 32)
    }

    #[inline]
    fn write(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.0 = (self.0.rotate_left(8) ^ u64::from(b)).wrapping_mul(0x100_0000_01B3);
        }
    }

    #[inline]
    fn write_u64(&mut self, v: u64) {
        self.0 ^= v;
    }
}

/// A hash map keyed by voxel.
pub type VoxelMap<V> = HashMap<VoxelKey, V, BuildHasherDefault<VoxelHasher>>;

/// Voxel-grid filter: one point per occupied cubic voxel of side `leaf_m`,
/// at the centroid of the voxel's points, with their mean intensity and
/// mean time offset and the ring of the voxel's first point. Output order is
/// the order in which voxels are first hit, so the result is deterministic.
/// A non-positive or non-finite `leaf_m` returns the cloud unchanged.
pub fn voxel_downsample(cloud: &PointCloud, leaf_m: f64) -> PointCloud {
    if !(leaf_m.is_finite() && leaf_m > 0.0) {
        return cloud.clone();
    }
    struct Acc {
        sum: Vector3<f64>,
        intensity: f64,
        t_ns: u64,
        n: u32,
        ring: u16,
    }
    let inv = leaf_m.recip();
    let mut index: VoxelMap<usize> = VoxelMap::default();
    let mut accs: Vec<Acc> = Vec::new();
    for p in &cloud.points {
        let i = *index.entry(VoxelKey::of(&p.xyz, inv)).or_insert_with(|| {
            accs.push(Acc {
                sum: Vector3::zeros(),
                intensity: 0.0,
                t_ns: 0,
                n: 0,
                ring: p.ring,
            });
            accs.len() - 1
        });
        let a = &mut accs[i];
        a.sum += p.xyz;
        a.intensity += f64::from(p.intensity);
        a.t_ns += u64::from(p.t_ns);
        a.n += 1;
    }
    let points = accs
        .into_iter()
        .map(|a| {
            let n = f64::from(a.n);
            Point {
                xyz: a.sum / n,
                intensity: (a.intensity / n) as f32,
                t_ns: (a.t_ns / u64::from(a.n)) as u32,
                ring: a.ring,
            }
        })
        .collect();
    PointCloud::new(points)
}
