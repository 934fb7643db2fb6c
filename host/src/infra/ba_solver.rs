//! Levenberg-Marquardt for the bundle adjustment of [`super::ba`], scaled to thousands of
//! keyframes and millions of keypoints:
//! - each iteration projects every keypoint once: its Jacobians and Cauchy weight go
//!   straight into the point's `V`, `g_p` and its `W = J_kf^T J_point` blocks (one per
//!   keyframe that sees the point, 144 bytes each, 0.54 GB at 3.7 M keypoints), which are
//!   cached for the Schur complement and the back-substitution;
//! - the points are eliminated by the Schur complement, a group of points at a time, in
//!   parallel (one partial reduced system per thread);
//! - the reduced system (6 per keyframe `k >= 1`, camera and `T_F_M`) keeps a fixed
//!   block-sparse pattern ([`super::blocksym`]) and is factored by faer's sparse
//!   (supernodal) Cholesky, symbolic analysis once (in the blocks' own order when that
//!   fills less than minimum degree), its buffers reused across iterations;
//! - the marker, blob and epipolar terms are linearised in parallel;
//! - by default ([`Steps::Inexact`]) the steps after the first alternate with exact ones
//!   while the iterations move far: a step by conjugate gradients on the implicit reduced
//!   system (`pcg`), preconditioned by the factor of the last exact step, taken as it is
//!   when it runs out of products and then followed by an exact step; near the minimum
//!   the conjugate gradients converge in a few products and the steps stay inexact until
//!   the cost stalls, when one exact step confirms the stop and its factor gives the
//!   covariance (no factorisation of its own).
//!
//! Damping: `lambda * diag` on the reduced-side blocks and on each point block, as
//! Marquardt scaled; the step is accepted when the robust cost decreases.

use nalgebra::{Matrix3, Matrix6, Matrix6x3, SMatrix, SVector, Vector2, Vector3, Vector6};
use rayon::prelude::*;
use std::ops::Range;
use std::time::Instant;

use super::ba::{blob_term, epipolar_term, marker_term, plus, vo_term_from, BaProblem, BaState};
use super::blocksym::{BlockPattern, Factor, PatternBuilder};

mod pcg;

/// How [`solve_with`] runs.
#[derive(Clone, Copy, Debug)]
pub struct Options {
    /// Levenberg-Marquardt iterations (accepted + rejected) at most.
    pub max_iterations: usize,
    /// How the steps are solved.
    pub steps: Steps,
    /// Conjugate gradients stop at this residual, relative to the reduced right-hand
    /// side's norm.
    pub pcg_tolerance: f64,
    /// Products with the reduced system per conjugate-gradient step at most.
    pub pcg_max_products: usize,
}

impl Options {
    /// Conjugate-gradient steps ([`Steps::Inexact`]) to a relative residual of 1e-2 in at
    /// most 8 products, chosen on the quarter-size benchmark problem (docs/benchmarks.md),
    /// not on the accuracy tests' seeds; at most `max_iterations`.
    pub fn new(max_iterations: usize) -> Self {
        Self {
            max_iterations,
            steps: Steps::Inexact,
            pcg_tolerance: 1e-2,
            pcg_max_products: 8,
        }
    }

    /// Every step exact.
    pub fn exact(max_iterations: usize) -> Self {
        Self {
            steps: Steps::Exact,
            ..Self::new(max_iterations)
        }
    }
}

/// Solution of the bundle adjustment.
#[derive(Clone, Debug)]
pub struct BaSolution {
    /// The state at the minimum.
    pub state: BaState,
    /// Covariance of each camera's `[theta, p]` (right perturbation of `T_vo_C`).
    pub camera_covariances: Vec<Matrix6<f64>>,
    /// Robust cost at the start and the end (whitened units).
    pub initial_cost: f64,
    /// See `initial_cost`.
    pub final_cost: f64,
    /// Accepted + rejected iterations.
    pub iterations: usize,
    /// Rejected iterations (the cost did not decrease or the system was not positive
    /// definite).
    pub rejected: usize,
    /// Variance factor (robust cost, i.e. whitened chi-square, per degree of freedom)
    /// applied to the covariances.
    pub variance_factor: f64,
    /// Steps solved exactly (reduced system formed and factored; the covariance's
    /// factorisation not counted).
    pub exact_steps: usize,
    /// Products with the implicit reduced system in the conjugate-gradient steps.
    pub pcg_products: usize,
    /// Wall time per phase.
    pub timings: Timings,
    /// Each iteration's step.
    pub trace: Vec<Iteration>,
}

/// One Levenberg-Marquardt iteration, as [`BaSolution::trace`] records it.
#[derive(Clone, Copy, Debug)]
pub struct Iteration {
    /// The candidate's robust cost (NaN: no candidate, the system was not positive
    /// definite or a projection failed).
    pub cost: f64,
    /// The damping of the step.
    pub lambda: f64,
    /// Whether the step was solved exactly (reduced system formed and factored).
    pub exact: bool,
    /// Conjugate-gradient products tried for the step.
    pub products: usize,
    /// Whether the candidate was accepted.
    pub accepted: bool,
}

/// Wall time (seconds) spent in each phase of [`solve_with`].
#[derive(Clone, Copy, Debug, Default)]
pub struct Timings {
    /// The problem's structure: keypoints by point, the reduced system's pattern and its
    /// symbolic factorisation.
    pub structure: f64,
    /// Linearisations (every term projected, `U`, `V`, `W`, gradients).
    pub linearise: f64,
    /// Schur complements formed (`reduced`).
    pub eliminate: f64,
    /// Numeric Cholesky factorisations.
    pub factor: f64,
    /// Conjugate-gradient solves (products and preconditioning).
    pub pcg: f64,
    /// Back-substitutions, triangular solves of the exact steps and state updates.
    pub back: f64,
    /// The covariance's solves (its elimination and factorisation counted above).
    pub covariance: f64,
}

/// Adds the wall time of `f` to `acc`.
fn timed<T>(acc: &mut f64, f: impl FnOnce() -> T) -> T {
    let t = std::time::Instant::now();
    let out = f();
    *acc += t.elapsed().as_secs_f64();
    out
}

/// How each Levenberg-Marquardt step is solved.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Steps {
    /// Every step exactly: Schur complement formed, factored, solved.
    Exact,
    /// By conjugate gradients on the implicit reduced system, preconditioned with the
    /// factor of the last exact step. Exact instead: the first step; the step after a
    /// conjugate-gradient step that ran out of products (which is taken as it is: the
    /// iterate still decreases the quadratic model; the next exact step refreshes the
    /// stale preconditioner); the step after a rejection; and the step after one that
    /// decreased the cost by less than the stop threshold, so the iterations always end
    /// on an exact step, whose factor also gives the covariance.
    Inexact,
}

/// Block numbers of the reduced system.
struct Layout {
    kfs: usize,
    cams: usize,
}

impl Layout {
    fn kf(&self, k: usize) -> Option<usize> {
        (k >= 1).then(|| k - 1)
    }
    fn cam(&self, c: usize) -> usize {
        self.kfs - 1 + c
    }
    fn tfm(&self) -> usize {
        self.kfs - 1 + self.cams
    }
    fn blocks(&self) -> usize {
        self.tfm() + 1
    }
    fn marker_blocks(&self, m: &super::ba::MarkerObs) -> [Option<usize>; 4] {
        let j = if m.i == m.j { None } else { self.kf(m.j) };
        [self.kf(m.i), j, Some(self.tfm()), Some(self.cam(m.cam))]
    }
}

/// What does not change between iterations: layout, pattern, keypoints per point (sorted
/// by keyframe) and the split of the points over the threads. Per-point arrays of the
/// solver (`V`, `g_p`, steps) are in processing order.
struct Structure {
    lay: Layout,
    pat: BlockPattern,
    /// The keypoints `(keyframe, pixel)` of each point, points in processing order
    /// (`order[k]` is the point), each point's sorted by keyframe: point `j`'s are
    /// `keypoints[kp_ptr[j]..kp_ptr[j + 1]]` (one array read in order by the linearisation).
    keypoints: Vec<(u32, Vector2<f64>)>,
    kp_ptr: Vec<usize>,
    order: Vec<usize>,
    chunks: Vec<Range<usize>>,
    /// The `W` entries of point `j` (processing order), one per keyframe `>= 1` that sees
    /// it (its keypoints in that keyframe summed, which is exact): `w_ptr[j]..w_ptr[j + 1]`.
    w_ptr: Vec<usize>,
    /// Reduced-system block of each `W` entry.
    w_block: Vec<usize>,
    /// The slots `(slot, a, b)` the terms other than keypoints fill in `U` (and every
    /// diagonal): the implicit product reads only these.
    u_slots: Vec<(usize, usize, usize)>,
}

fn structure(p: &BaProblem<'_>, start: &BaState) -> Option<Structure> {
    let lay = Layout {
        kfs: start.kf.len(),
        cams: start.cams.len(),
    };
    let (order, keypoints, kp_ptr) = keypoints_by_point(p, start.points.len())?;
    let mut b = PatternBuilder::new(lay.blocks());
    let (mut w_ptr, mut w_block) = (vec![0], Vec::new());
    let mut blocks = Vec::new();
    for j in 0..order.len() {
        // A point's keypoints are sorted by keyframe: its `W` entries are the distinct ones.
        blocks.clear();
        for (kf, _) in &keypoints[kp_ptr[j]..kp_ptr[j + 1]] {
            if let Some(a) = lay.kf(*kf as usize) {
                if blocks.last() != Some(&a) {
                    blocks.push(a);
                }
            }
        }
        b.mark_all(&blocks);
        w_block.extend_from_slice(&blocks);
        w_ptr.push(w_block.len());
    }
    for o in &p.blobs {
        if let Some(k) = lay.kf(o.kf) {
            b.mark(k, lay.cam(o.cam));
        }
    }
    for m in &p.markers {
        let list: Vec<usize> = lay.marker_blocks(m).iter().flatten().copied().collect();
        b.mark_all(&list);
    }
    for o in &p.epipolar {
        b.mark(lay.cam(o.a), lay.cam(o.b));
    }
    let chunks = split(&kp_ptr, rayon::current_num_threads().max(1));
    let pat = b.finish()?;
    let u_slots = u_slots(p, &lay, &pat)?;
    Some(Structure {
        lay,
        pat,
        keypoints,
        kp_ptr,
        order,
        chunks,
        w_ptr,
        w_block,
        u_slots,
    })
}

/// Processing order of the points (by their first keyframe: neighbouring points update
/// neighbouring blocks of the reduced system, cache reuse in the Schur complement) and
/// their keypoints `(keyframe, pixel)` in that order, each point's sorted by keyframe
/// (stable: equal keyframes in input order), with the offsets. Counting sorts reading the
/// observations in their order (indexing them by point is a cache miss per keypoint).
type ByPoint = (Vec<usize>, Vec<(u32, Vector2<f64>)>, Vec<usize>);

fn keypoints_by_point(p: &BaProblem<'_>, points: usize) -> Option<ByPoint> {
    let (mut count, mut first) = (vec![0usize; points], vec![usize::MAX; points]);
    for o in &p.vo {
        *count.get_mut(o.point)? += 1;
        first[o.point] = first[o.point].min(o.kf);
        u32::try_from(o.kf).ok()?;
    }
    let mut order: Vec<usize> = (0..points).collect();
    order.sort_by_key(|&j| first[j]);
    let mut kp_ptr = Vec::with_capacity(points + 1);
    kp_ptr.push(0);
    let mut cursor = vec![0; points];
    for &j in &order {
        cursor[j] = *kp_ptr.last()?;
        kp_ptr.push(cursor[j] + count[j]);
    }
    let mut keypoints = vec![(0u32, Vector2::zeros()); p.vo.len()];
    for o in &p.vo {
        keypoints[cursor[o.point]] = (o.kf as u32, o.uv);
        cursor[o.point] += 1;
    }
    for j in 0..points {
        keypoints[kp_ptr[j]..kp_ptr[j + 1]].sort_by_key(|k| k.0);
    }
    Some((order, keypoints, kp_ptr))
}

/// The slots of `U` that other terms than the keypoints fill, and the diagonal.
fn u_slots(
    p: &BaProblem<'_>,
    lay: &Layout,
    pat: &BlockPattern,
) -> Option<Vec<(usize, usize, usize)>> {
    let mut pairs: Vec<(usize, usize)> = (0..lay.blocks()).map(|b| (b, b)).collect();
    for o in &p.blobs {
        if let Some(k) = lay.kf(o.kf) {
            pairs.push((k, lay.cam(o.cam)));
        }
    }
    for m in &p.markers {
        let list: Vec<usize> = lay.marker_blocks(m).iter().flatten().copied().collect();
        for &a in &list {
            pairs.extend(list.iter().map(|&b| (a, b)));
        }
    }
    pairs.extend(p.epipolar.iter().map(|o| (lay.cam(o.a), lay.cam(o.b))));
    let mut out = Vec::with_capacity(pairs.len());
    for (a, b) in pairs {
        let (a, b) = (a.min(b), a.max(b));
        out.push((pat.slot(a, b)?, a, b));
    }
    out.sort_unstable();
    out.dedup();
    Some(out)
}

/// Contiguous ranges of points (keypoints `ptr[j]..ptr[j + 1]` each) with about equal
/// numbers of pairs of keypoints.
fn split(ptr: &[usize], parts: usize) -> Vec<Range<usize>> {
    let work: Vec<usize> = ptr.windows(2).map(|w| (w[1] - w[0]).pow(2) + 1).collect();
    let total: usize = work.iter().sum();
    let mut out = Vec::new();
    let (mut start, mut acc) = (0, 0);
    for (j, w) in work.iter().enumerate() {
        acc += w;
        if acc * parts >= total * (out.len() + 1) && out.len() + 1 < parts {
            out.push(start..j + 1);
            start = j + 1;
        }
    }
    out.push(start..work.len());
    out
}

/// One linearisation: the reduced-side blocks `U` (all terms, undamped), gradient `g`,
/// and per point `V`, `g_p`.
struct Lin {
    u: Vec<Matrix6<f64>>,
    g: Vec<f64>,
    v: Vec<Matrix3<f64>>,
    gp: Vec<Vector3<f64>>,
    cost: f64,
    count: usize,
}

/// Adds a dense term `J^T J`, `J^T r` over the blocks `blocks` (6 columns each, `None`
/// = fixed) into `lin`.
fn add_dense<const N: usize>(
    lin: &mut Lin,
    pat: &BlockPattern,
    blocks: &[Option<usize>],
    jtj: &SMatrix<f64, N, N>,
    jtr: &SVector<f64, N>,
) {
    for (i, bi) in blocks.iter().enumerate() {
        let Some(bi) = *bi else { continue };
        for k in 0..6 {
            lin.g[6 * bi + k] += jtr[6 * i + k];
        }
        for (j, bj) in blocks.iter().enumerate() {
            match *bj {
                Some(bj) if bi <= bj => {
                    let slot = pat.slot(bi, bj).expect("pattern holds every term's blocks");
                    lin.u[slot] += jtj.fixed_view::<6, 6>(6 * i, 6 * j);
                }
                _ => {}
            }
        }
    }
}

/// Per-thread sums of the keypoint terms of a range of points (the per-point `V`, `g_p`
/// and `W` go straight into their slices of the linearisation).
struct VoSums {
    diag: Vec<Matrix6<f64>>,
    g: Vec<f64>,
    cost: f64,
    count: usize,
}

/// A keyframe pose as `(R^T, t)`, the form its keypoints are projected with.
type Frame = (Matrix3<f64>, Vector3<f64>);

/// The per-point outputs of one range of points: `V`, `g_p` and the `W` entries.
struct VoOut<'a> {
    v: &'a mut [Matrix3<f64>],
    gp: &'a mut [Vector3<f64>],
    w: &'a mut [Matrix6x3<f64>],
}

/// Linearises the keypoints of the points `r`, each projected once: `V`, `g_p` and the
/// `W` entries into `out`, the keyframe diagonal blocks and gradient into the sums.
fn vo_part(
    p: &BaProblem<'_>,
    s: &BaState,
    st: &Structure,
    (r, frames): (Range<usize>, &[Frame]),
    out: VoOut<'_>,
) -> Option<VoSums> {
    let nk = st.lay.kfs;
    let mut sums = VoSums {
        diag: vec![Matrix6::zeros(); nk],
        g: vec![0.0; 6 * nk],
        cost: 0.0,
        count: 0,
    };
    let base = st.w_ptr[r.start];
    for (local, j) in r.enumerate() {
        let (mut v, mut gp) = (Matrix3::zeros(), Vector3::zeros());
        // `W` entries from `fresh` on are not written yet (cleared on first use: clearing
        // the whole array first is one more pass over it).
        let (mut e, mut fresh) = (st.w_ptr[j], st.w_ptr[j]);
        let x = &s.points[st.order[j]];
        for (kf, uv) in &st.keypoints[st.kp_ptr[j]..st.kp_ptr[j + 1]] {
            let kf = *kf as usize;
            let (rt, t) = &frames[kf];
            let (res, jr, jx, rho) = vo_term_from(p, (rt, t), x, uv)?;
            sums.cost += rho;
            sums.count += 2;
            // The keyframe Jacobian's translation columns are `-jx` (`p = R^T (X - t)`),
            // so its products reuse the point's: the same sums as the full `J_kf^T J_kf`,
            // `J_kf^T J_point`, `J_kf^T r` with about half the multiplications.
            let jtj = jx.transpose() * jx;
            let jtr = jx.transpose() * res;
            v += jtj;
            gp += jtr;
            if let Some(a) = st.lay.kf(kf) {
                if st.w_block[e] != a {
                    e += 1;
                }
                let cross = jr.transpose() * jx;
                let w = &mut out.w[e - base];
                if e == fresh {
                    *w = Matrix6x3::zeros();
                    fresh += 1;
                }
                let mut wr = w.fixed_view_mut::<3, 3>(0, 0);
                wr += cross;
                let mut wt = w.fixed_view_mut::<3, 3>(3, 0);
                wt -= jtj;
                let d = &mut sums.diag[a];
                let mut drr = d.fixed_view_mut::<3, 3>(0, 0);
                drr += jr.transpose() * jr;
                let mut drt = d.fixed_view_mut::<3, 3>(0, 3);
                drt -= cross;
                let mut dtr = d.fixed_view_mut::<3, 3>(3, 0);
                dtr -= cross.transpose();
                let mut dtt = d.fixed_view_mut::<3, 3>(3, 3);
                dtt += jtj;
                let gr = jr.transpose() * res;
                for k in 0..3 {
                    sums.g[6 * a + k] += gr[k];
                    sums.g[6 * a + 3 + k] -= jtr[k];
                }
            }
        }
        out.v[local] = v;
        out.gp[local] = gp;
    }
    Some(sums)
}

/// The keypoint terms, in parallel over the point ranges of `st.chunks`; `w` receives
/// every `W` entry (cached for the Schur complement and the back-substitution).
fn linearise_vo(
    p: &BaProblem<'_>,
    s: &BaState,
    st: &Structure,
    lin: &mut Lin,
    w: &mut [Matrix6x3<f64>],
) -> bool {
    let mut outs = Vec::with_capacity(st.chunks.len());
    let (mut v, mut gp, mut w) = (&mut lin.v[..], &mut lin.gp[..], w);
    for r in &st.chunks {
        let (v0, v1) = std::mem::take(&mut v).split_at_mut(r.len());
        let (g0, g1) = std::mem::take(&mut gp).split_at_mut(r.len());
        let (w0, w1) = std::mem::take(&mut w).split_at_mut(st.w_ptr[r.end] - st.w_ptr[r.start]);
        outs.push((
            r.clone(),
            VoOut {
                v: v0,
                gp: g0,
                w: w0,
            },
        ));
        (v, gp, w) = (v1, g1, w1);
    }
    // `(R^T, t)` of each keyframe, shared by its keypoints.
    let frames: Vec<Frame> =
        s.kf.iter()
            .map(|k| {
                let rt = k.rotation.to_rotation_matrix().matrix().transpose();
                (rt, k.translation.vector)
            })
            .collect();
    let parts: Vec<Option<VoSums>> = outs
        .into_par_iter()
        .map(|(r, out)| vo_part(p, s, st, (r, &frames), out))
        .collect();
    for part in parts {
        let Some(part) = part else { return false };
        for (a, d) in part.diag.iter().enumerate().take(st.lay.kfs - 1) {
            lin.u[st.pat.slot(a, a).expect("diagonal")] += d;
        }
        for (k, g) in part.g.iter().enumerate().take(6 * (st.lay.kfs - 1)) {
            lin.g[k] += g;
        }
        lin.cost += part.cost;
        lin.count += part.count;
    }
    true
}

fn linearise_markers(p: &BaProblem<'_>, s: &BaState, st: &Structure, lin: &mut Lin) -> bool {
    let terms: Vec<_> = p
        .markers
        .par_iter()
        .map(|m| {
            let (r, j, rho) = marker_term(p, s, m)?;
            Some((j.transpose() * j, j.transpose() * r, rho))
        })
        .collect();
    for (m, t) in p.markers.iter().zip(terms) {
        let Some((jtj, jtr, rho)) = t else {
            return false;
        };
        lin.cost += rho;
        lin.count += 8;
        add_dense(lin, &st.pat, &st.lay.marker_blocks(m), &jtj, &jtr);
    }
    true
}

fn linearise_blobs_epipolar(p: &BaProblem<'_>, s: &BaState, st: &Structure, lin: &mut Lin) {
    let blobs: Vec<_> = p
        .blobs
        .par_iter()
        .map(|b| {
            let (r, jk, jc, rho) = blob_term(p, s, b)?;
            let mut j = SMatrix::<f64, 2, 12>::zeros();
            j.fixed_view_mut::<2, 6>(0, 0).copy_from(&jk);
            j.fixed_view_mut::<2, 6>(0, 6).copy_from(&jc);
            Some((j.transpose() * j, j.transpose() * r, rho))
        })
        .collect();
    for (b, t) in p.blobs.iter().zip(blobs) {
        let Some((jtj, jtr, rho)) = t else { continue };
        lin.cost += rho;
        lin.count += 2;
        add_dense(
            lin,
            &st.pat,
            &[st.lay.kf(b.kf), Some(st.lay.cam(b.cam))],
            &jtj,
            &jtr,
        );
    }
    let epi: Vec<_> = p
        .epipolar
        .par_iter()
        .map(|o| {
            let (r, j, rho) = epipolar_term(s, o);
            (j.transpose() * j, j.transpose() * r, rho)
        })
        .collect();
    for (o, (jtj, jtr, rho)) in p.epipolar.iter().zip(epi) {
        lin.cost += rho;
        lin.count += 1;
        let blocks = [Some(st.lay.cam(o.a)), Some(st.lay.cam(o.b))];
        add_dense(lin, &st.pat, &blocks, &jtj, &jtr);
    }
}

/// Linearises every term at `s`, into the buffers of `reuse` when given (tens of MB at the
/// benchmark size, whose page faults cost ~5 % of the run when allocated anew); the
/// keypoints' `W` entries go to `w` (overwritten, also when `None` is returned).
fn linearise(
    p: &BaProblem<'_>,
    s: &BaState,
    st: &Structure,
    w: &mut [Matrix6x3<f64>],
    reuse: Option<Lin>,
) -> Option<Lin> {
    let mut lin = match reuse {
        Some(mut lin) => {
            lin.u.par_iter_mut().for_each(|u| *u = Matrix6::zeros());
            lin.g.fill(0.0);
            (lin.cost, lin.count) = (0.0, 0);
            lin
        }
        // `v` and `gp` are written for every point by `linearise_vo`.
        None => Lin {
            u: vec![Matrix6::zeros(); st.pat.slots()],
            g: vec![0.0; 6 * st.lay.blocks()],
            v: vec![Matrix3::zeros(); s.points.len()],
            gp: vec![Vector3::zeros(); s.points.len()],
            cost: 0.0,
            count: 0,
        },
    };
    if !linearise_vo(p, s, st, &mut lin, w) || !linearise_markers(p, s, st, &mut lin) {
        return None;
    }
    linearise_blobs_epipolar(p, s, st, &mut lin);
    Some(lin)
}

/// `(V + lambda diag V)^-1` of point `j`.
fn damped_inverse(v: &Matrix3<f64>, lambda: f64) -> Matrix3<f64> {
    let mut v = *v;
    for k in 0..3 {
        v[(k, k)] += lambda * v[(k, k)].max(1e-9) + 1e-12;
    }
    v.try_inverse().unwrap_or_else(Matrix3::zeros)
}

/// Points eliminated together: their updates of one block of the reduced system are
/// summed in registers before the block is written (the update is memory-bound otherwise).
const GROUP: usize = 16;

/// A group's entries, sorted by (block, member), as separate `Z = W V^-1` and `W` arrays
/// (the kernel streams the `W` of every later block for each block's `Z`), and per block
/// `(block, first entry, mask of the members that see it)`. The sort is a counting sort:
/// `seen` (a bit per block) gives the group's blocks in order, `index` the position of a
/// block in `kfs`, `cursor` the next free entry of each block.
#[derive(Default)]
struct Group {
    z: Vec<Matrix6x3<f64>>,
    w: Vec<Matrix6x3<f64>>,
    kfs: Vec<(usize, usize, u64)>,
    seen: Vec<u64>,
    index: Vec<usize>,
    cursor: Vec<usize>,
}

impl Group {
    /// Scratch for a reduced system of `blocks` blocks.
    fn new(blocks: usize) -> Self {
        Self {
            seen: vec![0; blocks.div_ceil(64)],
            index: vec![0; blocks],
            ..Self::default()
        }
    }

    /// `kfs` for the entries whose blocks are `blocks` (masks empty), `cursor` at the
    /// first entry of each block, `z` and `w` sized.
    fn layout(&mut self, blocks: &[usize]) {
        self.kfs.clear();
        for &b in blocks {
            self.seen[b / 64] |= 1 << (b % 64);
        }
        for (i, word) in self.seen.iter_mut().enumerate() {
            while *word != 0 {
                let b = 64 * i + word.trailing_zeros() as usize;
                *word &= *word - 1;
                self.index[b] = self.kfs.len();
                self.kfs.push((b, 0, 0));
            }
        }
        for &b in blocks {
            self.kfs[self.index[b]].1 += 1;
        }
        let mut first = 0;
        for k in &mut self.kfs {
            (k.1, first) = (first, first + k.1);
        }
        self.cursor.clear();
        self.cursor.extend(self.kfs.iter().map(|k| k.1));
        self.z.resize(blocks.len(), Matrix6x3::zeros());
        self.w.resize(blocks.len(), Matrix6x3::zeros());
    }
}

/// Gathers the `W` entries of the points `group` (at most 64) into `out` with their `Z`
/// and adds `Z g_p` to `rhs`.
fn gather(
    lin: &Lin,
    w: &[Matrix6x3<f64>],
    st: &Structure,
    (group, lambda): (Range<usize>, f64),
    rhs: &mut [f64],
    out: &mut Group,
) {
    out.layout(&st.w_block[st.w_ptr[group.start]..st.w_ptr[group.end]]);
    for (member, j) in group.enumerate() {
        let vi = damped_inverse(&lin.v[j], lambda);
        let r = st.w_ptr[j]..st.w_ptr[j + 1];
        for (we, &block) in w[r.clone()].iter().zip(&st.w_block[r]) {
            let z = we * vi;
            let za = z * lin.gp[j];
            for k in 0..6 {
                rhs[6 * block + k] += za[k];
            }
            let slot = out.index[block];
            let pos = out.cursor[slot];
            out.cursor[slot] += 1;
            (out.z[pos], out.w[pos]) = (z, *we);
            out.kfs[slot].2 |= 1 << member;
        }
    }
}

/// `sum_j W_j V_j^-1 W_j^T` (upper blocks) and `sum_j W_j V_j^-1 g_j` over a range of
/// points, `GROUP` points at a time, added into `blocks` and `rhs`.
fn schur_part(
    (lin, w, st): (&Lin, &[Matrix6x3<f64>], &Structure),
    r: Range<usize>,
    lambda: f64,
    (blocks, rhs): (&mut [Matrix6<f64>], &mut [f64]),
) {
    let mut group = Group::new(st.lay.blocks());
    let mut g0 = r.start;
    while g0 < r.end {
        let g1 = (g0 + GROUP).min(r.end);
        gather(lin, w, st, (g0..g1, lambda), rhs, &mut group);
        eliminate_group(&st.pat, &group, blocks);
        g0 = g1;
    }
}

/// Adds a group's `sum_p Z_pa W_pb^T` into the blocks `(a, b >= a)`: the inner loop of
/// the Schur complement, with an AVX2 + FMA register kernel when the CPU has them.
fn eliminate_group(pat: &BlockPattern, g: &Group, blocks: &mut [Matrix6<f64>]) {
    #[cfg(target_arch = "x86_64")]
    if std::is_x86_feature_detected!("avx2")
        && std::is_x86_feature_detected!("fma")
        && std::is_x86_feature_detected!("popcnt")
    {
        // SAFETY: the CPU supports AVX2, FMA and POPCNT (checked just above).
        unsafe { eliminate_group_fma(pat, g, blocks) };
        return;
    }
    eliminate_body::<false>(pat, g, blocks);
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma,popcnt")]
unsafe fn eliminate_group_fma(pat: &BlockPattern, g: &Group, blocks: &mut [Matrix6<f64>]) {
    eliminate_body::<true>(pat, g, blocks);
}

/// The group's entries of block `a` (first entry, member mask) and of block `b`.
type Pair = ((usize, u64), (usize, u64));

#[inline(always)]
fn eliminate_body<const FMA: bool>(pat: &BlockPattern, g: &Group, blocks: &mut [Matrix6<f64>]) {
    for (ia, &(a, ea, ma)) in g.kfs.iter().enumerate() {
        let (start, cols) = pat.row(a);
        let mut pos = 0;
        for &(b, eb, mb) in &g.kfs[ia..] {
            if ma & mb == 0 {
                continue;
            }
            while cols[pos] as usize != b {
                pos += 1;
            }
            let out = &mut blocks[start + pos];
            #[cfg(target_arch = "x86_64")]
            if FMA {
                // SAFETY: `FMA` is only set by `eliminate_group_fma`, which runs only on
                // CPUs with AVX2, FMA and POPCNT.
                unsafe { pair_fma(g, ((ea, ma), (eb, mb)), out) };
                continue;
            }
            pair_portable(g, ((ea, ma), (eb, mb)), out);
        }
    }
}

/// Index of the entry of the member `bit` in the block whose entries start at `e` and
/// whose members are `mask`.
#[inline(always)]
fn member_entry(e: usize, mask: u64, bit: u64) -> usize {
    e + (mask & (bit - 1)).count_ones() as usize
}

/// `out += sum_p Z_pa W_pb^T` over the members that see both blocks.
fn pair_portable(g: &Group, ((ea, ma), (eb, mb)): Pair, out: &mut Matrix6<f64>) {
    let mut both = ma & mb;
    while both != 0 {
        let bit = both & both.wrapping_neg();
        both &= both - 1;
        let z = &g.z[member_entry(ea, ma, bit)];
        let w = &g.w[member_entry(eb, mb, bit)];
        *out += z * w.transpose();
    }
}

/// [`pair_portable`] in registers: the 6 x 6 sum is 6 columns of 4 + 2 lanes (12 of the
/// 16 AVX registers), each member adds 3 rank-1 products (a column of `Z` times a
/// broadcast entry of `W`), and the block is read and written once per pair.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma,popcnt")]
#[inline]
unsafe fn pair_fma(g: &Group, ((ea, ma), (eb, mb)): Pair, out: &mut Matrix6<f64>) {
    use std::arch::x86_64::{
        _mm256_add_pd, _mm256_broadcast_sd, _mm256_castpd256_pd128, _mm256_fmadd_pd,
        _mm256_loadu_pd, _mm256_setzero_pd, _mm256_storeu_pd, _mm_add_pd, _mm_fmadd_pd,
        _mm_loadu_pd, _mm_setzero_pd, _mm_storeu_pd,
    };
    let mut hi = [_mm256_setzero_pd(); 6];
    let mut lo = [_mm_setzero_pd(); 6];
    let mut both = ma & mb;
    while both != 0 {
        let bit = both & both.wrapping_neg();
        both &= both - 1;
        // Column-major 6 x 3: column c is [6c, 6c + 6).
        let z = g.z[member_entry(ea, ma, bit)].as_slice();
        let w = g.w[member_entry(eb, mb, bit)].as_slice();
        for c in 0..3 {
            let zh = _mm256_loadu_pd(z[6 * c..6 * c + 4].as_ptr());
            let zl = _mm_loadu_pd(z[6 * c + 4..6 * c + 6].as_ptr());
            for jc in 0..6 {
                let s = _mm256_broadcast_sd(&w[jc + 6 * c]);
                hi[jc] = _mm256_fmadd_pd(zh, s, hi[jc]);
                lo[jc] = _mm_fmadd_pd(zl, _mm256_castpd256_pd128(s), lo[jc]);
            }
        }
    }
    let o = out.as_mut_slice();
    for jc in 0..6 {
        let (h, l) = (&mut o[6 * jc..6 * jc + 4], 6 * jc + 4);
        _mm256_storeu_pd(
            h.as_mut_ptr(),
            _mm256_add_pd(_mm256_loadu_pd(h.as_ptr()), hi[jc]),
        );
        let l = &mut o[l..l + 2];
        _mm_storeu_pd(l.as_mut_ptr(), _mm_add_pd(_mm_loadu_pd(l.as_ptr()), lo[jc]));
    }
}

/// Buffers of the reduced system kept across iterations (tens of MB each at the benchmark
/// size; allocated anew, their page faults cost ~10 % of the run): the system, one
/// partial Schur complement per point range, and the Cholesky factor.
struct Work {
    blocks: Vec<Matrix6<f64>>,
    rhs: Vec<f64>,
    parts: Vec<(Vec<Matrix6<f64>>, Vec<f64>)>,
    factor: Option<Factor>,
    /// Steps solved exactly (Schur complement formed and factored).
    exact: usize,
    /// Products with the implicit reduced system (conjugate gradients).
    products: usize,
    time: Timings,
    /// The damping of the kept factor.
    factor_lambda: f64,
    /// Whether the last step was a conjugate-gradient iterate short of its tolerance.
    truncated: bool,
}

impl Work {
    fn new(st: &Structure) -> Self {
        let part = || {
            (
                vec![Matrix6::zeros(); st.pat.slots()],
                vec![0.0; 6 * st.lay.blocks()],
            )
        };
        Self {
            blocks: vec![Matrix6::zeros(); st.pat.slots()],
            rhs: vec![0.0; 6 * st.lay.blocks()],
            parts: st.chunks.iter().map(|_| part()).collect(),
            factor: None,
            exact: 0,
            products: 0,
            time: Timings::default(),
            factor_lambda: f64::NAN,
            truncated: false,
        }
    }

    /// Factors `self.blocks` into the kept factor; false if not positive definite.
    fn factor(&mut self, pat: &BlockPattern) -> bool {
        if let Some(f) = &mut self.factor {
            if pat.refactor(&self.blocks, f) {
                return true;
            }
            self.factor = None;
            return false;
        }
        self.factor = pat.factor(&self.blocks);
        self.factor.is_some()
    }
}

/// The damped reduced system `S = U + lambda diag U - W V^-1 W^T` and its right-hand side
/// `g - W V^-1 g_p`, into `work.blocks` and `work.rhs`.
fn reduced(lin: &Lin, w: &[Matrix6x3<f64>], st: &Structure, lambda: f64, work: &mut Work) {
    work.blocks
        .par_chunks_mut(4096)
        .zip(lin.u.par_chunks(4096))
        .for_each(|(b, u)| b.copy_from_slice(u));
    for b in 0..st.lay.blocks() {
        let slot = st.pat.slot(b, b).expect("diagonal");
        for k in 0..6 {
            work.blocks[slot][(k, k)] += lambda * lin.u[slot][(k, k)].max(1e-9);
        }
    }
    work.rhs.copy_from_slice(&lin.g);
    work.parts
        .par_iter_mut()
        .zip(st.chunks.par_iter())
        .for_each(|((pb, pr), r)| {
            pb.fill(Matrix6::zeros());
            pr.fill(0.0);
            schur_part((lin, w, st), r.clone(), lambda, (pb, pr));
        });
    for (pb, pr) in &work.parts {
        work.blocks
            .par_iter_mut()
            .zip(pb.par_iter())
            .for_each(|(b, d)| *b -= d);
        for (r, d) in work.rhs.iter_mut().zip(pr) {
            *r -= d;
        }
    }
}

fn apply(s: &BaState, st: &Structure, d: &[f64], dx: &[Vector3<f64>]) -> BaState {
    let lay = &st.lay;
    let mut out = s.clone();
    for k in 1..s.kf.len() {
        let o = 6 * (k - 1);
        out.kf[k] = plus(&s.kf[k], &d[o..o + 6]);
    }
    for c in 0..s.cams.len() {
        let o = 6 * lay.cam(c);
        out.cams[c] = plus(&s.cams[c], &d[o..o + 6]);
    }
    let o = 6 * lay.tfm();
    out.t_f_m = plus(&s.t_f_m, &d[o..o + 6]);
    for (&j, d) in st.order.iter().zip(dx) {
        out.points[j] += d;
    }
    out
}

/// The step of the reduced unknowns: by conjugate gradients preconditioned with the kept
/// factor when there is one (and `steps` allows), else, or when they do not converge,
/// exactly (which refreshes the factor); `None` when the reduced system is not positive
/// definite.
fn reduced_step(
    (lin, w, st): (&Lin, &[Matrix6x3<f64>], &Structure),
    lambda: f64,
    work: &mut Work,
    (steps, opts): (Steps, &Options),
) -> Option<Vec<f64>> {
    work.truncated = false;
    if let (Steps::Inexact, Some(f)) = (steps, work.factor.as_ref()) {
        let t = Instant::now();
        let implicit = pcg::Implicit::new(lin, w, st, lambda);
        let b = implicit.rhs();
        let out = implicit.solve(&b, f, opts.pcg_tolerance, opts.pcg_max_products);
        work.products += out.products;
        work.time.pcg += t.elapsed().as_secs_f64();
        match out.end {
            pcg::End::Converged => return Some(out.x),
            pcg::End::Limit => {
                work.truncated = true;
                return Some(out.x);
            }
            _ => {}
        }
    }
    work.exact += 1;
    work.factor_lambda = lambda;
    if !eliminate_and_factor((lin, w, st), lambda, work) {
        return None;
    }
    let t = Instant::now();
    let rhs = &work.rhs;
    let mut x = faer::Mat::from_fn(rhs.len(), 1, |i, _| -rhs[i]);
    st.pat.solve(work.factor.as_ref()?, &mut x);
    work.time.back += t.elapsed().as_secs_f64();
    Some((0..rhs.len()).map(|i| x[(i, 0)]).collect())
}

/// [`reduced`] and [`Work::factor`], timed; false if not positive definite.
fn eliminate_and_factor(
    (lin, w, st): (&Lin, &[Matrix6x3<f64>], &Structure),
    lambda: f64,
    work: &mut Work,
) -> bool {
    let t = Instant::now();
    reduced(lin, w, st, lambda, work);
    let t1 = Instant::now();
    let ok = work.factor(&st.pat);
    work.time.eliminate += (t1 - t).as_secs_f64();
    work.time.factor += t1.elapsed().as_secs_f64();
    ok
}

/// One damped step: `None` when the reduced system is not positive definite.
fn step(
    (lin, w, st): (&Lin, &[Matrix6x3<f64>], &Structure),
    s: &BaState,
    lambda: f64,
    (work, steps): (&mut Work, (Steps, &Options)),
) -> Option<BaState> {
    let d = reduced_step((lin, w, st), lambda, work, steps)?;
    if d.iter().any(|v| !v.is_finite()) {
        return None;
    }
    let t = Instant::now();
    let dx: Vec<Vector3<f64>> = (0..s.points.len())
        .into_par_iter()
        .map(|j| {
            let mut acc = lin.gp[j];
            let r = st.w_ptr[j]..st.w_ptr[j + 1];
            for (we, &a) in w[r.clone()].iter().zip(&st.w_block[r]) {
                acc += we.transpose() * Vector6::from_column_slice(&d[6 * a..6 * a + 6]);
            }
            -(damped_inverse(&lin.v[j], lambda) * acc)
        })
        .collect();
    let out = apply(s, st, &d, &dx);
    work.time.back += t.elapsed().as_secs_f64();
    Some(out)
}

/// Runs Levenberg-Marquardt from `start` with the default [`Options::new`]. Each
/// iteration linearises once (the keypoint `W` blocks are cached for the Schur complement
/// and the back-substitution); a rejected step linearises the kept state again, as the
/// candidate's overwrote the cache.
pub fn solve(p: &BaProblem<'_>, start: BaState, max_iterations: usize) -> Option<BaSolution> {
    solve_with(p, start, Options::new(max_iterations))
}

/// Relative cost decrease below which the iterations stop (after an exact step).
const STOP_DECREASE: f64 = 1e-7;

/// [`solve`] with the choice of how the steps are solved (see [`Steps::Inexact`] for
/// when a step is exact).
pub fn solve_with(p: &BaProblem<'_>, start: BaState, opts: Options) -> Option<BaSolution> {
    let t = Instant::now();
    let st = structure(p, &start)?;
    let structure_time = t.elapsed().as_secs_f64();
    let mut w = vec![Matrix6x3::zeros(); st.w_block.len()];
    let mut lin_time = 0.0;
    // The symbolic factorisation (~1 s single-threaded at the benchmark size) beside the
    // first linearisation.
    let (_, n) = rayon::join(
        || st.pat.analyse(),
        || timed(&mut lin_time, || linearise(p, &start, &st, &mut w, None)),
    );
    let n = n?;
    let initial_cost = n.cost;
    let mut lm = Lm {
        p,
        st: &st,
        w,
        work: Work::new(&st),
        s: start,
        n,
        spare: None,
        lambda: 1e-4,
        rejected: 0,
        trace: Vec::new(),
        force_exact: false,
        lin_time,
    };
    let converged = lm.run(&opts)?;
    let Lm {
        s, n, w, mut work, ..
    } = lm;
    let unknowns = 6 * st.lay.blocks() + 3 * s.points.len();
    let variance_factor = (n.cost / n.count.saturating_sub(unknowns).max(1) as f64).max(1e-12);
    let camera_covariances = covariances((&n, &w, &st), variance_factor, &mut work, converged)?;
    Some(BaSolution {
        state: s,
        camera_covariances,
        initial_cost,
        final_cost: n.cost,
        iterations: lm.trace.len(),
        rejected: lm.rejected,
        variance_factor,
        exact_steps: work.exact,
        pcg_products: work.products,
        timings: Timings {
            structure: structure_time,
            linearise: lm.lin_time,
            ..work.time
        },
        trace: lm.trace,
    })
}

/// The Levenberg-Marquardt iterations' state: the current state `s` and its
/// linearisation `n` (with the cached `W` entries `w`), a spare linearisation's buffers.
struct Lm<'a> {
    p: &'a BaProblem<'a>,
    st: &'a Structure,
    w: Vec<Matrix6x3<f64>>,
    work: Work,
    s: BaState,
    n: Lin,
    spare: Option<Lin>,
    lambda: f64,
    rejected: usize,
    trace: Vec<Iteration>,
    /// Whether the next step is exact whatever the options say.
    force_exact: bool,
    lin_time: f64,
}

impl Lm<'_> {
    /// Iterates until the cost stalls after an exact step (`Some(true)`), the damping
    /// runs away or the iterations run out (`Some(false)`); `None` when the kept state
    /// no longer projects.
    fn run(&mut self, opts: &Options) -> Option<bool> {
        while self.trace.len() < opts.max_iterations {
            let kind = if self.force_exact {
                Steps::Exact
            } else {
                opts.steps
            };
            let (exact0, products0) = (self.work.exact, self.work.products);
            let c = step(
                (&self.n, &self.w, self.st),
                &self.s,
                self.lambda,
                (&mut self.work, (kind, opts)),
            );
            let exact = self.work.exact > exact0;
            self.trace.push(Iteration {
                cost: f64::NAN,
                lambda: self.lambda,
                exact,
                products: self.work.products - products0,
                accepted: false,
            });
            let Some(c) = c else {
                // Not positive definite: the cache is intact.
                if self.reject() {
                    return Some(false);
                }
                continue;
            };
            let (p, st, spare) = (self.p, self.st, self.spare.take());
            let m = timed(&mut self.lin_time, || {
                linearise(p, &c, st, &mut self.w, spare)
            });
            match m {
                Some(m) if m.cost < self.n.cost => {
                    if self.accept(c, m, exact) {
                        return Some(true);
                    }
                }
                candidate => {
                    if let (Some(m), Some(t)) = (&candidate, self.trace.last_mut()) {
                        t.cost = m.cost;
                    }
                    // The candidate's linearisation overwrote the cached `W` entries.
                    let s = &self.s;
                    self.n = timed(&mut self.lin_time, || {
                        linearise(p, s, st, &mut self.w, candidate)
                    })?;
                    if self.reject() {
                        return Some(false);
                    }
                }
            }
        }
        Some(false)
    }

    /// Takes the candidate `c` (linearised as `m`); true when the iterations stop there.
    fn accept(&mut self, c: BaState, m: Lin, exact: bool) -> bool {
        let t = self.trace.last_mut().expect("pushed by run");
        (t.cost, t.accepted) = (m.cost, true);
        let small = self.n.cost - m.cost < STOP_DECREASE * self.n.cost;
        self.s = c;
        self.spare = Some(std::mem::replace(&mut self.n, m));
        self.lambda = (self.lambda * 0.2).max(1e-10);
        self.force_exact = self.work.truncated || small;
        small && exact
    }

    /// Counts a rejected step and raises the damping; true when it ran away.
    fn reject(&mut self) -> bool {
        self.rejected += 1;
        (self.lambda, self.force_exact) = (self.lambda * 10.0, true);
        self.lambda > 1e6
    }
}

/// Damping up to which the factor of the last exact step serves the covariance.
const COVARIANCE_REUSE_LAMBDA: f64 = 1e-6;

/// Camera blocks of the inverse reduced system. When the iterations `converged` (the
/// last step was exact and moved the cost by less than [`STOP_DECREASE`]) with little
/// damping, from that step's factor (the system one step before the end, which changed
/// the cost by under 1e-7 of itself); otherwise from the undamped system at the end.
fn covariances(
    (n, w, st): (&Lin, &[Matrix6x3<f64>], &Structure),
    factor: f64,
    work: &mut Work,
    converged: bool,
) -> Option<Vec<Matrix6<f64>>> {
    let reuse = converged && work.factor_lambda <= COVARIANCE_REUSE_LAMBDA;
    if !reuse && !eliminate_and_factor((n, w, st), 0.0, work) {
        return None;
    }
    let t = Instant::now();
    let first = st.lay.cam(0);
    let f = work.factor.as_ref()?;
    let blocks = st
        .pat
        .inverse_diagonal_blocks(f, first..first + st.lay.cams);
    work.time.covariance += t.elapsed().as_secs_f64();
    (blocks.len() == st.lay.cams).then(|| blocks.iter().map(|b| b * factor).collect())
}

#[cfg(all(test, target_arch = "x86_64"))]
mod kernel_tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    /// The AVX2/FMA register kernel against the portable sum it replaces, on random groups
    /// (the infra tests only reach the kernel the CPU picks; CPUs without AVX2 get the
    /// portable one).
    #[test]
    fn register_kernel_equals_the_portable_sum() {
        if !(std::is_x86_feature_detected!("avx2")
            && std::is_x86_feature_detected!("fma")
            && std::is_x86_feature_detected!("popcnt"))
        {
            eprintln!("SKIP register_kernel_equals_the_portable_sum: no AVX2/FMA on this CPU");
            return;
        }
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(14);
        let random = |rng: &mut rand_chacha::ChaCha8Rng| rng.gen_range(-1.0..1.0);
        for _ in 0..200 {
            let members = (1u64 << GROUP) - 1;
            let ma = (rng.gen::<u64>() & members).max(1);
            let mb = (rng.gen::<u64>() & members) | (ma & ma.wrapping_neg());
            let entries = (ma.count_ones() + mb.count_ones()) as usize;
            let mut g = Group::default();
            for _ in 0..entries {
                g.z.push(Matrix6x3::from_fn(|_, _| random(&mut rng)));
                g.w.push(Matrix6x3::from_fn(|_, _| random(&mut rng)));
            }
            let pair = ((0, ma), (ma.count_ones() as usize, mb));
            let start = Matrix6::from_fn(|_, _| random(&mut rng));
            let (mut portable, mut register) = (start, start);
            pair_portable(&g, pair, &mut portable);
            // SAFETY: the CPU supports AVX2, FMA and POPCNT (checked above).
            unsafe { pair_fma(&g, pair, &mut register) };
            let err = (portable - register).amax();
            assert!(err < 1e-12 * (1.0 + portable.amax()), "{err:e}");
            assert!((portable - start).amax() > 0.0, "the pair shares a member");
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    /// The counting sort of a group's entries against a comparison sort: blocks in order,
    /// each block's first entry after the entries of the blocks before it.
    #[test]
    fn group_layout_equals_a_sort() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        let blocks = 300;
        let mut g = Group::new(blocks);
        for _ in 0..100 {
            let n = rng.gen_range(1..400);
            let list: Vec<usize> = (0..n).map(|_| rng.gen_range(0..blocks)).collect();
            g.layout(&list);
            let mut sorted = list.clone();
            sorted.sort_unstable();
            let mut want: Vec<(usize, usize, u64)> = Vec::new();
            for (k, &b) in sorted.iter().enumerate() {
                if want.last().map(|l| l.0) != Some(b) {
                    want.push((b, k, 0));
                }
            }
            assert_eq!(g.kfs, want);
            assert_eq!(g.cursor, want.iter().map(|k| k.1).collect::<Vec<_>>());
            assert_eq!((g.z.len(), g.w.len()), (n, n));
            assert!(g.seen.iter().all(|&w| w == 0), "the bitmap is left clear");
        }
    }
}
