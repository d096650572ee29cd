//! int16 storage: the fixed-point quantisers, the pair layout, the exact integer arithmetic every
//! path shares, and the portable int16 path.
//!
//! What this module **is**: symmetric fixed-point quantisation of hidden-layer weights (zero-point 0,
//! one f32 scale per output channel, `q = round(w / scale)` clamped to ±[`I16_WMAX`],
//! `scale = max |w| / I16_WMAX`) and of each layer's input activations (per call, one scale per layer:
//! `a = round(x · I16_AMAX / max |x|)`), the re-layout of the quantised rows as
//! `[blk][ceil(n_in/2)][16 lanes][2 inputs]` (one 64-byte [`PairBlock`] per output block and input
//! pair: what `vpdpwssd` / `vpmaddwd` consume), and the portable forward pass.
//!
//! ## Exactness
//! A hidden layer's dot products are computed in i32 over chunks of [`I16_CHUNK`] inputs and each
//! chunk's sum is converted to f32 and added in input order; the bounds `|q| ≤ 8191`, `|a| ≤ 16383`
//! make a chunk's sum fit in an i32 with no overflow whatever the weights and inputs
//! (`16 · 8191 · 16383 = 2 147 090 448 < 2³¹`). Integer sums are exact and the f32 steps (activation
//! scale, chunk conversion and sum, the final `acc · (scale · sa) + bias` as one fused multiply-add)
//! happen in the same order on every path, so the portable, AVX2, AVX-512 and AVX-512 VNNI paths
//! return **bit-identical** outputs (tests assert it).
//!
//! Accuracy: ≈ 14-bit weights and 15-bit activations, measured on the real ergoCub ankle-roll model
//! at a few 1e-3 Nm, below f16 storage (see `docs/decisions.md`); `frictl convert` measures it per
//! model and gates on it.
//!
//! What it is **not**: a calibrating quantiser (no clipping search, no activation statistics).

use super::{Block, LANES, Net, Scratch, Store};

/// Largest weight code magnitude (14-bit symmetric: `2¹³ − 1`).
pub const I16_WMAX: i16 = 8191;
/// Largest activation code magnitude (15-bit symmetric: `2¹⁴ − 1`).
pub const I16_AMAX: i16 = 16383;
/// Inputs per i32 chunk (8 input pairs).
pub const I16_CHUNK: usize = 16;

// No chunk sum can overflow an i32, whatever the codes.
const _: () = assert!(
    (I16_CHUNK as i64) * (I16_WMAX as i64) * (I16_AMAX as i64) <= i32::MAX as i64,
    "an int16 chunk sum must fit in i32"
);

/// 64 int16 weights: 16 output lanes × 2 consecutive inputs (`[lane][input % 2]`), 64-byte aligned.
#[derive(Clone, Copy, Debug, PartialEq)]
#[repr(C, align(64))]
pub(crate) struct PairBlock(pub(crate) [i16; 2 * LANES]);

/// The int16 weight store of one network: hidden-layer pair rows; layer `k` starts at row
/// `hidden[k].row0` and has `n_blk · ceil(n_in / 2)` rows (block `b`, pair `p` at [`pair_row`]).
pub(crate) type Int16Store = super::QuantStore<PairBlock>;

/// Number of input pairs of a layer with `n_in` inputs.
pub(crate) fn pairs(n_in: usize) -> usize {
    n_in.div_ceil(2)
}

/// Output blocks interleaved in one row group (what the AVX-512 paths keep in registers).
pub(crate) const GROUP: usize = 8;

/// Pair row of output block `blk`, input pair `p` in a layer of `n_blk` blocks and `np` pairs whose
/// rows start at `row0`: blocks are grouped [`GROUP`] at a time (the last group smaller) and within
/// a group the rows are `[pair][block]`, so a group's weights are one sequential stream.
#[inline]
pub(crate) fn pair_row(row0: usize, n_blk: usize, np: usize, blk: usize, p: usize) -> usize {
    let g0 = blk - blk % GROUP;
    let g = (n_blk - g0).min(GROUP);
    row0 + g0 * np + p * g + (blk - g0)
}

/// The scale of one output channel: `max |w| / 8191`, nudged (by at most a few ulps) to a value for
/// which `(8191 · scale) / 8191 == scale` and `8191 · scale ≥ max |w|` in f32, so that quantising the
/// dequantised weights again gives the same scale and codes (a `.fwt` int16 round trip is exact).
/// 0 for an all-zero channel.
pub fn int16_channel_scale(row: &[f32]) -> f32 {
    super::symmetric_scale(row, f32::from(I16_WMAX))
}

/// The int16 code of `w` at channel scale `scale` (round to nearest, ties away from zero; ±8191).
pub fn int16_code(w: f32, scale: f32) -> i16 {
    super::symmetric_code(w, scale, f32::from(I16_WMAX)) as i16
}

/// Activation scale of a layer input whose largest magnitude is `max_abs`: returns
/// `(1 / step, step)` with `step = max_abs / 16383`, or `(0, 0)` when every input is 0 (or all are
/// below ≈ 5e-35).
#[inline]
pub(crate) fn act_scale(max_abs: f32) -> (f32, f32) {
    let k = f32::from(I16_AMAX);
    let inv = k / max_abs;
    // A maximum so small that its inverse overflows (< 5e-35) quantises every input to 0.
    if max_abs > 0.0 && inv.is_finite() {
        (inv, max_abs / k)
    } else {
        (0.0, 0.0)
    }
}

/// The activation code of `x` at inverse step `inv`: `x · inv` rounded to nearest, ties to even (what
/// `cvtps2dq` does under the default MXCSR), clamped to ±16383.
#[inline]
pub(crate) fn act_code(x: f32, inv: f32) -> i16 {
    let k = f32::from(I16_AMAX);
    (x * inv).round_ties_even().clamp(-k, k) as i16
}

/// One portable int16 inference on the normalised input in `s.xin`.
pub(super) fn forward_portable(net: &Net, s: &mut Scratch) -> f32 {
    let Store::Int16(st) = &net.store else {
        return f32::NAN;
    };
    if !net.fits(s) {
        return f32::NAN;
    }
    let Scratch { xin, a, b, q, .. } = s;
    // The quantised activations (`q` holds at least 2·pairs(max width) i16 values).
    let qa: &mut [i16] = bytemuck_i16(q);
    for (k, p) in net.hidden[..net.n_hidden].iter().enumerate() {
        let (x, y): (&[Block], &mut [Block]) = match k {
            0 => (xin, a),
            k if k % 2 == 1 => (a, b),
            _ => (b, a),
        };
        let np = pairs(p.n_in);
        let n_x = 2 * np;
        let max_abs = x
            .iter()
            .flat_map(|blk| blk.0)
            .take(n_x)
            .fold(0f32, |m, v| m.max(v.abs()));
        let (inv, sa) = act_scale(max_abs);
        for (i, c) in qa[..n_x].iter_mut().enumerate() {
            *c = act_code(x[i / LANES].0[i % LANES], inv);
        }
        for (blk, yb) in y[..p.n_blk].iter_mut().enumerate() {
            let mut acc = [0f32; LANES];
            let mut pair0 = 0;
            while pair0 < np {
                let pair1 = (pair0 + I16_CHUNK / 2).min(np);
                let mut ci = [0i32; LANES];
                for pr in pair0..pair1 {
                    let w = &st.rows[pair_row(p.row0, p.n_blk, np, blk, pr)].0;
                    let (a0, a1) = (i32::from(qa[2 * pr]), i32::from(qa[2 * pr + 1]));
                    for (l, c) in ci.iter_mut().enumerate() {
                        *c += i32::from(w[2 * l]) * a0 + i32::from(w[2 * l + 1]) * a1;
                    }
                }
                for (al, c) in acc.iter_mut().zip(ci) {
                    *al += c as f32;
                }
                pair0 = pair1;
            }
            let sc = &st.scale[p.bias_blk0 + blk].0;
            let bi = &net.bias[p.bias_blk0 + blk].0;
            for (l, yl) in yb.0.iter_mut().enumerate() {
                *yl = acc[l].mul_add(sc[l] * sa, bi[l]).max(0.0);
            }
        }
    }
    let src: &[Block] = match net.n_hidden {
        0 => xin,
        n if n % 2 == 1 => a,
        _ => b,
    };
    let mut acc = [0f32; LANES];
    for (r, xb) in src[..net.out.n_blk].iter().enumerate() {
        for ((al, wl), xl) in acc.iter_mut().zip(st.out[net.out.row0 + r].0).zip(xb.0) {
            *al = wl.mul_add(xl, *al);
        }
    }
    reduce_lanes(acc) + net.out_bias
}

/// The output neuron's horizontal sum in the order every int16 path uses: lanes `i + 8`, then
/// `i + 4`, `i + 2`, `i + 1` added onto lane `i` (what the SIMD paths' halving reductions do).
pub(crate) fn reduce_lanes(mut l: [f32; LANES]) -> f32 {
    let mut half = LANES / 2;
    while half > 0 {
        for i in 0..half {
            l[i] += l[i + half];
        }
        half /= 2;
    }
    l[0]
}

/// The activation byte blocks as i16 values (two bytes per value).
fn bytemuck_i16(q: &mut [super::int8::ByteBlock]) -> &mut [i16] {
    // SAFETY: `ByteBlock` is `repr(C, align(64))` around `[u8; 64]` (no padding, every byte
    // initialised); 64-byte alignment satisfies i16's; the length is exactly the bytes / 2; the
    // returned slice mutably borrows `q` for its whole lifetime.
    unsafe { std::slice::from_raw_parts_mut(q.as_mut_ptr().cast::<i16>(), q.len() * 32) }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn scale_is_a_fixed_point_and_codes_round_trip() {
        let mut seed = 11u32;
        for _ in 0..2000 {
            seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            let m = f32::from_bits(0x3a00_0000 + (seed >> 8));
            let row = [m, -0.3 * m, 0.01 * m, -m * 0.999, 1e-7 * m];
            let s = int16_channel_scale(&row);
            assert!(s > 0.0 && (8191.0 * s) >= m);
            let q: Vec<i16> = row.iter().map(|&w| int16_code(w, s)).collect();
            let back: Vec<f32> = q.iter().map(|&c| f32::from(c) * s).collect();
            let s2 = int16_channel_scale(&back);
            assert_eq!(s2, s, "scale of {row:?}");
            let q2: Vec<i16> = back.iter().map(|&w| int16_code(w, s2)).collect();
            assert_eq!(q2, q);
        }
        assert_eq!(int16_channel_scale(&[0.0, 0.0]), 0.0);
        assert_eq!(int16_code(1.0, 0.0), 0);
    }

    #[test]
    fn activation_codes_stay_in_range_and_round_to_even() {
        for m in [1e-30f32, 1e-3, 0.7, 1.0, 3.3, 1e6, f32::MAX / 2.0] {
            let (inv, step) = act_scale(m);
            for x in [m, -m, 0.5 * m, -0.25 * m, 0.0] {
                let c = act_code(x, inv);
                assert!(c.abs() <= I16_AMAX, "{x} at max {m}: {c}");
                assert!((f32::from(c) * step - x).abs() <= step, "{x} at max {m}");
            }
            assert_eq!(act_code(m, inv), I16_AMAX, "max {m}");
        }
        assert_eq!(act_scale(0.0), (0.0, 0.0));
        assert_eq!(act_code(2.5, 1.0), 2);
        assert_eq!(act_code(-3.5, 1.0), -4);
    }
}
