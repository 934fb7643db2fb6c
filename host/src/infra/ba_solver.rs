//! Levenberg-Marquardt for the bundle adjustment of [`super::ba`], scaled to thousands of
//! keyframes and millions of keypoints:
//! - the points are eliminated by the Schur complement, point by point, in parallel
//!   (one partial reduced system per thread); the per-keypoint Jacobians are recomputed
//!   from the state when needed instead of stored (3.7 M keypoints x 6 x 3 would be
//!   0.5 GB);
//! - the reduced system (6 per keyframe `k >= 1`, camera and `T_F_M`) keeps a fixed
//!   block-sparse pattern ([`super::blocksym`]) and is factored by faer's sparse
//!   (supernodal) Cholesky, symbolic analysis once;
//! - the marker, blob and epipolar terms are linearised in parallel.
//!
//! Damping: `lambda * diag` on the reduced-side blocks and on each point block, as
//! Marquardt scaled; the step is accepted when the robust cost decreases.

use faer::linalg::solvers::Solve;
use nalgebra::{Matrix3, Matrix6, Matrix6x3, SMatrix, SVector, Vector3};
use rayon::prelude::*;
use std::ops::Range;

use super::ba::{blob_term, epipolar_term, marker_term, plus, vo_term, BaProblem, BaState};
use super::blocksym::{BlockPattern, PatternBuilder};

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
    /// Variance factor (robust cost, i.e. whitened chi-square, per degree of freedom)
    /// applied to the covariances.
    pub variance_factor: f64,
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
    /// Keypoints per point, points in processing order (`order[k]` is the point).
    by_point: Vec<Vec<usize>>,
    order: Vec<usize>,
    chunks: Vec<Range<usize>>,
}

fn structure(p: &BaProblem<'_>, start: &BaState) -> Option<Structure> {
    let lay = Layout {
        kfs: start.kf.len(),
        cams: start.cams.len(),
    };
    let mut by_point = vec![Vec::new(); start.points.len()];
    for (o, obs) in p.vo.iter().enumerate() {
        by_point.get_mut(obs.point)?.push(o);
    }
    for list in &mut by_point {
        list.sort_by_key(|&o| p.vo[o].kf);
    }
    // Points in the order of their first keyframe: neighbouring points update
    // neighbouring blocks of the reduced system (cache reuse in the Schur complement).
    let mut order: Vec<usize> = (0..by_point.len()).collect();
    order.sort_by_key(|&j| by_point[j].first().map_or(usize::MAX, |&o| p.vo[o].kf));
    let by_point: Vec<Vec<usize>> = order
        .iter()
        .map(|&j| std::mem::take(&mut by_point[j]))
        .collect();
    let mut b = PatternBuilder::new(lay.blocks());
    let mut blocks = Vec::new();
    for list in &by_point {
        blocks.clear();
        blocks.extend(list.iter().filter_map(|&o| lay.kf(p.vo[o].kf)));
        b.mark_all(&blocks);
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
    let chunks = split(&by_point, rayon::current_num_threads().max(1));
    Some(Structure {
        lay,
        pat: b.finish()?,
        by_point,
        order,
        chunks,
    })
}

/// Contiguous ranges of points with about equal numbers of pairs of keypoints.
fn split(by_point: &[Vec<usize>], parts: usize) -> Vec<Range<usize>> {
    let work: Vec<usize> = by_point.iter().map(|l| l.len() * l.len() + 1).collect();
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
    out.push(start..by_point.len());
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

/// Per-thread sums of the keypoint terms of a range of points.
struct VoPart {
    diag: Vec<Matrix6<f64>>,
    g: Vec<f64>,
    v: Vec<Matrix3<f64>>,
    gp: Vec<Vector3<f64>>,
    cost: f64,
    count: usize,
}

fn vo_part(p: &BaProblem<'_>, s: &BaState, st: &Structure, r: Range<usize>) -> Option<VoPart> {
    let nk = st.lay.kfs;
    let mut part = VoPart {
        diag: vec![Matrix6::zeros(); nk],
        g: vec![0.0; 6 * nk],
        v: Vec::with_capacity(r.len()),
        gp: Vec::with_capacity(r.len()),
        cost: 0.0,
        count: 0,
    };
    for j in r {
        let (mut v, mut gp) = (Matrix3::zeros(), Vector3::zeros());
        for &o in &st.by_point[j] {
            let (res, jp, jx, rho) = vo_term(p, s, &p.vo[o])?;
            part.cost += rho;
            part.count += 2;
            v += jx.transpose() * jx;
            gp += jx.transpose() * res;
            if let Some(a) = st.lay.kf(p.vo[o].kf) {
                part.diag[a] += jp.transpose() * jp;
                let ga = jp.transpose() * res;
                for k in 0..6 {
                    part.g[6 * a + k] += ga[k];
                }
            }
        }
        part.v.push(v);
        part.gp.push(gp);
    }
    Some(part)
}

fn linearise_vo(p: &BaProblem<'_>, s: &BaState, st: &Structure, lin: &mut Lin) -> bool {
    let parts: Vec<Option<VoPart>> = st
        .chunks
        .par_iter()
        .map(|r| vo_part(p, s, st, r.clone()))
        .collect();
    for part in parts {
        let Some(part) = part else { return false };
        for (a, d) in part.diag.iter().enumerate().take(st.lay.kfs - 1) {
            lin.u[st.pat.slot(a, a).expect("diagonal")] += d;
        }
        for (k, g) in part.g.iter().enumerate().take(6 * (st.lay.kfs - 1)) {
            lin.g[k] += g;
        }
        lin.v.extend(part.v);
        lin.gp.extend(part.gp);
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

fn linearise(p: &BaProblem<'_>, s: &BaState, st: &Structure) -> Option<Lin> {
    let mut lin = Lin {
        u: vec![Matrix6::zeros(); st.pat.slots()],
        g: vec![0.0; 6 * st.lay.blocks()],
        v: Vec::with_capacity(s.points.len()),
        gp: Vec::with_capacity(s.points.len()),
        cost: 0.0,
        count: 0,
    };
    if !linearise_vo(p, s, st, &mut lin) || !linearise_markers(p, s, st, &mut lin) {
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

/// `W = J_kf^T J_point` of the keypoints of point `j` (keyframe 0 left out), by block.
fn point_w(
    p: &BaProblem<'_>,
    s: &BaState,
    st: &Structure,
    j: usize,
    out: &mut Vec<(usize, Matrix6x3<f64>)>,
) {
    out.clear();
    for &o in &st.by_point[j] {
        let Some(a) = st.lay.kf(p.vo[o].kf) else {
            continue;
        };
        if let Some((_, jp, jx, _)) = vo_term(p, s, &p.vo[o]) {
            out.push((a, jp.transpose() * jx));
        }
    }
}

/// Points eliminated together: their updates of one block of the reduced system are
/// summed in registers before the block is written (the update is memory-bound otherwise).
const GROUP: usize = 16;

/// One keyframe's `W` (keypoints of one point in one keyframe summed, which is exact) and
/// `Z = W V^-1` for a point of the group.
#[derive(Clone, Copy)]
struct Entry {
    block: usize,
    member: usize,
    w: Matrix6x3<f64>,
    z: Matrix6x3<f64>,
}

/// The entries of a group of points, sorted by block, and per block `(block, first entry,
/// mask of the members that see it)`.
#[allow(clippy::too_many_arguments)]
fn gather(
    lin: &Lin,
    p: &BaProblem<'_>,
    s: &BaState,
    st: &Structure,
    group: Range<usize>,
    lambda: f64,
    rhs: &mut [f64],
    out: &mut (Vec<Entry>, Vec<(usize, usize, u64)>),
) {
    let (entries, kfs) = out;
    entries.clear();
    kfs.clear();
    let mut w = Vec::new();
    for (member, j) in group.enumerate() {
        let vi = damped_inverse(&lin.v[j], lambda);
        point_w(p, s, st, j, &mut w);
        let first = entries.len();
        for &(block, wa) in &w {
            let len = entries.len();
            match entries.last_mut() {
                Some(e) if len > first && e.block == block => e.w += wa,
                _ => entries.push(Entry {
                    block,
                    member,
                    w: wa,
                    z: Matrix6x3::zeros(),
                }),
            }
        }
        for e in &mut entries[first..] {
            e.z = e.w * vi;
            let za = e.z * lin.gp[j];
            for k in 0..6 {
                rhs[6 * e.block + k] += za[k];
            }
        }
    }
    entries.sort_by_key(|e| (e.block, e.member));
    for (k, e) in entries.iter().enumerate() {
        match kfs.last_mut() {
            Some(last) if last.0 == e.block => last.2 |= 1 << e.member,
            _ => kfs.push((e.block, k, 1 << e.member)),
        }
    }
}

/// `sum_j W_j V_j^-1 W_j^T` (upper blocks) and `sum_j W_j V_j^-1 g_j` over a range of
/// points, `GROUP` points at a time.
fn schur_part(
    lin: &Lin,
    p: &BaProblem<'_>,
    s: &BaState,
    st: &Structure,
    r: Range<usize>,
    lambda: f64,
) -> (Vec<Matrix6<f64>>, Vec<f64>) {
    let mut blocks = vec![Matrix6::zeros(); st.pat.slots()];
    let mut rhs = vec![0.0; 6 * st.lay.blocks()];
    let mut scratch = (Vec::new(), Vec::new());
    let mut g0 = r.start;
    while g0 < r.end {
        let g1 = (g0 + GROUP).min(r.end);
        gather(lin, p, s, st, g0..g1, lambda, &mut rhs, &mut scratch);
        eliminate_group(&st.pat, &scratch.0, &scratch.1, &mut blocks);
        g0 = g1;
    }
    (blocks, rhs)
}

/// Adds a group's `sum_p Z_pa W_pb^T` into the blocks `(a, b >= a)`: the inner loop of
/// the Schur complement, run with AVX2 + FMA when the CPU has them.
fn eliminate_group(
    pat: &BlockPattern,
    entries: &[Entry],
    kfs: &[(usize, usize, u64)],
    blocks: &mut [Matrix6<f64>],
) {
    #[cfg(target_arch = "x86_64")]
    if std::is_x86_feature_detected!("avx2") && std::is_x86_feature_detected!("fma") {
        // SAFETY: the CPU supports AVX2 and FMA (checked just above).
        unsafe { eliminate_group_fma(pat, entries, kfs, blocks) };
        return;
    }
    eliminate_body::<false>(pat, entries, kfs, blocks);
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn eliminate_group_fma(
    pat: &BlockPattern,
    entries: &[Entry],
    kfs: &[(usize, usize, u64)],
    blocks: &mut [Matrix6<f64>],
) {
    eliminate_body::<true>(pat, entries, kfs, blocks);
}

#[inline(always)]
fn eliminate_body<const FMA: bool>(
    pat: &BlockPattern,
    entries: &[Entry],
    kfs: &[(usize, usize, u64)],
    blocks: &mut [Matrix6<f64>],
) {
    for (ia, &(a, ea, ma)) in kfs.iter().enumerate() {
        let (start, cols) = pat.row(a);
        let mut pos = 0;
        for &(b, eb, mb) in &kfs[ia..] {
            let mut both = ma & mb;
            if both == 0 {
                continue;
            }
            while cols[pos] as usize != b {
                pos += 1;
            }
            let mut acc = [0.0f64; 36];
            while both != 0 {
                let bit = both & both.wrapping_neg();
                both &= both - 1;
                let za = entries[ea + (ma & (bit - 1)).count_ones() as usize].z;
                let wb = entries[eb + (mb & (bit - 1)).count_ones() as usize].w;
                let (zs, ws) = (za.as_slice(), wb.as_slice());
                for jc in 0..6 {
                    let (w0, w1, w2) = (ws[jc], ws[jc + 6], ws[jc + 12]);
                    for i in 0..6 {
                        let o = &mut acc[6 * jc + i];
                        *o = if FMA {
                            zs[i].mul_add(w0, zs[6 + i].mul_add(w1, zs[12 + i].mul_add(w2, *o)))
                        } else {
                            *o + zs[i] * w0 + zs[6 + i] * w1 + zs[12 + i] * w2
                        };
                    }
                }
            }
            let out = blocks[start + pos].as_mut_slice();
            for (o, v) in out.iter_mut().zip(acc) {
                *o += v;
            }
        }
    }
}

/// The damped reduced system `S = U + lambda diag U - W V^-1 W^T` and its right-hand side
/// `g - W V^-1 g_p`.
fn reduced(
    lin: &Lin,
    p: &BaProblem<'_>,
    s: &BaState,
    st: &Structure,
    lambda: f64,
) -> (Vec<Matrix6<f64>>, Vec<f64>) {
    let mut blocks = lin.u.clone();
    for b in 0..st.lay.blocks() {
        let slot = st.pat.slot(b, b).expect("diagonal");
        for k in 0..6 {
            blocks[slot][(k, k)] += lambda * lin.u[slot][(k, k)].max(1e-9);
        }
    }
    let mut rhs = lin.g.clone();
    let parts: Vec<_> = st
        .chunks
        .par_iter()
        .map(|r| schur_part(lin, p, s, st, r.clone(), lambda))
        .collect();
    for (pb, pr) in parts {
        for (b, d) in blocks.iter_mut().zip(&pb) {
            *b -= d;
        }
        for (r, d) in rhs.iter_mut().zip(&pr) {
            *r -= d;
        }
    }
    (blocks, rhs)
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

/// One damped step: `None` when the reduced system is not positive definite.
fn step(lin: &Lin, p: &BaProblem<'_>, s: &BaState, st: &Structure, lambda: f64) -> Option<BaState> {
    let (blocks, rhs) = reduced(lin, p, s, st, lambda);
    let llt = st.pat.factor(&blocks)?;
    let b = faer::Mat::from_fn(rhs.len(), 1, |i, _| -rhs[i]);
    let x = llt.solve(&b);
    let d: Vec<f64> = (0..rhs.len()).map(|i| x[(i, 0)]).collect();
    if d.iter().any(|v| !v.is_finite()) {
        return None;
    }
    let dx: Vec<Vector3<f64>> = (0..s.points.len())
        .into_par_iter()
        .map_init(Vec::new, |w, j| {
            point_w(p, s, st, j, w);
            let mut acc = lin.gp[j];
            for (a, wa) in w.iter() {
                let da = nalgebra::Vector6::from_column_slice(&d[6 * a..6 * a + 6]);
                acc += wa.transpose() * da;
            }
            -(damped_inverse(&lin.v[j], lambda) * acc)
        })
        .collect();
    Some(apply(s, st, &d, &dx))
}

/// Runs Levenberg-Marquardt from `start`.
pub fn solve(p: &BaProblem<'_>, start: BaState, max_iterations: usize) -> Option<BaSolution> {
    let st = structure(p, &start)?;
    let mut s = start;
    let mut n = linearise(p, &s, &st)?;
    let initial_cost = n.cost;
    let mut lambda = 1e-4;
    let mut iterations = 0;
    while iterations < max_iterations {
        iterations += 1;
        let candidate =
            step(&n, p, &s, &st, lambda).and_then(|c| linearise(p, &c, &st).map(|m| (c, m)));
        match candidate {
            Some((c, m)) if m.cost < n.cost => {
                let done = n.cost - m.cost < 1e-7 * n.cost;
                (s, n) = (c, m);
                lambda = (lambda * 0.2).max(1e-10);
                if done {
                    break;
                }
            }
            _ => {
                lambda *= 10.0;
                if lambda > 1e6 {
                    break;
                }
            }
        }
    }
    let unknowns = 6 * st.lay.blocks() + 3 * s.points.len();
    let variance_factor = (n.cost / n.count.saturating_sub(unknowns).max(1) as f64).max(1e-12);
    let camera_covariances = covariances(&n, p, &s, &st, variance_factor)?;
    Some(BaSolution {
        state: s,
        camera_covariances,
        initial_cost,
        final_cost: n.cost,
        iterations,
        variance_factor,
    })
}

/// Camera blocks of the inverse reduced (undamped) system.
fn covariances(
    n: &Lin,
    p: &BaProblem<'_>,
    s: &BaState,
    st: &Structure,
    factor: f64,
) -> Option<Vec<Matrix6<f64>>> {
    let (blocks, _) = reduced(n, p, s, st, 0.0);
    let llt = st.pat.factor(&blocks)?;
    let dim = 6 * st.lay.blocks();
    let first = 6 * st.lay.cam(0);
    let e = faer::Mat::from_fn(
        dim,
        6 * st.lay.cams,
        |i, j| {
            if i == first + j {
                1.0
            } else {
                0.0
            }
        },
    );
    let x = llt.solve(&e);
    Some(
        (0..st.lay.cams)
            .map(|c| Matrix6::from_fn(|i, j| x[(first + 6 * c + i, 6 * c + j)] * factor))
            .collect(),
    )
}
