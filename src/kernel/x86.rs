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

use super::int8::{Int8Store, quads};
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
        Store::Int8(st) => st.rows.as_ptr().cast(),
        Store::Int16(st) => st.rows.as_ptr().cast(),
    }
}

/// AVX-512 VNNI int8 forward pass (u8 activations × int8 weights after the first layer); falls back
/// to the AVX-512 weight-only int8 path if the CPU lacks AVX-512BW or VNNI.
pub(super) fn forward_vnni(net: &Net, s: &mut Scratch) -> f32 {
    if !(std::is_x86_feature_detected!("avx512f")
        && std::is_x86_feature_detected!("avx512bw")
        && std::is_x86_feature_detected!("avx512vnni"))
    {
        return forward_avx512(net, s, dt::INT8);
    }
    let Store::Int8(st) = &net.store else {
        return f32::NAN;
    };
    if !net.fits(s) {
        return f32::NAN;
    }
    // SAFETY: AVX-512F/BW/VNNI are present (checked above); `fits` bounds every quad row, scale, bias,
    // activation and quantised-activation byte the kernel addresses.
    unsafe { avx512_i8::run_vnni(net, st, s) }
}

/// AVX-512 forward pass; falls back to the portable path if the CPU lacks AVX-512F.
pub(super) fn forward_avx512(net: &Net, s: &mut Scratch, code: u8) -> f32 {
    if !std::is_x86_feature_detected!("avx512f") {
        return super::portable::forward(net, s, code);
    }
    if !net.fits(s) {
        return f32::NAN;
    }
    if code == dt::INT8 {
        let Store::Int8(st) = &net.store else {
            return f32::NAN;
        };
        // SAFETY: AVX-512F is present; `fits` bounds every row, scale, bias and activation block.
        return unsafe { avx512_i8::run_decode(net, st, s) };
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
    if code == dt::INT8 {
        let Store::Int8(st) = &net.store else {
            return f32::NAN;
        };
        // SAFETY: AVX2 and FMA are present; `fits` bounds every row, scale, bias and activation block.
        return unsafe { avx2_i8::run(net, st, s) };
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

pub(super) mod avx512 {
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
        // SAFETY: `fits` bounds the output rows and the last activation blocks.
        unsafe { output::<D>(w, &net.out, src, net.out_bias) }
    }

    /// The output neuron: the dot product of rows `o.row0 .. o.row0 + o.n_blk` of store `w` with
    /// the activation blocks at `src`, plus `out_bias` (also the int8 paths' f32 output layer).
    ///
    /// # Safety
    /// Those rows and `o.n_blk` activation blocks at `src` must be valid.
    #[target_feature(enable = "avx512f")]
    #[inline]
    pub(in crate::kernel) unsafe fn output<const D: u8>(
        w: *const u8,
        o: &LayerPlan,
        src: *const f32,
        out_bias: f32,
    ) -> f32 {
        let mut acc = [_mm512_setzero_ps(); 4];
        for r in 0..o.n_blk {
            // SAFETY: caller contract.
            let (wv, xv) = unsafe {
                (
                    load_row::<D>(w, o.row0 + r),
                    _mm512_load_ps(src.add(r * LANES)),
                )
            };
            acc[r % 4] = _mm512_fmadd_ps(wv, xv, acc[r % 4]);
        }
        let sum = _mm512_add_ps(_mm512_add_ps(acc[0], acc[1]), _mm512_add_ps(acc[2], acc[3]));
        _mm512_reduce_add_ps(sum) + out_bias
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

pub(super) mod avx2 {
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
        // SAFETY: `fits` bounds the output rows and the last activation blocks.
        unsafe { output::<D>(w, &net.out, src, net.out_bias) }
    }

    /// The output neuron: the dot product of rows `o.row0 .. o.row0 + o.n_blk` of store `w` with
    /// the activation blocks at `src`, plus `out_bias` (also the int8 path's f32 output layer).
    ///
    /// # Safety
    /// Those rows and `o.n_blk` activation blocks at `src` must be valid.
    #[target_feature(enable = "avx2,fma,f16c")]
    #[inline]
    pub(in crate::kernel) unsafe fn output<const D: u8>(
        w: *const u8,
        o: &LayerPlan,
        src: *const f32,
        out_bias: f32,
    ) -> f32 {
        let mut acc = [_mm256_setzero_ps(); 4];
        for r in 0..o.n_blk {
            // SAFETY: caller contract.
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
        _mm_cvtss_f32(s1) + out_bias
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
                group::<D, MAX_G, 1>(
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
        // Fewer blocks than MAX_G: the inputs are split over S interleaved accumulator sets so that
        // 8 FMA chains stay in flight (a chain waits for the previous FMA's result).
        unsafe {
            match p.n_blk - blk {
                1 => group::<D, 1, 4>(w, r0, ni, x, bb, yy),
                2 => group::<D, 2, 2>(w, r0, ni, x, bb, yy),
                3 => group::<D, 3, 1>(w, r0, ni, x, bb, yy),
                _ => {}
            }
        }
    }

    /// `G` consecutive output blocks; block `g`'s row for input `i` is `row0 + g * ni + i`. Input
    /// `i` goes to accumulator set `i % S` (for `i` below the largest multiple of `S`, the rest to
    /// set 0); the sets are added in order at the end.
    ///
    /// # Safety
    /// As for [`dense`], restricted to these `G` blocks.
    #[target_feature(enable = "avx2,fma,f16c")]
    #[inline]
    unsafe fn group<const D: u8, const G: usize, const S: usize>(
        w: *const u8,
        row0: usize,
        ni: usize,
        x: *const f32,
        bias: *const f32,
        y: *mut f32,
    ) {
        let mut sets = [[[_mm256_setzero_ps(); 2]; G]; S];
        for (g, a) in sets[0].iter_mut().enumerate() {
            // SAFETY: G bias blocks, 64-byte aligned.
            *a = unsafe { load_block(bias.add(g * LANES)) };
        }
        let split = ni - ni % S;
        let mut i = 0;
        while i < split {
            for (k, acc) in sets.iter_mut().enumerate() {
                // SAFETY: i + k < ni floats at x.
                let xv = _mm256_set1_ps(unsafe { *x.add(i + k) });
                for (g, a) in acc.iter_mut().enumerate() {
                    // SAFETY: row row0 + g*ni + i + k belongs to this layer.
                    let wv = unsafe { load_row::<D>(w, row0 + g * ni + i + k) };
                    a[0] = _mm256_fmadd_ps(wv[0], xv, a[0]);
                    a[1] = _mm256_fmadd_ps(wv[1], xv, a[1]);
                }
            }
            i += S;
        }
        for i in split..ni {
            // SAFETY: as above.
            let xv = _mm256_set1_ps(unsafe { *x.add(i) });
            for (g, a) in sets[0].iter_mut().enumerate() {
                // SAFETY: as above.
                let wv = unsafe { load_row::<D>(w, row0 + g * ni + i) };
                a[0] = _mm256_fmadd_ps(wv[0], xv, a[0]);
                a[1] = _mm256_fmadd_ps(wv[1], xv, a[1]);
            }
        }
        let mut acc = sets[0];
        for set in &sets[1..] {
            for (a, b) in acc.iter_mut().zip(set) {
                a[0] = _mm256_add_ps(a[0], b[0]);
                a[1] = _mm256_add_ps(a[1], b[1]);
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

/// int8 on AVX-512: the weight-only decode path (`run_decode`: sign-extend each byte of a quad row
/// with two shifts, convert, FMA with the f32 activation) and the VNNI path (`run_vnni`: the first
/// hidden layer as in `run_decode`; every later hidden layer quantises its input to u8 with a per-call
/// scale `max / 255` and accumulates `vpdpbusd` in i32, then scales by weight scale × activation scale,
/// adds the f32 bias and applies the ReLU). The output layer is an f32 dot product in both.
mod avx512_i8 {
    use super::*;
    use std::arch::x86_64::*;

    /// Output blocks per pass (8 zmm accumulators).
    const MAX_G: usize = 8;

    /// Quad row `r` of the store (64 bytes, 64-byte aligned).
    ///
    /// # Safety
    /// Row `r` must exist.
    #[target_feature(enable = "avx512f")]
    #[inline]
    unsafe fn row(w: *const u8, r: usize) -> __m512i {
        // SAFETY: caller contract; quad rows are 64-byte aligned.
        unsafe { _mm512_load_si512(w.add(r * 64).cast()) }
    }

    /// Weight-only pass (int8 weights decoded to f32, f32 activations).
    ///
    /// # Safety
    /// AVX-512F must be available and `net.fits(s)` must hold for `net.store == Store::Int8(st)`.
    #[target_feature(enable = "avx512f")]
    pub(super) unsafe fn run_decode(net: &Net, st: &Int8Store, s: &mut Scratch) -> f32 {
        let w = st.rows.as_ptr().cast::<u8>();
        let a = s.a.as_mut_ptr().cast::<f32>();
        let b = s.b.as_mut_ptr().cast::<f32>();
        let mut src = s.xin.as_ptr().cast::<f32>();
        for (k, p) in net.hidden[..net.n_hidden].iter().enumerate() {
            let dst = if k % 2 == 0 { a } else { b };
            // SAFETY: `fits` bounds this layer; src and dst are distinct buffers.
            unsafe { dense_decode(w, st, net, p, src, dst) };
            src = dst;
        }
        // SAFETY: as above.
        unsafe { out_dot(net, st, src) }
    }

    /// VNNI pass.
    ///
    /// # Safety
    /// AVX-512F, BW and VNNI must be available and `net.fits(s)` must hold for
    /// `net.store == Store::Int8(st)`.
    #[target_feature(enable = "avx512f,avx512bw,avx512vnni")]
    pub(super) unsafe fn run_vnni(net: &Net, st: &Int8Store, s: &mut Scratch) -> f32 {
        let w = st.rows.as_ptr().cast::<u8>();
        let a = s.a.as_mut_ptr().cast::<f32>();
        let b = s.b.as_mut_ptr().cast::<f32>();
        let qb = s.q.as_mut_ptr().cast::<u8>();
        let mut src = s.xin.as_ptr().cast::<f32>();
        for (k, p) in net.hidden[..net.n_hidden].iter().enumerate() {
            let dst = if k % 2 == 0 { a } else { b };
            // SAFETY: `fits` bounds this layer, its input blocks and the quantised bytes; src, dst and
            // qb are distinct buffers.
            unsafe {
                if k == 0 {
                    dense_decode(w, st, net, p, src, dst);
                } else {
                    let sa = quantise(src, p.n_in.div_ceil(LANES), qb);
                    dense_vnni(w, st, net, p, qb, sa, dst);
                }
            }
            src = dst;
        }
        // SAFETY: as above.
        unsafe { out_dot(net, st, src) }
    }

    /// The f32 output layer.
    ///
    /// # Safety
    /// `out.n_blk` rows of `st.out` from `out.row0` and as many activation blocks at `src`.
    #[target_feature(enable = "avx512f")]
    #[inline]
    unsafe fn out_dot(net: &Net, st: &Int8Store, src: *const f32) -> f32 {
        // SAFETY: caller contract (the f32 output rows of `st.out`).
        unsafe {
            super::avx512::output::<{ dt::F32 }>(
                st.out.as_ptr().cast(),
                &net.out,
                src,
                net.out_bias,
            )
        }
    }

    /// Quantises `n_blk` blocks of non-negative f32 at `x` to u8 at `q` (`round(x · 255 / max)`);
    /// returns the activation scale `max / 255` (0 if every value is 0).
    ///
    /// # Safety
    /// `n_blk` readable blocks at `x` (64-byte aligned), `16 · n_blk` writable bytes at `q`.
    #[target_feature(enable = "avx512f,avx512bw,avx512vnni")]
    #[inline]
    unsafe fn quantise(x: *const f32, n_blk: usize, q: *mut u8) -> f32 {
        let mut m = _mm512_setzero_ps();
        for b in 0..n_blk {
            // SAFETY: caller contract.
            m = _mm512_max_ps(m, unsafe { _mm512_load_ps(x.add(b * LANES)) });
        }
        let m = _mm512_reduce_max_ps(m);
        let (inv, sa) = if m > 0.0 {
            (255.0 / m, m / 255.0)
        } else {
            (0.0, 0.0)
        };
        let inv = _mm512_set1_ps(inv);
        for b in 0..n_blk {
            // SAFETY: caller contract. Values are ≥ 0 (after ReLU); the unsigned saturating narrow
            // clamps a rounding overshoot to 255.
            unsafe {
                let u = _mm512_cvtps_epi32(_mm512_mul_ps(_mm512_load_ps(x.add(b * LANES)), inv));
                _mm_storeu_si128(q.add(b * LANES).cast(), _mm512_cvtusepi32_epi8(u));
            }
        }
        sa
    }

    /// Hidden layer, weight-only: `y = relu(scale ⊙ (Q x) + b)`.
    ///
    /// # Safety
    /// As `run_decode` for layer `p`: its quad rows, scale and bias blocks, `4·ceil(n_in/4)` floats at
    /// `x`, `p.n_blk` blocks at `y`; `x` and `y` distinct.
    #[target_feature(enable = "avx512f")]
    #[inline]
    unsafe fn dense_decode(
        w: *const u8,
        st: &Int8Store,
        net: &Net,
        p: &LayerPlan,
        x: *const f32,
        y: *mut f32,
    ) {
        let nq = quads(p.n_in);
        let sc = st.scale.as_ptr().cast::<f32>();
        let bi = net.bias.as_ptr().cast::<f32>();
        let mut blk = 0;
        while blk < p.n_blk {
            let g = (p.n_blk - blk).min(MAX_G);
            let r0 = p.row0 + blk * nq;
            let off = (p.bias_blk0 + blk) * LANES;
            // SAFETY: blocks blk..blk+g of this layer (caller contract).
            unsafe {
                let (s0, b0, y0) = (sc.add(off), bi.add(off), y.add(blk * LANES));
                match g {
                    8 => group_decode::<8>(w, r0, nq, x, s0, b0, y0),
                    7 => group_decode::<7>(w, r0, nq, x, s0, b0, y0),
                    6 => group_decode::<6>(w, r0, nq, x, s0, b0, y0),
                    5 => group_decode::<5>(w, r0, nq, x, s0, b0, y0),
                    4 => group_decode::<4>(w, r0, nq, x, s0, b0, y0),
                    3 => group_decode::<3>(w, r0, nq, x, s0, b0, y0),
                    2 => group_decode::<2>(w, r0, nq, x, s0, b0, y0),
                    _ => group_decode::<1>(w, r0, nq, x, s0, b0, y0),
                }
            }
            blk += g;
        }
    }

    /// `G` output blocks, weight-only; block `g`'s quad `q` is row `row0 + g·nq + q`.
    ///
    /// # Safety
    /// As for `dense_decode`, restricted to these `G` blocks.
    #[target_feature(enable = "avx512f")]
    #[inline]
    unsafe fn group_decode<const G: usize>(
        w: *const u8,
        row0: usize,
        nq: usize,
        x: *const f32,
        scale: *const f32,
        bias: *const f32,
        y: *mut f32,
    ) {
        let mut acc = [_mm512_setzero_ps(); G];
        for q in 0..nq {
            // SAFETY: 4·nq floats at x.
            let xs = unsafe {
                [
                    _mm512_set1_ps(*x.add(4 * q)),
                    _mm512_set1_ps(*x.add(4 * q + 1)),
                    _mm512_set1_ps(*x.add(4 * q + 2)),
                    _mm512_set1_ps(*x.add(4 * q + 3)),
                ]
            };
            for (g, a) in acc.iter_mut().enumerate() {
                // SAFETY: row row0 + g·nq + q belongs to this layer.
                let v = unsafe { row(w, row0 + g * nq + q) };
                // Byte j of each 32-bit lane is input 4q + j: shift it to the top, sign-extend down.
                let w0 = _mm512_srai_epi32::<24>(_mm512_slli_epi32::<24>(v));
                let w1 = _mm512_srai_epi32::<24>(_mm512_slli_epi32::<16>(v));
                let w2 = _mm512_srai_epi32::<24>(_mm512_slli_epi32::<8>(v));
                let w3 = _mm512_srai_epi32::<24>(v);
                *a = _mm512_fmadd_ps(_mm512_cvtepi32_ps(w0), xs[0], *a);
                *a = _mm512_fmadd_ps(_mm512_cvtepi32_ps(w1), xs[1], *a);
                *a = _mm512_fmadd_ps(_mm512_cvtepi32_ps(w2), xs[2], *a);
                *a = _mm512_fmadd_ps(_mm512_cvtepi32_ps(w3), xs[3], *a);
            }
        }
        let z = _mm512_setzero_ps();
        for (g, a) in acc.iter().enumerate() {
            // SAFETY: G scale, bias and output blocks, 64-byte aligned.
            unsafe {
                let v = _mm512_fmadd_ps(
                    *a,
                    _mm512_load_ps(scale.add(g * LANES)),
                    _mm512_load_ps(bias.add(g * LANES)),
                );
                _mm512_store_ps(y.add(g * LANES), _mm512_max_ps(v, z));
            }
        }
    }

    /// Hidden layer, VNNI: `y = relu((scale · sa) ⊙ (Q u) + b)` with `u` the u8 input at `q`.
    ///
    /// # Safety
    /// As `dense_decode`, with `4·ceil(n_in/4)` readable bytes at `q` instead of floats at `x`.
    #[target_feature(enable = "avx512f,avx512bw,avx512vnni")]
    #[inline]
    unsafe fn dense_vnni(
        w: *const u8,
        st: &Int8Store,
        net: &Net,
        p: &LayerPlan,
        q: *const u8,
        sa: f32,
        y: *mut f32,
    ) {
        let nq = quads(p.n_in);
        let sc = st.scale.as_ptr().cast::<f32>();
        let bi = net.bias.as_ptr().cast::<f32>();
        let sa = _mm512_set1_ps(sa);
        let mut blk = 0;
        while blk < p.n_blk {
            let g = (p.n_blk - blk).min(MAX_G);
            let r0 = p.row0 + blk * nq;
            let off = (p.bias_blk0 + blk) * LANES;
            // SAFETY: blocks blk..blk+g of this layer (caller contract).
            unsafe {
                let (s0, b0, y0) = (sc.add(off), bi.add(off), y.add(blk * LANES));
                match g {
                    8 => group_vnni::<8>(w, r0, nq, q, s0, sa, b0, y0),
                    7 => group_vnni::<7>(w, r0, nq, q, s0, sa, b0, y0),
                    6 => group_vnni::<6>(w, r0, nq, q, s0, sa, b0, y0),
                    5 => group_vnni::<5>(w, r0, nq, q, s0, sa, b0, y0),
                    4 => group_vnni::<4>(w, r0, nq, q, s0, sa, b0, y0),
                    3 => group_vnni::<3>(w, r0, nq, q, s0, sa, b0, y0),
                    2 => group_vnni::<2>(w, r0, nq, q, s0, sa, b0, y0),
                    _ => group_vnni::<1>(w, r0, nq, q, s0, sa, b0, y0),
                }
            }
            blk += g;
        }
    }

    /// `G` output blocks, VNNI.
    ///
    /// # Safety
    /// As for `dense_vnni`, restricted to these `G` blocks.
    #[allow(clippy::too_many_arguments)]
    #[target_feature(enable = "avx512f,avx512bw,avx512vnni")]
    #[inline]
    unsafe fn group_vnni<const G: usize>(
        w: *const u8,
        row0: usize,
        nq: usize,
        q: *const u8,
        scale: *const f32,
        sa: __m512,
        bias: *const f32,
        y: *mut f32,
    ) {
        let mut acc = [_mm512_setzero_si512(); G];
        for qi in 0..nq {
            // SAFETY: 4·nq readable bytes at q.
            let u = _mm512_set1_epi32(unsafe { q.add(4 * qi).cast::<i32>().read_unaligned() });
            for (g, a) in acc.iter_mut().enumerate() {
                // SAFETY: row row0 + g·nq + qi belongs to this layer.
                *a = _mm512_dpbusd_epi32(*a, u, unsafe { row(w, row0 + g * nq + qi) });
            }
        }
        let z = _mm512_setzero_ps();
        for (g, a) in acc.iter().enumerate() {
            // SAFETY: G scale, bias and output blocks, 64-byte aligned.
            unsafe {
                let s = _mm512_mul_ps(_mm512_load_ps(scale.add(g * LANES)), sa);
                let v = _mm512_fmadd_ps(
                    _mm512_cvtepi32_ps(*a),
                    s,
                    _mm512_load_ps(bias.add(g * LANES)),
                );
                _mm512_store_ps(y.add(g * LANES), _mm512_max_ps(v, z));
            }
        }
    }
}

/// int8 on AVX2 + FMA: the weight-only decode path (16 lanes in two ymm, as `avx512_i8::run_decode`).
mod avx2_i8 {
    use super::*;
    use std::arch::x86_64::*;

    /// Output blocks per pass (2 × 2 ymm accumulators; the decode needs registers too).
    const MAX_G: usize = 2;

    /// The whole pass.
    ///
    /// # Safety
    /// AVX2 and FMA must be available and `net.fits(s)` must hold for `net.store == Store::Int8(st)`.
    #[target_feature(enable = "avx2,fma")]
    pub(super) unsafe fn run(net: &Net, st: &Int8Store, s: &mut Scratch) -> f32 {
        let w = st.rows.as_ptr().cast::<u8>();
        let sc = st.scale.as_ptr().cast::<f32>();
        let bi = net.bias.as_ptr().cast::<f32>();
        let a = s.a.as_mut_ptr().cast::<f32>();
        let b = s.b.as_mut_ptr().cast::<f32>();
        let mut src = s.xin.as_ptr().cast::<f32>();
        for (k, p) in net.hidden[..net.n_hidden].iter().enumerate() {
            let dst = if k % 2 == 0 { a } else { b };
            let nq = quads(p.n_in);
            let mut blk = 0;
            while blk < p.n_blk {
                let g = (p.n_blk - blk).min(MAX_G);
                let r0 = p.row0 + blk * nq;
                let off = (p.bias_blk0 + blk) * LANES;
                // SAFETY: `fits` bounds blocks blk..blk+g of this layer; src and dst are distinct.
                unsafe {
                    let (s0, b0, y0) = (sc.add(off), bi.add(off), dst.add(blk * LANES));
                    if g == 2 {
                        group::<2>(w, r0, nq, src, s0, b0, y0);
                    } else {
                        group::<1>(w, r0, nq, src, s0, b0, y0);
                    }
                }
                blk += g;
            }
            src = dst;
        }
        // SAFETY: the f32 output rows and the last activation blocks are in bounds (`fits`).
        unsafe {
            super::avx2::output::<{ dt::F32 }>(st.out.as_ptr().cast(), &net.out, src, net.out_bias)
        }
    }

    /// `G` output blocks of one hidden layer.
    ///
    /// # Safety
    /// As for `avx512_i8::group_decode`.
    #[target_feature(enable = "avx2,fma")]
    #[inline]
    unsafe fn group<const G: usize>(
        w: *const u8,
        row0: usize,
        nq: usize,
        x: *const f32,
        scale: *const f32,
        bias: *const f32,
        y: *mut f32,
    ) {
        let mut acc = [[_mm256_setzero_ps(); 2]; G];
        for q in 0..nq {
            // SAFETY: 4·nq floats at x.
            let xs = unsafe {
                [
                    _mm256_set1_ps(*x.add(4 * q)),
                    _mm256_set1_ps(*x.add(4 * q + 1)),
                    _mm256_set1_ps(*x.add(4 * q + 2)),
                    _mm256_set1_ps(*x.add(4 * q + 3)),
                ]
            };
            for (g, a) in acc.iter_mut().enumerate() {
                for (h, ah) in a.iter_mut().enumerate() {
                    // SAFETY: half h of quad row row0 + g·nq + q (32-byte aligned).
                    let v = unsafe {
                        _mm256_load_si256(w.add((row0 + g * nq + q) * 64 + 32 * h).cast())
                    };
                    let w0 = _mm256_srai_epi32::<24>(_mm256_slli_epi32::<24>(v));
                    let w1 = _mm256_srai_epi32::<24>(_mm256_slli_epi32::<16>(v));
                    let w2 = _mm256_srai_epi32::<24>(_mm256_slli_epi32::<8>(v));
                    let w3 = _mm256_srai_epi32::<24>(v);
                    *ah = _mm256_fmadd_ps(_mm256_cvtepi32_ps(w0), xs[0], *ah);
                    *ah = _mm256_fmadd_ps(_mm256_cvtepi32_ps(w1), xs[1], *ah);
                    *ah = _mm256_fmadd_ps(_mm256_cvtepi32_ps(w2), xs[2], *ah);
                    *ah = _mm256_fmadd_ps(_mm256_cvtepi32_ps(w3), xs[3], *ah);
                }
            }
        }
        let z = _mm256_setzero_ps();
        for (g, a) in acc.iter().enumerate() {
            for (h, ah) in a.iter().enumerate() {
                // SAFETY: G scale, bias and output blocks; halves 32-byte aligned.
                unsafe {
                    let o = g * LANES + 8 * h;
                    let v = _mm256_fmadd_ps(
                        *ah,
                        _mm256_load_ps(scale.add(o)),
                        _mm256_load_ps(bias.add(o)),
                    );
                    _mm256_store_ps(y.add(o), _mm256_max_ps(v, z));
                }
            }
        }
    }
}
