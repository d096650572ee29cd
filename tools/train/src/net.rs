//! The network's flat parameter layout, its preallocated batch buffers, and the batched forward and
//! backward passes (GEMMs through `gemm`, fused elementwise passes through rayon).
//!
//! Parameters live in one flat `Vec<f32>` in PyTorch `state_dict` order (`W0 [h0][n_in]`, `b0`, `W1`,
//! `b1`, …), so Adam, checkpoints and the gradient check treat them as one vector. This module does not
//! know about losses, optimisers or epochs (see the parent module).
//!
//! The elementwise passes are written to vectorise (dropout drawn per block, then applied branch-free;
//! ReLU gradient branch-free; bias sums one column block per thread); the measurements behind that are in
//! `docs/decisions.md` ("Training").

use super::rng::{XorShift64Star, derive, tag};

/// Rows per chunk of the elementwise passes. Fixed (not derived from the thread count) so that dropout
/// streams, which are keyed by chunk index, do not depend on how rayon schedules the chunks.
pub(crate) const CHUNK_ROWS: usize = 64;

/// Where each tensor lives in the flat parameter vector.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Layout {
    /// Layer sizes including input and output, e.g. `[40, 268, 215, 1]`.
    pub sizes: Vec<usize>,
    /// Offset of each layer's weight `[n_out][n_in]`.
    pub w_off: Vec<usize>,
    /// Offset of each layer's bias `[n_out]`.
    pub b_off: Vec<usize>,
    /// Total parameter count.
    pub n_params: usize,
}

impl Layout {
    /// The layout for `sizes` (input, hidden…, output).
    pub fn new(sizes: &[usize]) -> Self {
        let (mut w_off, mut b_off, mut off) = (Vec::new(), Vec::new(), 0);
        for l in 0..sizes.len() - 1 {
            w_off.push(off);
            off += sizes[l] * sizes[l + 1];
            b_off.push(off);
            off += sizes[l + 1];
        }
        Self {
            sizes: sizes.to_vec(),
            w_off,
            b_off,
            n_params: off,
        }
    }
    /// Number of dense layers (hidden + output).
    pub fn n_layers(&self) -> usize {
        self.sizes.len() - 1
    }
    /// Inputs of layer `l`.
    pub fn n_in(&self, l: usize) -> usize {
        self.sizes[l]
    }
    /// Outputs of layer `l`.
    pub fn n_out(&self, l: usize) -> usize {
        self.sizes[l + 1]
    }
    /// Weight of layer `l` inside `p`.
    pub fn weight<'a>(&self, p: &'a [f32], l: usize) -> &'a [f32] {
        &p[self.w_off[l]..self.w_off[l] + self.n_in(l) * self.n_out(l)]
    }
    /// Bias of layer `l` inside `p`.
    pub fn bias<'a>(&self, p: &'a [f32], l: usize) -> &'a [f32] {
        &p[self.b_off[l]..self.b_off[l] + self.n_out(l)]
    }
}

/// All per-batch buffers, allocated once for `cap` rows.
pub(crate) struct Workspace {
    /// Row capacity (the batch size).
    pub cap: usize,
    /// Normalised input batch, `cap × n_in`.
    pub x: Vec<f32>,
    /// Per layer, its post-activation (and post-dropout) output `cap × n_out`; the last one is ŷ.
    pub act: Vec<Vec<f32>>,
    /// Per layer, dLoss/d(pre-activation) `cap × n_out`; the last one is dLoss/dŷ.
    pub delta: Vec<Vec<f32>>,
}

impl Workspace {
    /// Buffers for `layout` and up to `cap` rows.
    pub fn new(layout: &Layout, cap: usize) -> Self {
        let per_layer = || {
            (0..layout.n_layers())
                .map(|l| vec![0f32; cap * layout.n_out(l)])
                .collect()
        };
        Self {
            cap,
            x: vec![0f32; cap * layout.sizes[0]],
            act: per_layer(),
            delta: per_layer(),
        }
    }
}

/// Dropout settings of one training step.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Dropout {
    /// A 16-bit lane below this drops the unit: `round(p · 65536)`.
    pub threshold: u16,
    /// Scale of kept units, `65536 / (65536 − threshold)` (1/(1−p) with the quantised p).
    pub keep_scale: f32,
    /// Stream key of this step (seed and global step already mixed in).
    pub key: u64,
}

impl Dropout {
    /// Settings for probability `p` in [0, 1) and a step key; `None` when `p` rounds to 0.
    pub fn new(p: f32, key: u64) -> Option<Self> {
        let threshold = (p as f64 * 65536.0).round().min(65535.0) as u16;
        (threshold > 0).then(|| Self {
            threshold,
            keep_scale: (65536.0 / (65536.0 - threshold as f64)) as f32,
            key,
        })
    }
}

/// A strided read-only matrix view: element `(i, j)` is `data[i·rs + j·cs]`.
#[derive(Clone, Copy)]
struct View<'a> {
    data: &'a [f32],
    rows: usize,
    cols: usize,
    rs: usize,
    cs: usize,
}

impl<'a> View<'a> {
    /// Row-major contiguous `rows × cols`.
    fn rm(data: &'a [f32], rows: usize, cols: usize) -> Self {
        Self {
            data,
            rows,
            cols,
            rs: cols,
            cs: 1,
        }
    }
    /// The transpose of a row-major `rows × cols` matrix stored in `data` (a `cols × rows` view).
    fn rm_t(data: &'a [f32], rows: usize, cols: usize) -> Self {
        Self {
            data,
            rows: cols,
            cols: rows,
            rs: 1,
            cs: cols,
        }
    }
    fn check(&self) {
        if self.rows > 0 && self.cols > 0 {
            let last = (self.rows - 1) * self.rs + (self.cols - 1) * self.cs;
            assert!(last < self.data.len(), "matrix view out of bounds");
        }
    }
}

/// `dst[m×n] (row-major) = (accumulate ? dst : 0) + lhs[m×k] · rhs[k×n]`, through `gemm::gemm`.
///
/// `gemm` 0.19 computes `dst := alpha·dst + beta·lhs·rhs` with each operand's column stride given
/// before its row stride; transposes are only strides. The extents are checked here so the unsafe call
/// cannot touch memory outside the slices.
fn matmul(dst: &mut [f32], lhs: View<'_>, rhs: View<'_>, accumulate: bool, threads: usize) {
    let (m, k, n) = (lhs.rows, lhs.cols, rhs.cols);
    assert_eq!(rhs.rows, k, "inner dimensions differ");
    assert!(dst.len() >= m * n, "destination too small");
    lhs.check();
    rhs.check();
    if m == 0 || n == 0 {
        return;
    }
    let parallelism = if threads > 1 {
        gemm::Parallelism::Rayon(threads)
    } else {
        gemm::Parallelism::None
    };
    // SAFETY: every element addressed (dst: i·n + j < m·n; lhs/rhs: checked above) lies inside its
    // slice; `dst` is exclusively borrowed and does not alias `lhs`/`rhs` (distinct borrows).
    unsafe {
        gemm::gemm(
            m,
            n,
            k,
            dst.as_mut_ptr(),
            1,
            n as isize,
            accumulate,
            lhs.data.as_ptr(),
            lhs.cs as isize,
            lhs.rs as isize,
            rhs.data.as_ptr(),
            rhs.cs as isize,
            rhs.rs as isize,
            1.0f32,
            1.0f32,
            false,
            false,
            false,
            parallelism,
        );
    }
}

/// Forward pass over the first `rows` rows of `ws.x` (already normalised). With `dropout`, hidden
/// outputs are masked and scaled (training mode); without, the pass is the eval-mode network.
/// The caller runs this inside the trainer's rayon pool.
pub(crate) fn forward(
    layout: &Layout,
    p: &[f32],
    ws: &mut Workspace,
    rows: usize,
    dropout: Option<Dropout>,
    threads: usize,
) {
    use rayon::prelude::*;
    assert!(rows <= ws.cap);
    let n_layers = layout.n_layers();
    for l in 0..n_layers {
        let (n_in, n_out) = (layout.n_in(l), layout.n_out(l));
        let (before, after) = ws.act.split_at_mut(l);
        let input: &[f32] = if l == 0 { &ws.x } else { &before[l - 1] };
        let out = &mut after[0][..rows * n_out];
        matmul(
            out,
            View::rm(&input[..rows * n_in], rows, n_in),
            View::rm_t(layout.weight(p, l), n_out, n_in),
            false,
            threads,
        );
        let bias = layout.bias(p, l);
        if l + 1 == n_layers {
            // Linear output layer: only the bias.
            for row in out.chunks_exact_mut(n_out) {
                for (z, b) in row.iter_mut().zip(bias) {
                    *z += b;
                }
            }
            continue;
        }
        // Fused bias + ReLU (+ dropout) pass, parallel over fixed row chunks.
        out.par_chunks_mut(CHUNK_ROWS * n_out)
            .enumerate()
            .for_each(|(ci, chunk)| hidden_activation(chunk, bias, dropout, l, ci));
    }
}

/// Units per block of the dropout pass: the 16-bit lanes of one block are drawn first (the serial
/// xorshift chain), then applied by a branch-free loop that LLVM vectorises. A multiple of 4, so the
/// blocks split a row exactly where the one-draw-per-four-units stream does.
const DROPOUT_BLOCK: usize = 256;

/// Bias + ReLU, and with `dropout` the mask and 1/(1−p) scale, in place over one chunk of rows
/// (`chunk.len()` a multiple of `bias.len()`); `l` and `ci` key the chunk's dropout stream.
///
/// Dropout stream: one xorshift64* draw per four consecutive units of a row (its 16-bit lanes, lowest
/// first); a unit is kept when its lane ≥ the threshold. Rewritten from a per-unit scalar loop (about
/// a third of an epoch's profile, unvectorised) into draw-then-apply blocks; the stream and the
/// arithmetic are unchanged, so the result is bit-identical (tested against the scalar definition).
#[inline]
fn hidden_activation(
    chunk: &mut [f32],
    bias: &[f32],
    dropout: Option<Dropout>,
    l: usize,
    ci: usize,
) {
    let n_out = bias.len();
    match dropout {
        None => {
            for row in chunk.chunks_exact_mut(n_out) {
                for (z, &b) in row.iter_mut().zip(bias) {
                    *z = (*z + b).max(0.0);
                }
            }
        }
        Some(d) => {
            let mut rng = XorShift64Star::new(derive(d.key, &[tag::DROPOUT, l as u64, ci as u64]));
            let (threshold, keep_scale) = (d.threshold, d.keep_scale);
            let mut lanes = [0u16; DROPOUT_BLOCK];
            for row in chunk.chunks_exact_mut(n_out) {
                for (zs, bs) in row
                    .chunks_mut(DROPOUT_BLOCK)
                    .zip(bias.chunks(DROPOUT_BLOCK))
                {
                    let lanes = &mut lanes[..zs.len().div_ceil(4) * 4];
                    for q in lanes.chunks_exact_mut(4) {
                        let bits = rng.next_u64();
                        q[0] = bits as u16;
                        q[1] = (bits >> 16) as u16;
                        q[2] = (bits >> 32) as u16;
                        q[3] = (bits >> 48) as u16;
                    }
                    for ((z, &b), &r) in zs.iter_mut().zip(bs).zip(lanes.iter()) {
                        let h = (*z + b).max(0.0) * keep_scale;
                        *z = if r >= threshold { h } else { 0.0 };
                    }
                }
            }
        }
    }
}

/// Backward pass for the first `rows` rows, after [`forward`] with the same `dropout`, with
/// dLoss/dŷ already in the last `ws.delta`. Writes the full gradient into `g` (same layout as `p`).
pub(crate) fn backward(
    layout: &Layout,
    p: &[f32],
    g: &mut [f32],
    ws: &mut Workspace,
    rows: usize,
    dropout: Option<Dropout>,
    threads: usize,
) {
    use rayon::prelude::*;
    let keep_scale = dropout.map_or(1.0, |d| d.keep_scale);
    for l in (0..layout.n_layers()).rev() {
        let (n_in, n_out) = (layout.n_in(l), layout.n_out(l));
        let input: &[f32] = if l == 0 {
            &ws.x[..rows * n_in]
        } else {
            &ws.act[l - 1][..rows * n_in]
        };
        let (lower, upper) = ws.delta.split_at_mut(l);
        let dz = &upper[0][..rows * n_out];
        // dW[n_out × n_in] = dZᵀ · A_prev
        let gw = &mut g[layout.w_off[l]..layout.w_off[l] + n_out * n_in];
        matmul(
            gw,
            View::rm_t(dz, rows, n_out),
            View::rm(input, rows, n_in),
            false,
            threads,
        );
        // db = column sums of dZ, each column summed in row order (deterministic). Parallel over
        // fixed column blocks: the same additions in the same order as one sequential pass, so the
        // result does not depend on the thread count.
        let gb = &mut g[layout.b_off[l]..layout.b_off[l] + n_out];
        let cols = bias_block_cols(n_out, threads);
        gb.par_chunks_mut(cols)
            .enumerate()
            .for_each(|(bi, acc)| column_sums(acc, dz, n_out, bi * cols));
        if l == 0 {
            break; // no gradient with respect to the input
        }
        // dA_prev[rows × n_in] = dZ · W, then × ReLU'·mask·scale (a kept, active unit has output > 0).
        let dprev = &mut lower[l - 1][..rows * n_in];
        matmul(
            dprev,
            View::rm(dz, rows, n_out),
            View::rm(layout.weight(p, l), n_out, n_in),
            false,
            threads,
        );
        dprev
            .par_chunks_mut(CHUNK_ROWS * n_in)
            .zip(input.par_chunks(CHUNK_ROWS * n_in))
            .for_each(|(d, a)| relu_dropout_grad(d, a, keep_scale));
    }
}

/// Columns per parallel block of the bias-gradient sums: one block per thread, a multiple of 16
/// floats (one cache line), so every thread streams its own part of each row and dZ is read once
/// in total (narrow blocks re-read the whole matrix once per block: 4 % of an epoch with 32 columns).
/// Column sums are independent, so the block width never changes a bit of the result.
fn bias_block_cols(n_cols: usize, threads: usize) -> usize {
    n_cols.div_ceil(threads.max(1)).next_multiple_of(16).max(16)
}

/// `acc[j] = Σ_rows m[row][c0 + j]` over the row-major `m` (`n_cols` wide), rows in order.
#[inline]
fn column_sums(acc: &mut [f32], m: &[f32], n_cols: usize, c0: usize) {
    acc.fill(0.0);
    let w = acc.len();
    for row in m.chunks_exact(n_cols) {
        for (a, &v) in acc.iter_mut().zip(&row[c0..c0 + w]) {
            *a += v;
        }
    }
}

/// `d ← d · keep_scale` where the layer's output `a` is > 0 (active and kept), else 0: the ReLU and
/// dropout derivative. Branch-free with the scale in a local, so LLVM vectorises it (the closure
/// version compiled to a scalar loop reloading the captured scale every element).
#[inline]
fn relu_dropout_grad(d: &mut [f32], a: &[f32], keep_scale: f32) {
    for (dv, &av) in d.iter_mut().zip(a) {
        *dv = if av > 0.0 { *dv * keep_scale } else { 0.0 };
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn matmul_strides_match_naive_products() {
        // A[3×2], B[2×4] row-major; also Aᵀ·C with C[3×4].
        let a: Vec<f32> = (0..6).map(|i| i as f32 - 2.0).collect();
        let b: Vec<f32> = (0..8).map(|i| (i as f32) * 0.5).collect();
        let mut d = vec![0f32; 12];
        matmul(&mut d, View::rm(&a, 3, 2), View::rm(&b, 2, 4), false, 1);
        for i in 0..3 {
            for j in 0..4 {
                let want: f32 = (0..2).map(|p| a[i * 2 + p] * b[p * 4 + j]).sum();
                assert_eq!(d[i * 4 + j], want);
            }
        }
        let c: Vec<f32> = (0..12).map(|i| 1.0 + i as f32).collect();
        let mut e = vec![1f32; 8];
        matmul(&mut e, View::rm_t(&a, 3, 2), View::rm(&c, 3, 4), true, 1);
        for i in 0..2 {
            for j in 0..4 {
                let want: f32 = 1.0 + (0..3).map(|p| a[p * 2 + i] * c[p * 4 + j]).sum::<f32>();
                assert_eq!(e[i * 4 + j], want);
            }
        }
    }

    /// The per-unit scalar definition of the dropout pass (the code before the block rewrite).
    fn hidden_activation_scalar(chunk: &mut [f32], bias: &[f32], d: Dropout, l: usize, ci: usize) {
        let mut rng = XorShift64Star::new(derive(d.key, &[tag::DROPOUT, l as u64, ci as u64]));
        for row in chunk.chunks_exact_mut(bias.len()) {
            for (zs, bs) in row.chunks_mut(4).zip(bias.chunks(4)) {
                let mut bits = rng.next_u64();
                for (z, b) in zs.iter_mut().zip(bs) {
                    let keep = (bits as u16) >= d.threshold;
                    bits >>= 16;
                    let h = (*z + b).max(0.0) * d.keep_scale;
                    *z = if keep { h } else { 0.0 };
                }
            }
        }
    }

    #[test]
    fn blocked_dropout_pass_is_bit_identical_to_the_scalar_definition() {
        let mut g = XorShift64Star::new(99);
        let mut u = || (g.next_u64() >> 40) as f32 / (1u64 << 24) as f32 * 2.0 - 1.0;
        // Widths: not a multiple of 4, the paper's two, and wider than one block (not a multiple of 4).
        for (n_out, p) in [(7usize, 0.5f32), (215, 0.07), (268, 0.1), (599, 0.3)] {
            let rows = 5;
            let bias: Vec<f32> = (0..n_out).map(|_| u()).collect();
            let z: Vec<f32> = (0..rows * n_out).map(|_| u()).collect();
            let d = Dropout::new(p, 1234 + n_out as u64).unwrap();
            let (mut fast, mut slow) = (z.clone(), z.clone());
            hidden_activation(&mut fast, &bias, Some(d), 1, 3);
            hidden_activation_scalar(&mut slow, &bias, d, 1, 3);
            let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
            assert_eq!(bits(&fast), bits(&slow), "width {n_out}");
            let dropped = fast.iter().filter(|&&x| x == 0.0).count();
            let relu_zero = z
                .chunks_exact(n_out)
                .flat_map(|r| r.iter().zip(&bias).map(|(a, b)| a + b <= 0.0))
                .filter(|&x| x)
                .count();
            assert!(
                dropped > relu_zero,
                "width {n_out}: dropout dropped nothing"
            );
        }
    }

    #[test]
    fn blocked_column_sums_equal_the_row_order_sums() {
        let (rows, cols) = (37, 75);
        let m: Vec<f32> = (0..rows * cols)
            .map(|i| ((i * 31) % 17) as f32 * 0.37 - 3.0)
            .collect();
        for threads in [1, 2, 3, 8] {
            let w = bias_block_cols(cols, threads);
            assert!(w.is_multiple_of(16) && w * threads >= cols);
            let mut blocked = vec![f32::NAN; cols];
            for (bi, acc) in blocked.chunks_mut(w).enumerate() {
                column_sums(acc, &m, cols, bi * w);
            }
            for (j, &b) in blocked.iter().enumerate() {
                let want = (0..rows).fold(0f32, |s, r| s + m[r * cols + j]);
                assert_eq!(b.to_bits(), want.to_bits(), "column {j}, {threads} threads");
            }
        }
    }

    #[test]
    fn relu_dropout_grad_masks_inactive_units() {
        let a = [0.0, 1.5, -0.0, 2.0, 0.0];
        let mut d = [1.0, 2.0, 3.0, -4.0, 5.0];
        relu_dropout_grad(&mut d, &a, 1.25);
        assert_eq!(d, [0.0, 2.5, 0.0, -5.0, 0.0]);
    }

    #[test]
    fn layout_is_pytorch_state_dict_order() {
        let l = Layout::new(&[3, 4, 1]);
        assert_eq!(l.w_off, vec![0, 16]);
        assert_eq!(l.b_off, vec![12, 20]);
        assert_eq!(l.n_params, 21);
    }
}
