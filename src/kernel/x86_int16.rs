//! The x86-64 int16 paths: AVX-512 VNNI (`vpdpwssd`), AVX-512BW (`vpmaddwd` + `vpaddd`) and AVX2
//! (`vpmaddwd` on two ymm per 16 lanes). Each computes exactly what `int16::forward_portable`
//! computes (see `int16.rs`, "Exactness"): the same activation codes, the same i32 chunk sums, the same
//! f32 operations in the same order, hence bit-identical outputs.
//!
//! Each hidden layer: quantise the layer input (max |x| → one scale, `cvtps2dq`, clamp, narrow to
//! i16), then for up to `G` output blocks at a time broadcast one input pair (two i16 as one i32) and
//! issue one multiply-accumulate per block; every 8 pairs (16 inputs) the i32 sums are converted and
//! added to f32 accumulators; finally `acc · (scale · sa) + bias` (one FMA) and the ReLU. The output
//! layer is the f32 dot product the other paths use.
//!
//! `unsafe` is confined here as in `x86.rs`: raw-pointer loads and stores whose bounds `Net::fits`
//! checks once per call, and calls into `#[target_feature]` functions made after run-time detection.

use super::int16::{GROUP, I16_AMAX, I16_CHUNK, Int16Store, act_scale, pairs};
use super::{LANES, Net, Scratch, Store};

/// Pairs per i32 chunk.
const CHUNK_PAIRS: usize = I16_CHUNK / 2;

/// AVX-512 VNNI int16 pass; the AVX-512BW pass if the CPU lacks VNNI.
pub(super) fn forward_vnni(net: &Net, s: &mut Scratch) -> f32 {
    if !(std::is_x86_feature_detected!("avx512f")
        && std::is_x86_feature_detected!("avx512bw")
        && std::is_x86_feature_detected!("avx512vnni"))
    {
        return forward_avx512(net, s);
    }
    let Store::Int16(st) = &net.store else {
        return f32::NAN;
    };
    if !net.fits(s) {
        return f32::NAN;
    }
    // SAFETY: AVX-512F/BW/VNNI are present (checked above); `fits` bounds every pair row, scale,
    // bias, activation block and quantised activation the kernel addresses.
    unsafe { vnni::run(net, st, s) }
}

/// AVX-512BW int16 pass; the AVX2 pass if the CPU lacks AVX-512BW.
pub(super) fn forward_avx512(net: &Net, s: &mut Scratch) -> f32 {
    if !(std::is_x86_feature_detected!("avx512f") && std::is_x86_feature_detected!("avx512bw")) {
        return forward_avx2(net, s);
    }
    let Store::Int16(st) = &net.store else {
        return f32::NAN;
    };
    if !net.fits(s) {
        return f32::NAN;
    }
    // SAFETY: AVX-512F/BW are present; `fits` bounds every address, as above.
    unsafe { madd512::run(net, st, s) }
}

/// AVX2 + FMA int16 pass; the portable pass if the CPU lacks them.
pub(super) fn forward_avx2(net: &Net, s: &mut Scratch) -> f32 {
    if !(std::is_x86_feature_detected!("avx2") && std::is_x86_feature_detected!("fma")) {
        return super::int16::forward_portable(net, s);
    }
    let Store::Int16(st) = &net.store else {
        return f32::NAN;
    };
    if !net.fits(s) {
        return f32::NAN;
    }
    // SAFETY: AVX2 and FMA are present; `fits` bounds every address, as above.
    unsafe { avx2::run(net, st, s) }
}

/// Lanes `i + 4`, `i + 2`, `i + 1` added onto lane `i` of 8 (the tail of `int16::reduce_lanes`).
#[target_feature(enable = "avx2")]
#[inline]
fn reduce8(v: std::arch::x86_64::__m256) -> f32 {
    use std::arch::x86_64::*;
    let h4 = _mm_add_ps(_mm256_castps256_ps128(v), _mm256_extractf128_ps::<1>(v));
    let h2 = _mm_add_ps(h4, _mm_movehl_ps(h4, h4));
    let h1 = _mm_add_ss(h2, _mm_shuffle_ps::<0b01>(h2, h2));
    _mm_cvtss_f32(h1)
}

/// The two AVX-512 int16 paths differ only in the multiply-accumulate instruction; this writes
/// both from one body (`$feat`: the target features, `$dot`: `acc + Σ pairs(u · w)` in i32).
macro_rules! avx512_int16 {
    ($name:ident, $feat:literal, $what:literal, |$acc:ident, $u:ident, $w:ident| $dot:expr) => {
        #[doc = $what]
        mod $name {
            use super::*;
            use std::arch::x86_64::*;

            /// Output blocks per pass (8 i32 + 8 f32 zmm accumulators): one row group.
            const MAX_G: usize = GROUP;

            /// `acc + Σ pairs(u · w)` in i32 lanes.
            #[target_feature(enable = $feat)]
            #[inline]
            fn dot($acc: __m512i, $u: __m512i, $w: __m512i) -> __m512i {
                $dot
            }

            /// The whole pass on the normalised input in `s.xin`.
            ///
            /// # Safety
            /// The target features must be available and `net.fits(s)` must hold for
            /// `net.store == Store::Int16(st)`.
            #[target_feature(enable = $feat)]
            pub(super) unsafe fn run(net: &Net, st: &Int16Store, s: &mut Scratch) -> f32 {
                let w = st.rows.as_ptr().cast::<u8>();
                let sc = st.scale.as_ptr().cast::<f32>();
                let bi = net.bias.as_ptr().cast::<f32>();
                let a = s.a.as_mut_ptr().cast::<f32>();
                let b = s.b.as_mut_ptr().cast::<f32>();
                let q = s.q.as_mut_ptr().cast::<i16>();
                let mut src = s.xin.as_ptr().cast::<f32>();
                for (k, p) in net.hidden[..net.n_hidden].iter().enumerate() {
                    let dst = if k % 2 == 0 { a } else { b };
                    let np = pairs(p.n_in);
                    // SAFETY: `fits` bounds this layer's input blocks (whole blocks cover the
                    // 2·np inputs), its quantised activations, pair rows, scales, biases and output
                    // blocks; src, dst and q are distinct buffers.
                    unsafe {
                        let sa = _mm512_set1_ps(quantise(src, (2 * np).div_ceil(LANES), q));
                        let mut blk = 0;
                        while blk < p.n_blk {
                            let g = (p.n_blk - blk).min(MAX_G);
                            let r0 = p.row0 + blk * np;
                            let off = (p.bias_blk0 + blk) * LANES;
                            let (s0, b0, y0) = (sc.add(off), bi.add(off), dst.add(blk * LANES));
                            match g {
                                8 => group::<8>(w, r0, np, q, s0, sa, b0, y0),
                                7 => group::<7>(w, r0, np, q, s0, sa, b0, y0),
                                6 => group::<6>(w, r0, np, q, s0, sa, b0, y0),
                                5 => group::<5>(w, r0, np, q, s0, sa, b0, y0),
                                4 => group::<4>(w, r0, np, q, s0, sa, b0, y0),
                                3 => group::<3>(w, r0, np, q, s0, sa, b0, y0),
                                2 => group::<2>(w, r0, np, q, s0, sa, b0, y0),
                                _ => group::<1>(w, r0, np, q, s0, sa, b0, y0),
                            }
                            blk += g;
                        }
                    }
                    src = dst;
                }
                // SAFETY: the f32 output rows and the last activation blocks are in bounds (`fits`).
                unsafe { output(st, net, src) }
            }

            /// The f32 output neuron: one FMA chain over the blocks, then the halving reduction of
            /// `int16::reduce_lanes` (the same order on every int16 path).
            ///
            /// # Safety
            /// `net.out.n_blk` rows of `st.out` from `net.out.row0` and as many blocks at `src`.
            #[target_feature(enable = $feat)]
            #[inline]
            unsafe fn output(st: &Int16Store, net: &Net, src: *const f32) -> f32 {
                let o = &net.out;
                let w = st.out.as_ptr().cast::<f32>();
                let mut acc = _mm512_setzero_ps();
                for r in 0..o.n_blk {
                    // SAFETY: caller contract.
                    unsafe {
                        acc = _mm512_fmadd_ps(
                            _mm512_load_ps(w.add((o.row0 + r) * LANES)),
                            _mm512_load_ps(src.add(r * LANES)),
                            acc,
                        );
                    }
                }
                let h8 = _mm256_add_ps(
                    _mm512_castps512_ps256(acc),
                    _mm256_castpd_ps(_mm512_extractf64x4_pd::<1>(_mm512_castps_pd(acc))),
                );
                reduce8(h8) + net.out_bias
            }

            /// Quantises `n_blk` blocks of f32 at `x` to i16 codes at `q`
            /// (`round(x · 16383 / max |x|)`, ties to even, clamped to ±16383); returns the
            /// activation step `max |x| / 16383` (0 if every value is 0).
            ///
            /// # Safety
            /// `n_blk` readable blocks at `x` (64-byte aligned), `16 · n_blk` writable i16 at `q`.
            #[target_feature(enable = $feat)]
            #[inline]
            unsafe fn quantise(x: *const f32, n_blk: usize, q: *mut i16) -> f32 {
                let mut m = _mm512_setzero_ps();
                for b in 0..n_blk {
                    // SAFETY: caller contract.
                    m = _mm512_max_ps(
                        m,
                        _mm512_abs_ps(unsafe { _mm512_load_ps(x.add(b * LANES)) }),
                    );
                }
                let (inv, step) = act_scale(_mm512_reduce_max_ps(m));
                let inv = _mm512_set1_ps(inv);
                let (lo, hi) = (
                    _mm512_set1_epi32(-i32::from(I16_AMAX)),
                    _mm512_set1_epi32(i32::from(I16_AMAX)),
                );
                for b in 0..n_blk {
                    // SAFETY: caller contract. `cvtps2dq` rounds to nearest even (default MXCSR).
                    unsafe {
                        let c = _mm512_cvtps_epi32(_mm512_mul_ps(
                            _mm512_load_ps(x.add(b * LANES)),
                            inv,
                        ));
                        let c = _mm512_min_epi32(_mm512_max_epi32(c, lo), hi);
                        _mm256_storeu_si256(q.add(b * LANES).cast(), _mm512_cvtepi32_epi16(c));
                    }
                }
                step
            }

            /// `G` output blocks: `y = relu(Σ_chunks f32(Σ_chunk w·a) · (scale · sa) + b)`.
            ///
            /// # Safety
            /// Pair rows `row0 + p·G + g` (`g < G`, `p < np`: one row group), `2·np` i16 at `q`,
            /// `G` blocks at `scale`, `bias` and `y`.
            #[allow(clippy::too_many_arguments)]
            #[target_feature(enable = $feat)]
            #[inline]
            unsafe fn group<const G: usize>(
                w: *const u8,
                row0: usize,
                np: usize,
                q: *const i16,
                scale: *const f32,
                sa: __m512,
                bias: *const f32,
                y: *mut f32,
            ) {
                let mut accf = [_mm512_setzero_ps(); G];
                let mut p0 = 0;
                while p0 < np {
                    let p1 = (p0 + CHUNK_PAIRS).min(np);
                    let mut acci = [_mm512_setzero_si512(); G];
                    for p in p0..p1 {
                        // SAFETY: 2·np i16 at q; pair rows of this layer (64-byte aligned).
                        unsafe {
                            let u = _mm512_set1_epi32(q.add(2 * p).cast::<i32>().read_unaligned());
                            for (g, ai) in acci.iter_mut().enumerate() {
                                let wv = _mm512_load_si512(w.add((row0 + p * G + g) * 64).cast());
                                *ai = dot(*ai, u, wv);
                            }
                        }
                    }
                    for (af, ai) in accf.iter_mut().zip(acci) {
                        *af = _mm512_add_ps(*af, _mm512_cvtepi32_ps(ai));
                    }
                    p0 = p1;
                }
                let z = _mm512_setzero_ps();
                for (g, af) in accf.iter().enumerate() {
                    // SAFETY: G scale, bias and output blocks, 64-byte aligned.
                    unsafe {
                        let s = _mm512_mul_ps(_mm512_load_ps(scale.add(g * LANES)), sa);
                        let v = _mm512_fmadd_ps(*af, s, _mm512_load_ps(bias.add(g * LANES)));
                        _mm512_store_ps(y.add(g * LANES), _mm512_max_ps(v, z));
                    }
                }
            }
        }
    };
}

avx512_int16!(
    vnni,
    "avx512f,avx512bw,avx512vnni",
    "int16 on AVX-512 VNNI: one `vpdpwssd` per output block and input pair.",
    |acc, u, w| _mm512_dpwssd_epi32(acc, u, w)
);
avx512_int16!(
    madd512,
    "avx512f,avx512bw",
    "int16 on AVX-512BW: `vpmaddwd` + `vpaddd` per output block and input pair.",
    |acc, u, w| _mm512_add_epi32(acc, _mm512_madd_epi16(u, w))
);

/// int16 on AVX2 + FMA: 16 lanes in two ymm, `vpmaddwd` + `vpaddd`.
mod avx2 {
    use super::*;
    use std::arch::x86_64::*;

    /// Output blocks per pass (2 × 2 i32 + 2 × 2 f32 ymm accumulators).
    const MAX_G: usize = 2;

    /// The whole pass.
    ///
    /// # Safety
    /// AVX2 and FMA must be available and `net.fits(s)` must hold for `net.store == Store::Int16(st)`.
    #[target_feature(enable = "avx2,fma")]
    pub(super) unsafe fn run(net: &Net, st: &Int16Store, s: &mut Scratch) -> f32 {
        let w = st.rows.as_ptr().cast::<u8>();
        let sc = st.scale.as_ptr().cast::<f32>();
        let bi = net.bias.as_ptr().cast::<f32>();
        let a = s.a.as_mut_ptr().cast::<f32>();
        let b = s.b.as_mut_ptr().cast::<f32>();
        let q = s.q.as_mut_ptr().cast::<i16>();
        let mut src = s.xin.as_ptr().cast::<f32>();
        for (k, p) in net.hidden[..net.n_hidden].iter().enumerate() {
            let dst = if k % 2 == 0 { a } else { b };
            let np = pairs(p.n_in);
            // SAFETY: as in the AVX-512 passes (`fits`); src, dst and q are distinct buffers.
            unsafe {
                let sa = _mm256_set1_ps(quantise(src, (2 * np).div_ceil(LANES), q));
                let mut blk = 0;
                while blk < p.n_blk {
                    // The row group holding `blk` and the block's place in it.
                    let g0 = blk - blk % GROUP;
                    let stride = (p.n_blk - g0).min(GROUP);
                    let g = (g0 + stride - blk).min(MAX_G);
                    let r0 = p.row0 + g0 * np + (blk - g0);
                    let off = (p.bias_blk0 + blk) * LANES;
                    let (s0, b0, y0) = (sc.add(off), bi.add(off), dst.add(blk * LANES));
                    if g == 2 {
                        group::<2>(w, r0, stride, np, q, s0, sa, b0, y0);
                    } else {
                        group::<1>(w, r0, stride, np, q, s0, sa, b0, y0);
                    }
                    blk += g;
                }
            }
            src = dst;
        }
        // SAFETY: the f32 output rows and the last activation blocks are in bounds (`fits`).
        unsafe { output(st, net, src) }
    }

    /// As the AVX-512 `output`: lanes 0–7 and 8–15 in two FMA chains, added, then `reduce8`.
    ///
    /// # Safety
    /// As for the AVX-512 `output`.
    #[target_feature(enable = "avx2,fma")]
    #[inline]
    unsafe fn output(st: &Int16Store, net: &Net, src: *const f32) -> f32 {
        let o = &net.out;
        let w = st.out.as_ptr().cast::<f32>();
        let (mut lo, mut hi) = (_mm256_setzero_ps(), _mm256_setzero_ps());
        for r in 0..o.n_blk {
            // SAFETY: caller contract (32-byte aligned halves).
            unsafe {
                let (wr, xr) = (w.add((o.row0 + r) * LANES), src.add(r * LANES));
                lo = _mm256_fmadd_ps(_mm256_load_ps(wr), _mm256_load_ps(xr), lo);
                hi = _mm256_fmadd_ps(_mm256_load_ps(wr.add(8)), _mm256_load_ps(xr.add(8)), hi);
            }
        }
        reduce8(_mm256_add_ps(lo, hi)) + net.out_bias
    }

    /// As the AVX-512 `quantise`, 8 lanes at a time.
    ///
    /// # Safety
    /// `n_blk` readable blocks at `x` (32-byte aligned halves), `16 · n_blk` writable i16 at `q`.
    #[target_feature(enable = "avx2,fma")]
    #[inline]
    unsafe fn quantise(x: *const f32, n_blk: usize, q: *mut i16) -> f32 {
        let sign = _mm256_set1_ps(-0.0);
        let mut m = _mm256_setzero_ps();
        for h in 0..2 * n_blk {
            // SAFETY: caller contract.
            m = _mm256_max_ps(
                m,
                _mm256_andnot_ps(sign, unsafe { _mm256_load_ps(x.add(8 * h)) }),
            );
        }
        let mut lanes = [0f32; 8];
        // SAFETY: 8 writable floats.
        unsafe { _mm256_storeu_ps(lanes.as_mut_ptr(), m) };
        let (inv, step) = act_scale(lanes.iter().fold(0f32, |a, &v| a.max(v)));
        let inv = _mm256_set1_ps(inv);
        let (lo, hi) = (
            _mm256_set1_epi32(-i32::from(I16_AMAX)),
            _mm256_set1_epi32(i32::from(I16_AMAX)),
        );
        for b in 0..n_blk {
            // SAFETY: caller contract. `cvtps2dq` rounds to nearest even (default MXCSR); the
            // values are within ±16383 so the saturating pack is exact; `permute4x64` undoes the
            // pack's 128-bit interleave.
            unsafe {
                let c0 = _mm256_cvtps_epi32(_mm256_mul_ps(_mm256_load_ps(x.add(b * LANES)), inv));
                let c1 =
                    _mm256_cvtps_epi32(_mm256_mul_ps(_mm256_load_ps(x.add(b * LANES + 8)), inv));
                let c0 = _mm256_min_epi32(_mm256_max_epi32(c0, lo), hi);
                let c1 = _mm256_min_epi32(_mm256_max_epi32(c1, lo), hi);
                let packed = _mm256_permute4x64_epi64::<0b11_01_10_00>(_mm256_packs_epi32(c0, c1));
                _mm256_storeu_si256(q.add(b * LANES).cast(), packed);
            }
        }
        step
    }

    /// `G` output blocks of a row group whose rows for pair `p` are `row0 + p·stride + g`, as the
    /// AVX-512 `group`.
    ///
    /// # Safety
    /// As for the AVX-512 `group`, with those rows.
    #[allow(clippy::too_many_arguments)]
    #[target_feature(enable = "avx2,fma")]
    #[inline]
    unsafe fn group<const G: usize>(
        w: *const u8,
        row0: usize,
        stride: usize,
        np: usize,
        q: *const i16,
        scale: *const f32,
        sa: __m256,
        bias: *const f32,
        y: *mut f32,
    ) {
        let mut accf = [[_mm256_setzero_ps(); 2]; G];
        let mut p0 = 0;
        while p0 < np {
            let p1 = (p0 + CHUNK_PAIRS).min(np);
            let mut acci = [[_mm256_setzero_si256(); 2]; G];
            for p in p0..p1 {
                // SAFETY: 2·np i16 at q; pair rows of this layer (halves 32-byte aligned).
                unsafe {
                    let u = _mm256_set1_epi32(q.add(2 * p).cast::<i32>().read_unaligned());
                    for (g, ai) in acci.iter_mut().enumerate() {
                        for (h, aih) in ai.iter_mut().enumerate() {
                            let wv = _mm256_load_si256(
                                w.add((row0 + p * stride + g) * 64 + 32 * h).cast(),
                            );
                            *aih = _mm256_add_epi32(*aih, _mm256_madd_epi16(u, wv));
                        }
                    }
                }
            }
            for (af, ai) in accf.iter_mut().zip(acci) {
                for (afh, aih) in af.iter_mut().zip(ai) {
                    *afh = _mm256_add_ps(*afh, _mm256_cvtepi32_ps(aih));
                }
            }
            p0 = p1;
        }
        let z = _mm256_setzero_ps();
        for (g, af) in accf.iter().enumerate() {
            for (h, afh) in af.iter().enumerate() {
                // SAFETY: G scale, bias and output blocks; halves 32-byte aligned.
                unsafe {
                    let o = g * LANES + 8 * h;
                    let s = _mm256_mul_ps(_mm256_load_ps(scale.add(o)), sa);
                    let v = _mm256_fmadd_ps(*afh, s, _mm256_load_ps(bias.add(o)));
                    _mm256_store_ps(y.add(o), _mm256_max_ps(v, z));
                }
            }
        }
    }
}
