//! The x86-64 intrinsics paths: AVX-512F (16 lanes in one zmm) and AVX2 + FMA + F16C (16 lanes in two
//! ymm). Not the portable fallback (see `portable.rs`) and not a general GEMV.
//!
//! Each path runs the *whole* forward pass inside one `#[target_feature]` function and every helper has
//! the same `#[target_feature]` attribute plus `#[inline]`, so LLVM inlines them and compiles the
//! surrounding loops with the wide registers too (helpers without the attribute are not inlined into
//! the wide-register code; `docs/decisions.md`, "Inference kernel"). Hidden layers keep `G` output blocks in registers (AVX-512: up to 8 zmm, AVX2: up to
//! 4 × 2 ymm), preload the bias, broadcast `x[i]`, issue one FMA per block and fuse the ReLU into the
//! store. Weights are decoded in-register: f16 with `vcvtph2ps`, bf16 by a 16-bit left shift.
//!
//! `unsafe` is confined here: raw-pointer loads/stores whose bounds `Net::fits` checks once per call, and
//! the calls into `#[target_feature]` functions, made only after run-time feature detection.

use super::{LANES, LayerPlan, Net, Scratch, Store, dt};

/// Bytes of one 16-wide weight row for a dtype code.
const fn row_bytes(d: u8) -> usize {
    if d == dt::F32 { 64 } else { 32 }
}

/// Weight base pointer of the store (64-byte aligned).
fn weight_ptr(store: &Store) -> *const u8 {
    match store {
        Store::F32(v) => v.as_ptr().cast(),
        Store::Half(v) => v.as_ptr().cast(),
    }
}

/// AVX-512 forward pass; falls back to the portable path if the CPU lacks AVX-512F.
pub(super) fn forward_avx512(net: &Net, s: &mut Scratch, code: u8) -> f32 {
    if !std::is_x86_feature_detected!("avx512f") {
        return super::portable::forward(net, s, code);
    }
    if !net.fits(s) {
        return f32::NAN;
    }
    let w = weight_ptr(&net.store);
    // SAFETY: AVX-512F is present (checked above); `fits` guarantees every row, bias block and activation
    // block addressed by the kernel lies inside its allocation; `code` matches the store (checked by the
    // caller, and a mismatch would only mis-decode in-bounds memory).
    unsafe {
        match code {
            dt::F32 => avx512::run::<{ dt::F32 }>(net, s, w),
            dt::F16 => avx512::run::<{ dt::F16 }>(net, s, w),
            _ => avx512::run::<{ dt::BF16 }>(net, s, w),
        }
    }
}

/// AVX2 + FMA + F16C forward pass; falls back to the portable path if the CPU lacks one of them.
pub(super) fn forward_avx2(net: &Net, s: &mut Scratch, code: u8) -> f32 {
    if !(std::is_x86_feature_detected!("avx2")
        && std::is_x86_feature_detected!("fma")
        && std::is_x86_feature_detected!("f16c"))
    {
        return super::portable::forward(net, s, code);
    }
    if !net.fits(s) {
        return f32::NAN;
    }
    let w = weight_ptr(&net.store);
    // SAFETY: as in `forward_avx512`, with AVX2, FMA and F16C detected above.
    unsafe {
        match code {
            dt::F32 => avx2::run::<{ dt::F32 }>(net, s, w),
            dt::F16 => avx2::run::<{ dt::F16 }>(net, s, w),
            _ => avx2::run::<{ dt::BF16 }>(net, s, w),
        }
    }
}

mod avx512 {
    use super::*;
    use std::arch::x86_64::*;

    /// Output blocks per pass: 8 zmm accumulators (128 outputs).
    const MAX_G: usize = 8;

    /// Loads weight row `r` as 16 f32.
    ///
    /// # Safety
    /// `w + r * row_bytes(D)` must point to a readable row of the store, aligned as the store aligns it.
    #[target_feature(enable = "avx512f")]
    #[inline]
    unsafe fn load_row<const D: u8>(w: *const u8, r: usize) -> __m512 {
        // SAFETY: caller contract; f32 rows are 64-byte aligned, half rows 32-byte aligned.
        unsafe {
            let p = w.add(r * row_bytes(D));
            match D {
                dt::F32 => _mm512_load_ps(p.cast()),
                dt::F16 => _mm512_cvtph_ps(_mm256_load_si256(p.cast())),
                _ => _mm512_castsi512_ps(_mm512_slli_epi32::<16>(_mm512_cvtepu16_epi32(
                    _mm256_load_si256(p.cast()),
                ))),
            }
        }
    }

    /// The whole forward pass on the normalised input in `s.xin`.
    ///
    /// # Safety
    /// AVX-512F must be available, `net.fits(s)` must hold and `w` must be the store's base pointer.
    #[target_feature(enable = "avx512f")]
    pub(super) unsafe fn run<const D: u8>(net: &Net, s: &mut Scratch, w: *const u8) -> f32 {
        let bias = net.bias.as_ptr().cast::<f32>();
        let a = s.a.as_mut_ptr().cast::<f32>();
        let b = s.b.as_mut_ptr().cast::<f32>();
        let mut src = s.xin.as_ptr().cast::<f32>();
        for (k, p) in net.hidden[..net.n_hidden].iter().enumerate() {
            let dst = if k % 2 == 0 { a } else { b };
            // SAFETY: `fits` bounds every block of this layer; src and dst are distinct buffers.
            unsafe { dense::<D>(w, p, bias.add(p.bias_blk0 * LANES), src, dst) };
            src = dst;
        }
        let o = &net.out;
        let mut acc = [_mm512_setzero_ps(); 4];
        for r in 0..o.n_blk {
            // SAFETY: rows row0..row0+n_blk and activation blocks 0..n_blk are in bounds (`fits`).
            let (wv, xv) = unsafe {
                (
                    load_row::<D>(w, o.row0 + r),
                    _mm512_load_ps(src.add(r * LANES)),
                )
            };
            acc[r % 4] = _mm512_fmadd_ps(wv, xv, acc[r % 4]);
        }
        let sum = _mm512_add_ps(_mm512_add_ps(acc[0], acc[1]), _mm512_add_ps(acc[2], acc[3]));
        _mm512_reduce_add_ps(sum) + net.out_bias
    }

    /// One hidden layer `y = relu(W x + b)`.
    ///
    /// # Safety
    /// Rows `p.row0 .. p.row0 + p.n_blk * p.n_in`, `p.n_blk` blocks at `bias` and `y`, and `p.n_in` floats at
    /// `x` must be valid; `x` and `y` must not overlap.
    #[target_feature(enable = "avx512f")]
    #[inline]
    unsafe fn dense<const D: u8>(
        w: *const u8,
        p: &LayerPlan,
        bias: *const f32,
        x: *const f32,
        y: *mut f32,
    ) {
        let ni = p.n_in;
        let mut blk = 0;
        // SAFETY (all calls below): block range blk..blk+G lies within 0..p.n_blk.
        while blk + MAX_G <= p.n_blk {
            unsafe {
                group::<D, MAX_G>(
                    w,
                    p.row0 + blk * ni,
                    ni,
                    x,
                    bias.add(blk * LANES),
                    y.add(blk * LANES),
                )
            };
            blk += MAX_G;
        }
        let (r0, bb, yy) = (
            p.row0 + blk * ni,
            unsafe { bias.add(blk * LANES) },
            unsafe { y.add(blk * LANES) },
        );
        unsafe {
            match p.n_blk - blk {
                1 => group::<D, 1>(w, r0, ni, x, bb, yy),
                2 => group::<D, 2>(w, r0, ni, x, bb, yy),
                3 => group::<D, 3>(w, r0, ni, x, bb, yy),
                4 => group::<D, 4>(w, r0, ni, x, bb, yy),
                5 => group::<D, 5>(w, r0, ni, x, bb, yy),
                6 => group::<D, 6>(w, r0, ni, x, bb, yy),
                7 => group::<D, 7>(w, r0, ni, x, bb, yy),
                _ => {}
            }
        }
    }

    /// `G` consecutive output blocks; block `g`'s row for input `i` is `row0 + g * ni + i`.
    ///
    /// # Safety
    /// As for [`dense`], restricted to these `G` blocks.
    #[target_feature(enable = "avx512f")]
    #[inline]
    unsafe fn group<const D: u8, const G: usize>(
        w: *const u8,
        row0: usize,
        ni: usize,
        x: *const f32,
        bias: *const f32,
        y: *mut f32,
    ) {
        let mut acc = [_mm512_setzero_ps(); G];
        for (g, a) in acc.iter_mut().enumerate() {
            // SAFETY: G bias blocks, 64-byte aligned.
            *a = unsafe { _mm512_load_ps(bias.add(g * LANES)) };
        }
        for i in 0..ni {
            // SAFETY: i < ni floats at x.
            let xv = _mm512_set1_ps(unsafe { *x.add(i) });
            for (g, a) in acc.iter_mut().enumerate() {
                // SAFETY: row row0 + g*ni + i belongs to this layer.
                *a = _mm512_fmadd_ps(unsafe { load_row::<D>(w, row0 + g * ni + i) }, xv, *a);
            }
        }
        let z = _mm512_setzero_ps();
        for (g, a) in acc.iter().enumerate() {
            // SAFETY: G output blocks, 64-byte aligned.
            unsafe { _mm512_store_ps(y.add(g * LANES), _mm512_max_ps(*a, z)) };
        }
    }
}

mod avx2 {
    use super::*;
    use std::arch::x86_64::*;

    /// Output blocks per pass: 4 blocks = 8 ymm accumulators (64 outputs).
    const MAX_G: usize = 4;

    /// Loads weight row `r` as 16 f32 in two ymm (lanes 0–7, 8–15).
    ///
    /// # Safety
    /// `w + r * row_bytes(D)` must point to a readable row of the store, aligned as the store aligns it.
    #[target_feature(enable = "avx2,fma,f16c")]
    #[inline]
    unsafe fn load_row<const D: u8>(w: *const u8, r: usize) -> [__m256; 2] {
        // SAFETY: caller contract; f32 rows are 64-byte aligned, half rows 32-byte aligned.
        unsafe {
            let p = w.add(r * row_bytes(D));
            match D {
                dt::F32 => [_mm256_load_ps(p.cast()), _mm256_load_ps(p.add(32).cast())],
                dt::F16 => [
                    _mm256_cvtph_ps(_mm_load_si128(p.cast())),
                    _mm256_cvtph_ps(_mm_load_si128(p.add(16).cast())),
                ],
                _ => [
                    _mm256_castsi256_ps(_mm256_slli_epi32::<16>(_mm256_cvtepu16_epi32(
                        _mm_load_si128(p.cast()),
                    ))),
                    _mm256_castsi256_ps(_mm256_slli_epi32::<16>(_mm256_cvtepu16_epi32(
                        _mm_load_si128(p.add(16).cast()),
                    ))),
                ],
            }
        }
    }

    /// Loads 16 f32 (one 64-byte aligned block) as two ymm.
    ///
    /// # Safety
    /// 16 readable, 32-byte aligned floats at `p`.
    #[target_feature(enable = "avx2,fma,f16c")]
    #[inline]
    unsafe fn load_block(p: *const f32) -> [__m256; 2] {
        // SAFETY: caller contract.
        unsafe { [_mm256_load_ps(p), _mm256_load_ps(p.add(8))] }
    }

    /// The whole forward pass on the normalised input in `s.xin`.
    ///
    /// # Safety
    /// AVX2, FMA and F16C must be available, `net.fits(s)` must hold and `w` must be the store's base.
    #[target_feature(enable = "avx2,fma,f16c")]
    pub(super) unsafe fn run<const D: u8>(net: &Net, s: &mut Scratch, w: *const u8) -> f32 {
        let bias = net.bias.as_ptr().cast::<f32>();
        let a = s.a.as_mut_ptr().cast::<f32>();
        let b = s.b.as_mut_ptr().cast::<f32>();
        let mut src = s.xin.as_ptr().cast::<f32>();
        for (k, p) in net.hidden[..net.n_hidden].iter().enumerate() {
            let dst = if k % 2 == 0 { a } else { b };
            // SAFETY: `fits` bounds every block of this layer; src and dst are distinct buffers.
            unsafe { dense::<D>(w, p, bias.add(p.bias_blk0 * LANES), src, dst) };
            src = dst;
        }
        let o = &net.out;
        let mut acc = [_mm256_setzero_ps(); 4];
        for r in 0..o.n_blk {
            // SAFETY: rows row0..row0+n_blk and activation blocks 0..n_blk are in bounds (`fits`).
            let (wv, xv) =
                unsafe { (load_row::<D>(w, o.row0 + r), load_block(src.add(r * LANES))) };
            let k = 2 * (r % 2);
            acc[k] = _mm256_fmadd_ps(wv[0], xv[0], acc[k]);
            acc[k + 1] = _mm256_fmadd_ps(wv[1], xv[1], acc[k + 1]);
        }
        let s8 = _mm256_add_ps(_mm256_add_ps(acc[0], acc[1]), _mm256_add_ps(acc[2], acc[3]));
        let s4 = _mm_add_ps(_mm256_castps256_ps128(s8), _mm256_extractf128_ps::<1>(s8));
        let s2 = _mm_add_ps(s4, _mm_movehl_ps(s4, s4));
        let s1 = _mm_add_ss(s2, _mm_shuffle_ps::<1>(s2, s2));
        _mm_cvtss_f32(s1) + net.out_bias
    }

    /// One hidden layer `y = relu(W x + b)`.
    ///
    /// # Safety
    /// As for the AVX-512 `dense`.
    #[target_feature(enable = "avx2,fma,f16c")]
    #[inline]
    unsafe fn dense<const D: u8>(
        w: *const u8,
        p: &LayerPlan,
        bias: *const f32,
        x: *const f32,
        y: *mut f32,
    ) {
        let ni = p.n_in;
        let mut blk = 0;
        // SAFETY (all calls below): block range blk..blk+G lies within 0..p.n_blk.
        while blk + MAX_G <= p.n_blk {
            unsafe {
                group::<D, MAX_G>(
                    w,
                    p.row0 + blk * ni,
                    ni,
                    x,
                    bias.add(blk * LANES),
                    y.add(blk * LANES),
                )
            };
            blk += MAX_G;
        }
        let (r0, bb, yy) = (
            p.row0 + blk * ni,
            unsafe { bias.add(blk * LANES) },
            unsafe { y.add(blk * LANES) },
        );
        unsafe {
            match p.n_blk - blk {
                1 => group::<D, 1>(w, r0, ni, x, bb, yy),
                2 => group::<D, 2>(w, r0, ni, x, bb, yy),
                3 => group::<D, 3>(w, r0, ni, x, bb, yy),
                _ => {}
            }
        }
    }

    /// `G` consecutive output blocks; block `g`'s row for input `i` is `row0 + g * ni + i`.
    ///
    /// # Safety
    /// As for [`dense`], restricted to these `G` blocks.
    #[target_feature(enable = "avx2,fma,f16c")]
    #[inline]
    unsafe fn group<const D: u8, const G: usize>(
        w: *const u8,
        row0: usize,
        ni: usize,
        x: *const f32,
        bias: *const f32,
        y: *mut f32,
    ) {
        let mut acc = [[_mm256_setzero_ps(); 2]; G];
        for (g, a) in acc.iter_mut().enumerate() {
            // SAFETY: G bias blocks, 64-byte aligned.
            *a = unsafe { load_block(bias.add(g * LANES)) };
        }
        for i in 0..ni {
            // SAFETY: i < ni floats at x.
            let xv = _mm256_set1_ps(unsafe { *x.add(i) });
            for (g, a) in acc.iter_mut().enumerate() {
                // SAFETY: row row0 + g*ni + i belongs to this layer.
                let wv = unsafe { load_row::<D>(w, row0 + g * ni + i) };
                a[0] = _mm256_fmadd_ps(wv[0], xv, a[0]);
                a[1] = _mm256_fmadd_ps(wv[1], xv, a[1]);
            }
        }
        let z = _mm256_setzero_ps();
        for (g, a) in acc.iter().enumerate() {
            // SAFETY: G output blocks, 64-byte aligned.
            unsafe {
                _mm256_store_ps(y.add(g * LANES), _mm256_max_ps(a[0], z));
                _mm256_store_ps(y.add(g * LANES + 8), _mm256_max_ps(a[1], z));
            }
        }
    }
}
