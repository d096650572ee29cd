//! The portable path: plain safe Rust on [`Block`]s, which LLVM auto-vectorises for whatever the build
//! targets (ymm/FMA on the x86-64-v3 baseline, xmm on plain x86-64, NEON elsewhere).
//!
//! It is the reference implementation of the blocked layout and the fallback on CPUs without the
//! intrinsics paths; it is not tuned beyond the register blocking.

use super::{Block, LANES, LayerPlan, Net, Scratch, Store, dt};

/// `a * b + c`, fused only when the build enables FMA (otherwise `mul_add` would be a libm call).
#[inline(always)]
fn fmadd(a: f32, b: f32, c: f32) -> f32 {
    #[cfg(target_feature = "fma")]
    {
        a.mul_add(b, c)
    }
    #[cfg(not(target_feature = "fma"))]
    {
        a * b + c
    }
}

/// Output blocks accumulated per pass (4 × 16 f32 = 8 ymm accumulators).
const MAX_G: usize = 4;

/// One inference on the already-normalised input in `s.xin`.
pub(super) fn forward(net: &Net, s: &mut Scratch, code: u8) -> f32 {
    if !net.fits(s) {
        return f32::NAN;
    }
    match (&net.store, code) {
        (Store::F32(v), _) => run(net, s, |r| v[r].0),
        (Store::Half(v), dt::F16) => run(net, s, |r| {
            let bits = &v[r / 2].0[(r % 2) * LANES..];
            std::array::from_fn(|l| half::f16::from_bits(bits[l]).to_f32())
        }),
        (Store::Half(v), _) => run(net, s, |r| {
            let bits = &v[r / 2].0[(r % 2) * LANES..];
            std::array::from_fn(|l| f32::from_bits(u32::from(bits[l]) << 16))
        }),
        (Store::Int8(_), _) => super::int8::forward_portable(net, s),
        (Store::Int16(_), _) => super::int16::forward_portable(net, s),
    }
}

#[inline(always)]
fn run<R: Fn(usize) -> [f32; LANES]>(net: &Net, s: &mut Scratch, row: R) -> f32 {
    let Scratch { xin, a, b, .. } = s;
    for (k, p) in net.hidden[..net.n_hidden].iter().enumerate() {
        let bias = &net.bias[p.bias_blk0..p.bias_blk0 + p.n_blk];
        if k == 0 {
            dense(&row, p, bias, xin, a);
        } else if k % 2 == 1 {
            dense(&row, p, bias, a, b);
        } else {
            dense(&row, p, bias, b, a);
        }
    }
    let src: &[Block] = match net.n_hidden {
        0 => xin,
        n if n % 2 == 1 => a,
        _ => b,
    };
    let mut acc = [0f32; LANES];
    for (r, xb) in src[..net.out.n_blk].iter().enumerate() {
        let w = row(net.out.row0 + r);
        for ((al, wl), xl) in acc.iter_mut().zip(w).zip(xb.0) {
            *al = fmadd(wl, xl, *al);
        }
    }
    // Pairwise horizontal sum.
    let mut width = LANES / 2;
    while width > 0 {
        for l in 0..width {
            acc[l] += acc[l + width];
        }
        width /= 2;
    }
    acc[0] + net.out_bias
}

/// One hidden layer: `y = relu(W x + b)` over all output blocks.
#[inline(always)]
fn dense<R: Fn(usize) -> [f32; LANES]>(
    row: &R,
    p: &LayerPlan,
    bias: &[Block],
    x: &[Block],
    y: &mut [Block],
) {
    let mut blk = 0;
    while blk + MAX_G <= p.n_blk {
        group::<R, MAX_G>(row, p, blk, bias, x, y);
        blk += MAX_G;
    }
    match p.n_blk - blk {
        1 => group::<R, 1>(row, p, blk, bias, x, y),
        2 => group::<R, 2>(row, p, blk, bias, x, y),
        3 => group::<R, 3>(row, p, blk, bias, x, y),
        _ => {}
    }
}

/// Output blocks `blk0 .. blk0 + G` of one hidden layer, accumulators in registers, fused bias + ReLU.
#[inline(always)]
fn group<R: Fn(usize) -> [f32; LANES], const G: usize>(
    row: &R,
    p: &LayerPlan,
    blk0: usize,
    bias: &[Block],
    x: &[Block],
    y: &mut [Block],
) {
    let mut acc = [[0f32; LANES]; G];
    for (g, a) in acc.iter_mut().enumerate() {
        *a = bias[blk0 + g].0;
    }
    for i in 0..p.n_in {
        let xi = x[i / LANES].0[i % LANES];
        for (g, a) in acc.iter_mut().enumerate() {
            let w = row(p.row0 + (blk0 + g) * p.n_in + i);
            for (al, wl) in a.iter_mut().zip(w) {
                *al = fmadd(wl, xi, *al);
            }
        }
    }
    for (g, a) in acc.iter().enumerate() {
        for (yl, al) in y[blk0 + g].0.iter_mut().zip(a) {
            *yl = al.max(0.0);
        }
    }
}
