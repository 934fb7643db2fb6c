//! The linear least squares of the alignment (VINS-Mono's visual-inertial alignment with
//! the lever arm and the accelerometer bias as extra unknowns): assembly of the normal
//! equations from 3-row residual blocks, the solve, and the residual statistics.

use nalgebra::{DMatrix, DVector, Matrix3, Matrix3x2, Matrix3xX, Vector3};

use super::Window;

/// Which group a residual block belongs to (each has its own noise variance).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Group {
    /// Position increments (pose translation noise), m.
    Position = 0,
    /// Velocity increments (rotation noise times the velocity change), m/s.
    Velocity = 1,
    /// Priors on the lever arm and the accelerometer bias (their sigma is in the block).
    Prior = 2,
}

/// Three residual rows `sum_i A_i x[col_i..] - rhs`, unweighted, with noise
/// `scale * sigma_group` per row.
pub(crate) struct RowBlock {
    pub group: Group,
    pub scale: f64,
    pub pieces: Vec<(usize, Matrix3xX<f64>)>,
    pub rhs: Vector3<f64>,
}

/// How gravity enters the unknowns.
#[derive(Debug, Clone, Copy)]
pub(crate) enum GravityModel {
    /// `g_O` itself, 3 unknowns (the first, linear solve).
    Free,
    /// `g_O = g + B w`, `w` the 2 unknowns on the tangent plane of the sphere `|g_O| = |g|`.
    Tangent {
        gravity: Vector3<f64>,
        basis: Matrix3x2<f64>,
    },
}

impl GravityModel {
    pub fn dim(&self) -> usize {
        match self {
            Self::Free => 3,
            Self::Tangent { .. } => 2,
        }
    }

    /// `(coefficient of the unknowns, known part)` of `g_O * scale`.
    fn terms(&self, scale: f64) -> (Matrix3xX<f64>, Vector3<f64>) {
        match self {
            Self::Free => (
                Matrix3xX::from_column_slice(Matrix3::identity().as_slice()) * scale,
                Vector3::zeros(),
            ),
            Self::Tangent { gravity, basis } => (
                Matrix3xX::from_column_slice(basis.as_slice()) * scale,
                gravity * scale,
            ),
        }
    }
}

/// Unknown layout: `v_0 .. v_N` (3 each), gravity, lever arm `p_I_S`, accelerometer bias.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Layout {
    pub velocities: usize,
    pub gravity_dim: usize,
}

impl Layout {
    pub fn gravity(&self) -> usize {
        3 * self.velocities
    }
    pub fn lever(&self) -> usize {
        self.gravity() + self.gravity_dim
    }
    pub fn accel_bias(&self) -> usize {
        self.lever() + 3
    }
    pub fn len(&self) -> usize {
        self.accel_bias() + 3
    }
}

fn block(m: Matrix3<f64>) -> Matrix3xX<f64> {
    Matrix3xX::from_column_slice(m.as_slice())
}

/// The residual blocks of `window` for the IMU-to-sensor rotation `r_i_s`:
/// position `v_k dt + g dt^2/2 + (R_k+1 - R_k) p + R_k J_p b_a = dp_S - R_k dp`,
/// velocity `v_k+1 - v_k - g dt - R_k J_v b_a = R_k dv` (`R_k = R_O_I` at pose `k`),
/// and the priors `p = 0 +- sigma_p`, `b_a = 0 +- sigma_b` (their rows carry `1/sigma`).
/// The velocity rows' noise is modelled, not estimated (they have almost no redundancy: each
/// new velocity absorbs one): `sigma^2 = q_a dt + (sigma_rot |dv|)^2`, accelerometer white
/// noise plus the pose rotation noise turning the velocity increment.
pub(crate) fn residual_blocks(
    window: &Window,
    r_i_s: &Matrix3<f64>,
    gravity: &GravityModel,
    noise: &Noise,
) -> (Layout, Vec<RowBlock>) {
    let layout = Layout {
        velocities: window.intervals.len() + 1,
        gravity_dim: gravity.dim(),
    };
    let mut blocks = Vec::with_capacity(2 * window.intervals.len() + 2);
    for (k, iv) in window.intervals.iter().enumerate() {
        let (dt, pre) = (iv.pre.dt, &iv.pre);
        let r_a = iv.r_o_s_a * r_i_s.transpose();
        let r_b = iv.r_o_s_b * r_i_s.transpose();
        let (g_pos, g_pos_known) = gravity.terms(0.5 * dt * dt);
        blocks.push(RowBlock {
            group: Group::Position,
            scale: 1.0,
            pieces: vec![
                (3 * k, block(Matrix3::identity() * dt)),
                (layout.gravity(), g_pos),
                (layout.lever(), block(r_b - r_a)),
                (layout.accel_bias(), block(r_a * pre.dp_dba)),
            ],
            rhs: iv.dp_o_s - r_a * pre.delta_p - g_pos_known,
        });
        let (g_vel, g_vel_known) = gravity.terms(-dt);
        let velocity_sigma = (noise.accel_density.powi(2) * dt
            + (noise.pose_rotation_rad * pre.delta_v.norm()).powi(2))
        .sqrt();
        blocks.push(RowBlock {
            group: Group::Velocity,
            scale: velocity_sigma,
            pieces: vec![
                (3 * (k + 1), block(Matrix3::identity())),
                (3 * k, block(-Matrix3::identity())),
                (layout.gravity(), g_vel),
                (layout.accel_bias(), block(-r_a * pre.dv_dba)),
            ],
            rhs: r_a * pre.delta_v - g_vel_known,
        });
    }
    for (col, sigma) in [
        (layout.lever(), noise.lever_prior_m),
        (layout.accel_bias(), noise.accel_bias_prior),
    ] {
        blocks.push(RowBlock {
            group: Group::Prior,
            scale: sigma,
            pieces: vec![(col, block(Matrix3::identity()))],
            rhs: Vector3::zeros(),
        });
    }
    (layout, blocks)
}

/// A weighted solve: the estimate, the normal matrix and the whitened residuals per group.
pub(crate) struct Solution {
    pub x: DVector<f64>,
    pub normal: DMatrix<f64>,
    /// Sum of squared residuals per group, each row divided by its scale, and rows per group.
    pub ssr: [f64; 3],
    pub rows: [usize; 3],
    /// Redundancy per group: rows minus the group's share of the unknowns,
    /// `n_g - trace(W_g A_g N^-1 A_g^T)`.
    pub redundancy: [f64; 3],
}

/// Weighted linear least squares over `blocks` with the position / velocity sigmas `sigmas`
/// (prior rows are already whitened); `None` when the normal matrix is not positive definite.
pub(crate) fn solve(layout: &Layout, blocks: &[RowBlock], sigmas: &[f64; 2]) -> Option<Solution> {
    let n = layout.len();
    let mut normal = DMatrix::<f64>::zeros(n, n);
    let mut b = DVector::<f64>::zeros(n);
    for blk in blocks {
        let w = weight(blk, sigmas);
        for (ci, ai) in &blk.pieces {
            let ai_t = ai.transpose();
            let mut rows = b.rows_mut(*ci, ai.ncols());
            rows += &ai_t * blk.rhs * w;
            for (cj, aj) in &blk.pieces {
                let mut view = normal.view_mut((*ci, *cj), (ai.ncols(), aj.ncols()));
                view += &ai_t * aj * w;
            }
        }
    }
    let cholesky = normal.clone().cholesky()?;
    let x = cholesky.solve(&b);
    let inverse = cholesky.inverse();
    if !x.iter().all(|v| v.is_finite()) {
        return None;
    }
    let mut ssr = [0.0; 3];
    let mut rows = [0; 3];
    let mut redundancy = [0.0; 3];
    for blk in blocks {
        let mut r = -blk.rhs;
        for (c, a) in &blk.pieces {
            r += a * x.rows(*c, a.ncols());
        }
        ssr[blk.group as usize] += r.norm_squared() / (blk.scale * blk.scale);
        rows[blk.group as usize] += 3;
        let w = weight(blk, sigmas);
        let mut share = 0.0;
        for (ci, ai) in &blk.pieces {
            for (cj, aj) in &blk.pieces {
                let n_ij = inverse.view((*ci, *cj), (ai.ncols(), aj.ncols()));
                share += (ai * n_ij * aj.transpose()).trace() * w;
            }
        }
        redundancy[blk.group as usize] -= share;
    }
    for g in 0..3 {
        redundancy[g] += rows[g] as f64;
    }
    Some(Solution {
        x,
        normal,
        ssr,
        rows,
        redundancy,
    })
}

fn weight(blk: &RowBlock, sigmas: &[f64; 2]) -> f64 {
    let group = match blk.group {
        Group::Position => sigmas[0],
        Group::Velocity => sigmas[1],
        Group::Prior => 1.0,
    };
    1.0 / (group * blk.scale).powi(2)
}

/// Noise model and priors of the rows.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Noise {
    pub accel_density: f64,
    pub pose_rotation_rad: f64,
    pub lever_prior_m: f64,
    pub accel_bias_prior: f64,
}

/// The position rows' sigma from their residuals (variance component, Foerstner): their sum
/// of squared residuals over their redundancy. The velocity rows keep their modelled noise.
pub(crate) fn variance_components(solution: &Solution) -> [f64; 2] {
    let position = (solution.ssr[0] / solution.redundancy[0].max(1.0)).sqrt();
    [position.max(1e-9), 1.0]
}
