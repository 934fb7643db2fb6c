//! A symmetric matrix of 6 x 6 blocks with a fixed sparsity pattern (upper triangle stored)
//! and its sparse Cholesky factorisation (faer's supernodal `LL^T`, symbolic analysis done
//! once per pattern). The reduced camera / keyframe system of the bundle adjustment
//! ([`super::ba`]) lives here.
//!
//! Ordering: the symbolic analysis is done twice, with faer's approximate minimum degree
//! and with the blocks in their own order, and the one with the smaller factor is kept.
//! The bundle adjustment numbers its blocks keyframe by keyframe in time, then the
//! cameras: a band (plus the loop closure's border), for which that order gives a factor
//! of less than half the entries of the minimum-degree one (docs/benchmarks.md). The
//! analysis runs on first use ([`BlockPattern::analyse`] may start it early, e.g. beside
//! other work), so building a pattern is cheap.

use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::cholesky::llt::factor::LltRegularization;
use faer::linalg::{matmul, triangular_solve};
use faer::prelude::{Reborrow, ReborrowMut};
use faer::sparse::linalg::cholesky::supernodal::SupernodalLltRef;
use faer::sparse::linalg::cholesky::{
    factorize_symbolic_cholesky, LltRef, SymbolicCholesky, SymbolicCholeskyRaw, SymmetricOrdering,
};
use faer::sparse::{SparseColMatRef, SymbolicSparseColMatRef};
use faer::{Accum, Conj};
use nalgebra::Matrix6;
use rayon::prelude::*;
use std::sync::OnceLock;

/// Collects the block pairs of a pattern (a bit per block pair).
pub struct PatternBuilder {
    nb: usize,
    words: usize,
    bits: Vec<u64>,
    /// Scratch of [`Self::mark_all`]: the marked set as bits.
    set: Vec<u64>,
}

impl PatternBuilder {
    /// An empty pattern of `nb` x `nb` blocks (the diagonal is always present).
    pub fn new(nb: usize) -> Self {
        let words = nb.div_ceil(64);
        let mut b = Self {
            nb,
            words,
            bits: vec![0; nb * words],
            set: Vec::new(),
        };
        for k in 0..nb {
            b.mark(k, k);
        }
        b
    }

    /// Marks the block pair `(a, b)` (either order).
    pub fn mark(&mut self, a: usize, b: usize) {
        let (r, c) = if a <= b { (a, b) } else { (b, a) };
        self.bits[r * self.words + c / 64] |= 1 << (c % 64);
    }

    /// Marks every pair of `blocks`.
    pub fn mark_all(&mut self, blocks: &[usize]) {
        let (Some(&lo), Some(&hi)) = (blocks.iter().min(), blocks.iter().max()) else {
            return;
        };
        // Row `a` receives every member `c >= a`: the set's words from `a`'s on, a word at a
        // time (a bundle adjustment point's keyframes span a few words, so this is linear
        // in the members instead of quadratic).
        let (lo, hi) = (lo / 64, hi / 64);
        self.set.clear();
        self.set.resize(hi - lo + 1, 0);
        for &b in blocks {
            self.set[b / 64 - lo] |= 1 << (b % 64);
        }
        for &a in blocks {
            let first = a / 64;
            let row = &mut self.bits[a * self.words + first..a * self.words + hi + 1];
            for (k, (word, &m)) in row.iter_mut().zip(&self.set[first - lo..]).enumerate() {
                *word |= if k == 0 { m & (!0u64 << (a % 64)) } else { m };
            }
        }
    }

    /// The pattern (its symbolic Cholesky factorisation follows on first use); `None` if
    /// faer refuses it.
    pub fn finish(self) -> Option<BlockPattern> {
        let mut row_ptr = vec![0usize];
        let mut cols = Vec::new();
        for r in 0..self.nb {
            for w in 0..self.words {
                let mut word = self.bits[r * self.words + w];
                while word != 0 {
                    let bit = word.trailing_zeros() as usize;
                    cols.push((64 * w + bit) as u32);
                    word &= word - 1;
                }
            }
            row_ptr.push(cols.len());
        }
        BlockPattern::new(self.nb, row_ptr, cols)
    }
}

/// The fixed pattern: per block row the sorted block columns `>= row`, slot numbers in
/// row-major order, and the scalar upper-triangular CSC layout handed to faer.
pub struct BlockPattern {
    nb: usize,
    row_ptr: Vec<usize>,
    cols: Vec<u32>,
    col_ptr: Vec<usize>,
    row_idx: Vec<usize>,
    /// Per CSC entry: `36 * slot + i + 6 * j` into the column-major blocks.
    src: Vec<usize>,
    /// The symbolic factorisation, `None` inside if faer refused both orderings.
    symbolic: OnceLock<Option<SymbolicCholesky<usize>>>,
}

/// A numeric Cholesky factor of a [`BlockPattern`] matrix; its buffers are reused by
/// [`BlockPattern::refactor`].
pub struct Factor {
    /// The factor's values (faer's supernodal layout).
    l: Vec<f64>,
    /// The matrix's values in the CSC layout.
    vals: Vec<f64>,
    scratch: MemBuffer,
}

impl BlockPattern {
    fn new(nb: usize, row_ptr: Vec<usize>, cols: Vec<u32>) -> Option<Self> {
        // Transpose: per block column, the block rows above (and at) the diagonal.
        let mut by_col: Vec<Vec<(usize, usize)>> = vec![Vec::new(); nb];
        for r in 0..nb {
            for s in row_ptr[r]..row_ptr[r + 1] {
                by_col[cols[s] as usize].push((r, s));
            }
        }
        let (mut col_ptr, mut row_idx, mut src) = (vec![0usize], Vec::new(), Vec::new());
        for (c, rows) in by_col.iter().enumerate() {
            for j in 0..6 {
                for &(r, s) in rows {
                    let top = if r == c { j + 1 } else { 6 };
                    for i in 0..top {
                        row_idx.push(6 * r + i);
                        src.push(36 * s + i + 6 * j);
                    }
                }
                col_ptr.push(row_idx.len());
            }
        }
        let n = 6 * nb;
        SymbolicSparseColMatRef::new_checked(n, n, &col_ptr, None, &row_idx);
        Some(Self {
            nb,
            row_ptr,
            cols,
            col_ptr,
            row_idx,
            src,
            symbolic: OnceLock::new(),
        })
    }

    /// The symbolic factorisation in the ordering with the smaller factor, computed on the
    /// first call; `None` if faer refuses both orderings.
    pub fn analyse(&self) -> Option<&SymbolicCholesky<usize>> {
        self.symbolic
            .get_or_init(|| {
                let n = 6 * self.nb;
                let sym =
                    SymbolicSparseColMatRef::new_checked(n, n, &self.col_ptr, None, &self.row_idx);
                let analyse = |ord| {
                    factorize_symbolic_cholesky(sym, faer::Side::Upper, ord, Default::default())
                        .ok()
                };
                match (
                    analyse(SymmetricOrdering::Identity),
                    analyse(SymmetricOrdering::Amd),
                ) {
                    (Some(own), Some(amd)) if amd.len_val() < own.len_val() => Some(amd),
                    (Some(own), _) => Some(own),
                    (None, amd) => amd,
                }
            })
            .as_ref()
    }

    /// Number of block rows.
    pub fn blocks(&self) -> usize {
        self.nb
    }

    /// Number of stored blocks (slots).
    pub fn slots(&self) -> usize {
        self.cols.len()
    }

    /// First slot of block row `r` and its sorted block columns.
    pub fn row(&self, r: usize) -> (usize, &[u32]) {
        (
            self.row_ptr[r],
            &self.cols[self.row_ptr[r]..self.row_ptr[r + 1]],
        )
    }

    /// Slot of the block `(r, c)`, `r <= c`; `None` outside the pattern.
    pub fn slot(&self, r: usize, c: usize) -> Option<usize> {
        let (start, cols) = self.row(r);
        cols.binary_search(&(c as u32)).ok().map(|k| start + k)
    }

    /// Entries of the Cholesky factor (the chosen ordering's fill included).
    pub fn factor_len(&self) -> usize {
        self.analyse().map_or(0, |s| s.len_val())
    }

    /// Cholesky factor of the matrix whose upper blocks are `blocks` (one per slot);
    /// `None` when it is not positive definite.
    pub fn factor(&self, blocks: &[Matrix6<f64>]) -> Option<Factor> {
        let par = faer::get_global_parallelism();
        let symbolic = self.analyse()?;
        let scratch = symbolic
            .factorize_numeric_llt_scratch::<f64>(par, Default::default())
            .or(symbolic.solve_in_place_scratch::<f64>(1, par));
        let mut f = Factor {
            l: vec![0.0; symbolic.len_val()],
            vals: vec![0.0; self.src.len()],
            scratch: MemBuffer::try_new(scratch).ok()?,
        };
        self.refactor(blocks, &mut f).then_some(f)
    }

    /// [`Self::factor`] into the buffers of an earlier factor `f` of this pattern; false
    /// (and `f` unusable until the next success) when the matrix is not positive definite.
    pub fn refactor(&self, blocks: &[Matrix6<f64>], f: &mut Factor) -> bool {
        let Some(symbolic) = self.analyse() else {
            return false;
        };
        f.vals
            .par_chunks_mut(1 << 16)
            .zip(self.src.par_chunks(1 << 16))
            .for_each(|(vals, src)| {
                for (v, &k) in vals.iter_mut().zip(src) {
                    *v = blocks[k / 36].as_slice()[k % 36];
                }
            });
        let n = 6 * self.nb;
        let sym = SymbolicSparseColMatRef::new_checked(n, n, &self.col_ptr, None, &self.row_idx);
        let mat = SparseColMatRef::new(sym, &f.vals);
        symbolic
            .factorize_numeric_llt(
                &mut f.l,
                mat,
                faer::Side::Upper,
                LltRegularization::default(),
                faer::get_global_parallelism(),
                MemStack::new(&mut f.scratch),
                Default::default(),
            )
            .is_ok()
    }

    /// Solves `A x = b` in place for the columns of `b`, `f` the factor of `A`.
    pub fn solve(&self, f: &Factor, b: &mut faer::Mat<f64>) {
        // A factor exists only once the analysis succeeded.
        let Some(symbolic) = self.analyse() else {
            return;
        };
        let par = faer::get_global_parallelism();
        let req = symbolic.solve_in_place_scratch::<f64>(b.ncols(), par);
        let mut buf = MemBuffer::new(req);
        LltRef::new(symbolic, &f.l).solve_in_place_with_conj(
            Conj::No,
            b.as_mut(),
            par,
            MemStack::new(&mut buf),
        );
    }
}

impl BlockPattern {
    /// The diagonal blocks `(A^-1)_bb` of the blocks `b` in `blocks` (consecutive), `f` the
    /// factor of `A`. With `P A P^T = L L^T`, `E^T A^-1 E = (L^-1 P E)^T (L^-1 P E)` for the
    /// unit columns `E` of those blocks: forward solves only, and (supernodal factor) only
    /// the supernodes where `L^-1 P E` is not yet zero, which for blocks at the end of the
    /// blocks' own order is the trailing corner of `L`. A simplicial factor (small systems)
    /// takes full solves.
    pub fn inverse_diagonal_blocks(
        &self,
        f: &Factor,
        blocks: std::ops::Range<usize>,
    ) -> Vec<Matrix6<f64>> {
        let Some(symbolic) = self.analyse() else {
            return Vec::new();
        };
        let (first, k) = (6 * blocks.start, 6 * blocks.len());
        let n = 6 * self.nb;
        let SymbolicCholeskyRaw::Supernodal(sn) = symbolic.raw() else {
            let mut x = faer::Mat::from_fn(n, k, |i, j| if i == first + j { 1.0 } else { 0.0 });
            self.solve(f, &mut x);
            return (0..blocks.len())
                .map(|c| Matrix6::from_fn(|i, j| x[(first + 6 * c + i, 6 * c + j)]))
                .collect();
        };
        // Row of each unknown in the factor's order.
        let row = |i: usize| symbolic.perm().map_or(i, |p| p.arrays().1[i]);
        let mut x = faer::Mat::<f64>::zeros(n, k);
        for j in 0..k {
            x[(row(first + j), j)] = 1.0;
        }
        let par = faer::get_global_parallelism();
        let l = SupernodalLltRef::new(sn, &f.l);
        let mut tmp = faer::Mat::<f64>::zeros(0, k);
        for s in 0..sn.n_supernodes() {
            let s = l.supernode(s);
            let size = s.val().ncols();
            let (top, bottom) = s.val().split_at_row(size);
            let mut xt = x.as_mut().subrows_mut(s.start(), size);
            if xt.rb().col_iter().all(|c| c.iter().all(|&v| v == 0.0)) {
                continue;
            }
            triangular_solve::solve_lower_triangular_in_place(top, xt.rb_mut(), par);
            tmp.resize_with(s.pattern().len(), k, |_, _| 0.0);
            matmul::matmul(tmp.as_mut(), Accum::Replace, bottom, xt.rb(), 1.0, par);
            for j in 0..k {
                for (t, &i) in s.pattern().iter().enumerate() {
                    x[(i, j)] -= tmp[(t, j)];
                }
            }
        }
        (0..blocks.len())
            .map(|c| {
                let y = x.as_ref().subcols(6 * c, 6);
                Matrix6::from_fn(|i, j| y.col(i).transpose() * y.col(j))
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The word-at-a-time `mark_all` against marking every pair of the list.
    #[test]
    fn mark_all_marks_every_pair() {
        let nb = 300;
        let (mut fast, mut pairs) = (PatternBuilder::new(nb), PatternBuilder::new(nb));
        let mut seed = 7u64;
        let mut next = |n: usize| {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (seed >> 33) as usize % n
        };
        for _ in 0..200 {
            let (start, len) = (next(nb), 1 + next(90));
            let mut list: Vec<usize> = (0..len).map(|_| (start + next(150)).min(nb - 1)).collect();
            list.push(next(nb));
            fast.mark_all(&list);
            for &a in &list {
                for &b in &list {
                    pairs.mark(a, b);
                }
            }
        }
        assert_eq!(fast.bits, pairs.bits);
        assert!(fast.bits.iter().map(|w| w.count_ones()).sum::<u32>() > 10 * nb as u32);
    }
    use nalgebra::DMatrix;

    /// A random positive definite block matrix on the pattern of `pairs` (and the
    /// diagonal), as blocks and dense.
    fn random_system(
        nb: usize,
        pairs: &[(usize, usize)],
        seed: u64,
    ) -> (BlockPattern, Vec<Matrix6<f64>>, DMatrix<f64>) {
        let mut b = PatternBuilder::new(nb);
        for &(r, c) in pairs {
            b.mark(c, r);
        }
        let pat = b.finish().expect("pattern");
        let mut blocks = vec![Matrix6::zeros(); pat.slots()];
        let mut dense = DMatrix::<f64>::zeros(6 * nb, 6 * nb);
        let mut seed = seed;
        let mut rnd = || {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((seed >> 11) as f64 / (1u64 << 53) as f64) - 0.5
        };
        for &(r, c) in pairs {
            let m = Matrix6::from_fn(|_, _| rnd());
            blocks[pat.slot(r, c).expect("slot")] = m;
            dense.view_mut((6 * r, 6 * c), (6, 6)).copy_from(&m);
            dense
                .view_mut((6 * c, 6 * r), (6, 6))
                .copy_from(&m.transpose());
        }
        for k in 0..nb {
            let a = Matrix6::from_fn(|_, _| rnd());
            let d = a * a.transpose() + Matrix6::identity() * (8.0 + nb as f64);
            blocks[pat.slot(k, k).expect("diag")] = d;
            dense.view_mut((6 * k, 6 * k), (6, 6)).copy_from(&d);
        }
        (pat, blocks, dense)
    }

    /// The diagonal blocks of the inverse from forward solves equal the dense inverse's,
    /// for a small system (simplicial factor, full solves) and a banded one with a dense
    /// border (supernodal factor, the bundle adjustment's shape: the border blocks last).
    #[test]
    fn inverse_diagonal_blocks_equal_the_dense_inverse() {
        let small = [(0, 3), (1, 2), (2, 6), (4, 5), (3, 6)];
        let nb = 90;
        let mut banded = Vec::new();
        for a in 0..nb - 6 {
            banded.extend((a + 1..(a + 12).min(nb - 6)).map(|b| (a, b)));
            banded.extend((nb - 6..nb).filter(|_| a % 7 == 0).map(|c| (a, c)));
        }
        banded.extend((nb - 6..nb).flat_map(|a| (a + 1..nb).map(move |b| (a, b))));
        let mut kinds = Vec::new();
        for (nb, pairs, range) in [(7, &small[..], 2..5), (nb, &banded[..], nb - 6..nb)] {
            let (pat, blocks, dense) = random_system(nb, pairs, 5);
            let f = pat.factor(&blocks).expect("pd");
            kinds.push(matches!(
                pat.analyse().expect("analysed").raw(),
                SymbolicCholeskyRaw::Supernodal(_)
            ));
            let inv = dense.try_inverse().expect("invertible");
            let got = pat.inverse_diagonal_blocks(&f, range.clone());
            assert_eq!(got.len(), range.len());
            for (b, g) in range.zip(&got) {
                let want = inv.view((6 * b, 6 * b), (6, 6));
                let err = (g - want).amax();
                assert!(err < 1e-12 * want.amax().max(1e-300), "block {b}: {err:e}");
            }
        }
        assert_eq!(kinds, [false, true], "both factor kinds exercised");
    }

    /// A random symmetric positive definite block matrix with a sparse pattern: the
    /// factor's solution matches a dense solve.
    #[test]
    fn sparse_factor_solves_like_dense() {
        let nb = 7;
        let pairs = [(0, 3), (1, 2), (2, 6), (4, 5), (3, 6)];
        let (pat, blocks, dense) = random_system(nb, &pairs, 1);
        let rhs = faer::Mat::from_fn(6 * nb, 2, |i, j| (i + 3 * j) as f64 * 0.1 - 1.0);
        let mut x = rhs.clone();
        pat.solve(&pat.factor(&blocks).expect("pd"), &mut x);
        let rd = DMatrix::from_fn(6 * nb, 2, |i, j| rhs[(i, j)]);
        let xd = dense.cholesky().expect("dense pd").solve(&rd);
        for i in 0..6 * nb {
            for j in 0..2 {
                assert!((x[(i, j)] - xd[(i, j)]).abs() < 1e-9, "{i},{j}");
            }
        }
        // Refactoring into the same buffers: twice the matrix, half the solution.
        let mut f = pat.factor(&blocks).expect("pd");
        let doubled: Vec<Matrix6<f64>> = blocks.iter().map(|b| b * 2.0).collect();
        assert!(pat.refactor(&doubled, &mut f));
        let mut half = rhs.clone();
        pat.solve(&f, &mut half);
        for i in 0..6 * nb {
            for j in 0..2 {
                assert!((2.0 * half[(i, j)] - xd[(i, j)]).abs() < 1e-9, "{i},{j}");
            }
        }
        assert!(pat.factor_len() >= pat.src.len());
        assert_eq!(pat.slot(1, 0), None);
        assert!(pat.slot(0, 1).is_none() && pat.slot(0, 3).is_some());
    }
}
