//! int8 storage: the per-output-channel quantiser, the `vpdpbusd` layout and the portable int8 path.
//!
//! What this module **is**: symmetric int8 quantisation of hidden-layer weights (zero-point 0, one f32
//! scale per output channel, `q = round(w / scale)` clamped to ±127, `scale = max |w| / 127`), the
//! re-layout of the quantised rows as `[blk][ceil(n_in/4)][16 lanes][4 inputs]` (one 64-byte
//! [`QuadBlock`] per output block and input quad: what `vpdpbusd` consumes), and the portable
//! "int8 weights × f32 activations" forward pass. The output layer stays f32.
//!
//! What it is **not**: a calibrating quantiser (no clipping search, no per-tensor activation
//! statistics); the activation quantisation of the VNNI path is dynamic, per layer and per call (see
//! `x86.rs`).

use super::{Block, LANES, Net, Scratch, Store};

/// 64 int8 weights: 16 output lanes × 4 consecutive inputs (`[lane][input % 4]`), 64-byte aligned.
#[derive(Clone, Copy, Debug, PartialEq)]
#[repr(C, align(64))]
pub(crate) struct QuadBlock(pub(crate) [i8; 4 * LANES]);

/// 64 bytes of quantised (u8) activations, 64-byte aligned.
#[derive(Clone, Copy, Debug, PartialEq)]
#[repr(C, align(64))]
pub(crate) struct ByteBlock(pub(crate) [u8; 4 * LANES]);

/// The int8 weight store of one network: hidden-layer quad rows; layer `k` starts at row
/// `hidden[k].row0` and has `n_blk · ceil(n_in / 4)` rows (block `b`, quad `q` at
/// `row0 + b · ceil(n_in/4) + q`).
pub(crate) type Int8Store = super::QuantStore<QuadBlock>;

/// Number of input quads of a layer with `n_in` inputs.
pub(crate) fn quads(n_in: usize) -> usize {
    n_in.div_ceil(4)
}

/// The scale of one output channel: `max |w| / 127`, nudged (by at most a few ulps) to a value for
/// which `(127 · scale) / 127 == scale` in f32, so that quantising the dequantised weights again gives
/// the same scale and the same codes (a `.fwt` int8 round trip is exact). 0 for an all-zero channel.
pub fn int8_channel_scale(row: &[f32]) -> f32 {
    super::symmetric_scale(row, 127.0)
}

/// The int8 code of `w` at channel scale `scale` (round to nearest, ties away from zero; ±127).
pub fn int8_code(w: f32, scale: f32) -> i8 {
    super::symmetric_code(w, scale, 127.0) as i8
}

/// One portable int8 inference on the normalised input in `s.xin` ("int8 weights, f32 activations").
pub(super) fn forward_portable(net: &Net, s: &mut Scratch) -> f32 {
    let Store::Int8(st) = &net.store else {
        return f32::NAN;
    };
    if !net.fits(s) {
        return f32::NAN;
    }
    let Scratch { xin, a, b, .. } = s;
    for (k, p) in net.hidden[..net.n_hidden].iter().enumerate() {
        let (x, y): (&[Block], &mut [Block]) = match k {
            0 => (xin, a),
            k if k % 2 == 1 => (a, b),
            _ => (b, a),
        };
        let nq = quads(p.n_in);
        for (blk, yb) in y[..p.n_blk].iter_mut().enumerate() {
            let mut acc = [0f32; LANES];
            for q in 0..nq {
                let w = &st.rows[p.row0 + blk * nq + q].0;
                for j in 0..4 {
                    let i = 4 * q + j;
                    let xi = x[i / LANES].0[i % LANES];
                    for (l, al) in acc.iter_mut().enumerate() {
                        *al += f32::from(w[4 * l + j]) * xi;
                    }
                }
            }
            let sc = &st.scale[p.bias_blk0 + blk].0;
            let bi = &net.bias[p.bias_blk0 + blk].0;
            for (l, yl) in yb.0.iter_mut().enumerate() {
                *yl = (acc[l] * sc[l] + bi[l]).max(0.0);
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
            *al += wl * xl;
        }
    }
    acc.iter().sum::<f32>() + net.out_bias
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn scale_is_a_fixed_point_and_codes_round_trip() {
        let mut seed = 7u32;
        for _ in 0..2000 {
            seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            let m = f32::from_bits(0x3a00_0000 + (seed >> 8));
            let row = [m, -0.3 * m, 0.01 * m, -m * 0.999];
            let s = int8_channel_scale(&row);
            assert!(s > 0.0 && (127.0 * s) >= m);
            let q: Vec<i8> = row.iter().map(|&w| int8_code(w, s)).collect();
            let back: Vec<f32> = q.iter().map(|&c| f32::from(c) * s).collect();
            let s2 = int8_channel_scale(&back);
            assert_eq!(s2, s, "scale of {row:?}");
            let q2: Vec<i8> = back.iter().map(|&w| int8_code(w, s2)).collect();
            assert_eq!(q2, q);
        }
        assert_eq!(int8_channel_scale(&[0.0, 0.0]), 0.0);
        assert_eq!(int8_code(1.0, 0.0), 0);
    }
}
