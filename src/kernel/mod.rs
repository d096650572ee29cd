//! Allocation-free single-sample MLP inference with runtime CPU dispatch.
//!
//! What this module **is**: the real-time inference kernel for the friction networks described by
//! [`MlpWeights`] (dense + ReLU hidden layers, at most [`limits::MAX_HIDDEN_LAYERS`] of them, widths up to
//! [`limits::MAX_WIDTH`], one linear output). [`Mlp::new`] re-lays the weights out once (this allocates);
//! afterwards [`Mlp::forward`] performs no allocation, no locking and no system call.
//!
//! What it is **not**: a general tensor library, a batch engine or a trainer. It does not parse files
//! (see [`crate::weights`]) and it never runs several samples at once.
//!
//! ## Layout
//! Each hidden layer is stored *blocked* as `[ceil(out/16)][in][16]`: output rows are grouped 16 at a time
//! and, for every input `i`, the 16 weights of a group are contiguous. The kernel broadcasts `x[i]` and
//! performs one 16-lane FMA per output group, so it vectorises across outputs (no horizontal reductions)
//! and streams the weights linearly. Outputs are zero-padded to a multiple of 16 (padding weights and
//! biases are 0, so padded activations are exactly 0 after ReLU). The output layer (one neuron) is stored
//! as its weight row zero-padded to a multiple of 16 and evaluated as a 16-lane dot product followed by a
//! horizontal sum. All buffers are 64-byte aligned ([`Block`]-sized chunks).
//!
//! [`StorageDtype::Int8`] lays the hidden layers out as `[ceil(out/16)][ceil(in/4)][16][4]` int8: one
//! 64-byte row holds 4 consecutive inputs of each of 16 outputs (what `vpdpbusd` consumes), with one
//! f32 scale per output channel (indexed like the biases); the output layer stays f32 rows.
//! [`StorageDtype::Int16`] lays them out as 64-byte rows of 16 outputs × 2 consecutive inputs (int16,
//! what `vpdpwssd`/`vpmaddwd` consume), grouped 8 output blocks at a time with a group's rows ordered
//! `[input pair][block]` so a group streams sequentially (`int16.rs`). Every weight byte of a net
//! lives in its `Store` (`Net::weight_spans` lists the byte ranges).
//!
//! The input normalisation `(x − mean) / scale` is applied first, in f32, exactly as written (not folded
//! into the first layer), so reduced-precision storage rounds the *same* weights the trainer produced.
//!
//! ## Precision
//! Accumulation is f32 (i32 for the VNNI dot products) with f32 biases and normalisation. Weights are
//! stored as f32, IEEE f16, bf16 or int8 ([`StorageDtype`]): f16/bf16 rounded to nearest-even once at
//! load and decoded inside the kernel (`vcvtph2ps` for f16, a 16-bit left shift for bf16); int8
//! quantised per output channel ([`int8_channel_scale`], [`int8_code`]) and either decoded to f32
//! (sign-extending shifts, then FMA with f32 activations: "weight-only") or, on
//! [`KernelPath::Avx512Vnni`], multiplied with u8 activations: every hidden layer after the first
//! quantises its input (≥ 0 after the ReLU) per call to `round(x · 255 / max x)`, accumulates
//! `vpdpbusd` in i32 and rescales by weight scale × `max x / 255` (the first layer, whose inputs are
//! signed, stays weight-only). [`StorageDtype::Int16`] is fixed point on every path: 14-bit weight
//! codes ([`int16_channel_scale`], [`int16_code`]) times 15-bit activation codes quantised per layer
//! and call, summed exactly in i32 over chunks of [`I16_CHUNK`] inputs, then in f32 in a fixed order,
//! so every path returns the same bits. [`storage_rounded`] gives the exact weights a reduced-precision kernel
//! computes with (for int8 the dequantised weights; the VNNI path's activation rounding comes on top),
//! for validation against the f32 model; `frictl convert` gates a conversion on the measured error.
//!
//! Not here: a bf16 dot-product path (`vdpbf16ps`, AVX512-BF16) and an AMX path. bf16 weights are
//! decoded to f32 on every path. AMX is absent on the development CPU (AMD Zen 4), so no AMX code
//! exists (none could be tested).
//!
//! ## Paths
//! [`KernelPath::Avx512Vnni`] (AVX-512F/BW/VNNI: int8 as above, int16 with `vpdpwssd`, every other
//! dtype exactly as `Avx512`; int16 on `Avx512` uses `vpmaddwd` (AVX-512BW), on `Avx2Fma` `vpmaddwd` on ymm), [`KernelPath::Avx512`] (AVX-512F intrinsics), [`KernelPath::Avx2Fma`] (AVX2 + FMA + F16C intrinsics)
//! and [`KernelPath::Portable`] (plain Rust that the compiler auto-vectorises; correct on any CPU, uses
//! FMA only when the build enables it). [`Mlp::new`] picks the fastest path the running CPU supports;
//! [`Mlp::with_path`] forces one (tests compare all of them).

use crate::mlp::{Activation, MlpShapeError, MlpWeights, StorageDtype, limits};
use thiserror::Error;

mod int16;
mod int8;
mod portable;
mod prefetch;
#[cfg(target_arch = "x86_64")]
mod x86;
#[cfg(target_arch = "x86_64")]
mod x86_int16;

use int8::{ByteBlock, Int8Store, QuadBlock};
pub use int8::{int8_channel_scale, int8_code};
pub use int16::{I16_AMAX, I16_CHUNK, I16_WMAX, int16_channel_scale, int16_code};
use int16::{Int16Store, PairBlock};

/// Lanes per block: outputs are processed 16 at a time (one zmm, or two ymm).
pub const LANES: usize = 16;

/// 16 f32 values, 64-byte aligned (one cache line, one zmm register).
#[derive(Clone, Copy, Debug, PartialEq)]
#[repr(C, align(64))]
pub(crate) struct Block(pub(crate) [f32; LANES]);

/// 32 16-bit values (two rows of 16 f16/bf16 weights), 64-byte aligned.
#[derive(Clone, Copy, Debug, PartialEq)]
#[repr(C, align(64))]
pub(crate) struct HalfBlock(pub(crate) [u16; 2 * LANES]);

const ZERO_BLOCK: Block = Block([0.0; LANES]);

/// Dtype codes used as const generic parameters of the kernels.
pub(crate) mod dt {
    /// f32 rows (64 bytes).
    pub const F32: u8 = 0;
    /// IEEE binary16 rows (32 bytes).
    pub const F16: u8 = 1;
    /// bfloat16 rows (32 bytes).
    pub const BF16: u8 = 2;
    /// int8 quad rows (64 bytes = 16 lanes × 4 inputs), f32 output layer.
    pub const INT8: u8 = 3;
    /// int16 pair rows (64 bytes = 16 lanes × 2 inputs), f32 output layer.
    pub const INT16: u8 = 4;
}

/// Which implementation [`Mlp::forward`] runs.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum KernelPath {
    /// AVX-512F + BW + VNNI (x86-64 only, detected at run time): for [`StorageDtype::Int8`] the hidden
    /// layers after the first multiply int8 weights by dynamically quantised u8 activations with
    /// `vpdpbusd` (i32 accumulation); for [`StorageDtype::Int16`] `vpdpwssd` (the same bits as every
    /// other path); every other dtype runs exactly the [`KernelPath::Avx512`] code.
    Avx512Vnni,
    /// AVX-512F intrinsics (x86-64 only, detected at run time).
    Avx512,
    /// AVX2 + FMA + F16C intrinsics (x86-64 only, detected at run time).
    Avx2Fma,
    /// Plain Rust, auto-vectorised for whatever the build targets; always available.
    Portable,
}

impl KernelPath {
    /// All paths, fastest first.
    pub const ALL: [KernelPath; 4] = [
        KernelPath::Avx512Vnni,
        KernelPath::Avx512,
        KernelPath::Avx2Fma,
        KernelPath::Portable,
    ];

    /// Whether the running CPU can execute this path.
    pub fn is_available(self) -> bool {
        match self {
            KernelPath::Portable => true,
            #[cfg(target_arch = "x86_64")]
            KernelPath::Avx512Vnni => {
                std::is_x86_feature_detected!("avx512f")
                    && std::is_x86_feature_detected!("avx512bw")
                    && std::is_x86_feature_detected!("avx512vnni")
            }
            #[cfg(target_arch = "x86_64")]
            KernelPath::Avx512 => std::is_x86_feature_detected!("avx512f"),
            #[cfg(target_arch = "x86_64")]
            KernelPath::Avx2Fma => {
                std::is_x86_feature_detected!("avx2")
                    && std::is_x86_feature_detected!("fma")
                    && std::is_x86_feature_detected!("f16c")
            }
            #[cfg(not(target_arch = "x86_64"))]
            _ => false,
        }
    }

    /// The fastest path available on the running CPU.
    pub fn detect() -> KernelPath {
        Self::ALL
            .into_iter()
            .find(|p| p.is_available())
            .unwrap_or(KernelPath::Portable)
    }

    /// Every path available on the running CPU, fastest first.
    pub fn available() -> Vec<KernelPath> {
        Self::ALL.into_iter().filter(|p| p.is_available()).collect()
    }

    /// Short lowercase name (`avx512vnni`, `avx512`, `avx2fma`, `portable`).
    pub fn name(self) -> &'static str {
        match self {
            KernelPath::Avx512Vnni => "avx512vnni",
            KernelPath::Avx512 => "avx512",
            KernelPath::Avx2Fma => "avx2fma",
            KernelPath::Portable => "portable",
        }
    }
}

impl std::fmt::Display for KernelPath {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// A forced [`KernelPath`] that the running CPU cannot execute.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Error)]
#[error("kernel path {0} is not supported by this CPU")]
pub struct PathUnavailable(pub KernelPath);

/// Where one dense layer lives in the weight store.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub(crate) struct LayerPlan {
    /// Inputs of the layer (not padded).
    pub(crate) n_in: usize,
    /// Output blocks (`ceil(n_out / 16)`); for the output layer: input blocks (`ceil(n_in / 16)`).
    pub(crate) n_blk: usize,
    /// First 16-wide row of this layer in the weight store.
    pub(crate) row0: usize,
    /// First bias block of this layer (hidden layers only).
    pub(crate) bias_blk0: usize,
}

/// The weight store of a quantised network (int8 quad rows or int16 pair rows): every weight byte of
/// the net lives in these `Vec`s.
#[derive(Clone, Debug)]
pub(crate) struct QuantStore<R> {
    /// Hidden-layer code rows (64 bytes each; layout per dtype in `int8.rs` / `int16.rs`).
    pub(crate) rows: Vec<R>,
    /// Per-output-channel weight scales, indexed exactly like `Net::bias` (padding lanes 0).
    pub(crate) scale: Vec<Block>,
    /// The output layer's f32 weight rows (`out.row0` indexes this `Vec`).
    pub(crate) out: Vec<Block>,
}

/// The re-laid-out weights.
#[derive(Clone, Debug)]
pub(crate) enum Store {
    /// f32 rows, one [`Block`] per row.
    F32(Vec<Block>),
    /// f16 or bf16 bit patterns, two rows per [`HalfBlock`].
    Half(Vec<HalfBlock>),
    /// int8 hidden layers (quad rows + per-channel scales) and an f32 output layer.
    Int8(Int8Store),
    /// int16 hidden layers (pair rows + per-channel scales) and an f32 output layer.
    Int16(Int16Store),
}

/// Everything the kernels read (immutable after construction).
#[derive(Clone, Debug)]
pub(crate) struct Net {
    pub(crate) n_in: usize,
    /// The input normalisation's means in blocks, padded with 0.
    pub(crate) mean: Vec<Block>,
    /// Its scales in blocks, padded with 1 (so the padding normalises to 0).
    pub(crate) scale: Vec<Block>,
    pub(crate) hidden: [LayerPlan; limits::MAX_HIDDEN_LAYERS],
    pub(crate) n_hidden: usize,
    pub(crate) out: LayerPlan,
    pub(crate) out_bias: f32,
    pub(crate) store: Store,
    pub(crate) bias: Vec<Block>,
}

/// Activation buffers (the only memory [`Mlp::forward`] writes).
#[derive(Clone, Debug)]
pub(crate) struct Scratch {
    /// Normalised input, zero-padded to whole blocks.
    pub(crate) xin: Vec<Block>,
    /// Ping-pong activation buffers, each `max hidden blocks` long.
    pub(crate) a: Vec<Block>,
    pub(crate) b: Vec<Block>,
    /// The quantised input of the current layer: u8 for the int8 VNNI path (at least
    /// `4 · ceil(max width / 4)` bytes), i16 for the int16 paths (at least `2 · ceil(max width / 2)`
    /// values).
    pub(crate) q: Vec<ByteBlock>,
}

/// An MLP laid out for inference. Built once (allocates), then [`Mlp::forward`] never allocates.
#[derive(Clone, Debug)]
pub struct Mlp {
    net: Net,
    scratch: Scratch,
    dtype: StorageDtype,
    path: KernelPath,
}

/// Rounds one f32 weight to the storage precision and returns its bit pattern (f16/bf16) — RNE.
fn encode_half(v: f32, dtype: StorageDtype) -> u16 {
    match dtype {
        StorageDtype::Bf16 => half::bf16::from_f32(v).to_bits(),
        _ => half::f16::from_f32(v).to_bits(),
    }
}

/// The weights a kernel with storage `dtype` actually computes with: every layer weight rounded to
/// `dtype` (round to nearest, ties to even) and back to f32; for [`StorageDtype::Int8`] and
/// [`StorageDtype::Int16`] every hidden-layer weight quantised per output channel
/// ([`int8_channel_scale`]/[`int8_code`], [`int16_channel_scale`]/[`int16_code`]) and dequantised,
/// the output layer unchanged. Biases and normalisation stay f32, as in the kernel (the int8 VNNI
/// path and the int16 paths additionally quantise activations, which this does not model). Use it to validate a reduced-precision model against its f32 original.
pub fn storage_rounded(w: &MlpWeights, dtype: StorageDtype) -> MlpWeights {
    let mut r = w.clone();
    for l in &mut r.layers {
        for v in &mut l.weight {
            *v = match dtype {
                StorageDtype::F32 => *v,
                StorageDtype::F16 => half::f16::from_f32(*v).to_f32(),
                StorageDtype::Bf16 => half::bf16::from_f32(*v).to_f32(),
                StorageDtype::Int8 | StorageDtype::Int16 => *v, // per channel below
            };
        }
    }
    let n_hidden = r.layers.len().saturating_sub(1);
    for l in &mut r.layers[..n_hidden] {
        for row in l.weight.chunks_mut(l.n_in.max(1)) {
            match dtype {
                StorageDtype::Int8 => {
                    let sc = int8_channel_scale(row);
                    for v in row {
                        *v = f32::from(int8_code(*v, sc)) * sc;
                    }
                }
                StorageDtype::Int16 => {
                    let sc = int16_channel_scale(row);
                    for v in row {
                        *v = f32::from(int16_code(*v, sc)) * sc;
                    }
                }
                _ => {}
            }
        }
    }
    r
}

fn blocks(n: usize) -> usize {
    n.div_ceil(LANES)
}

/// The symmetric per-channel scale of `row` for codes up to ±`qmax`: `max |w| / qmax`, nudged (by at
/// most a few ulps) to a value with `fl(fl(qmax · scale) / qmax) == scale` and `qmax · scale ≥ max |w|`,
/// so quantising the dequantised row again gives the same scale and codes. 0 for an all-zero row.
pub(crate) fn symmetric_scale(row: &[f32], qmax: f32) -> f32 {
    let m = row.iter().fold(0f32, |m, v| m.max(v.abs()));
    if m == 0.0 || !m.is_finite() {
        return 0.0;
    }
    let s = m / qmax;
    let mut c = s;
    for _ in 0..8 {
        if (qmax * c) / qmax == c && (qmax * c) >= m {
            return c;
        }
        c = f32::from_bits(c.to_bits() + 1);
    }
    s
}

/// The code of `w` at `scale`: `round(w / scale)` (ties away from zero) clamped to ±`qmax`; 0 at scale 0.
pub(crate) fn symmetric_code(w: f32, scale: f32, qmax: f32) -> f32 {
    if scale == 0.0 {
        return 0.0;
    }
    (w / scale).round().clamp(-qmax, qmax)
}

/// The shared part of the int8 and int16 stores: sets `hidden[k].row0` (rows of `rows_per_blk(n_in)`
/// per output block, layer after layer), computes each hidden row's channel scale, hands every weight
/// to `put(layer plan, block, lane, input, weight, scale)`, and returns the scale blocks and the
/// output layer as f32 rows (re-pointing `out.row0` at them).
fn quantise_hidden(
    w: &MlpWeights,
    hidden: &mut [LayerPlan],
    out: &mut LayerPlan,
    n_bias_blk: usize,
    rows_per_blk: fn(usize) -> usize,
    channel_scale: fn(&[f32]) -> f32,
    mut put: impl FnMut(&LayerPlan, usize, usize, usize, f32, f32),
) -> (Vec<Block>, Vec<Block>) {
    let mut scale = vec![ZERO_BLOCK; n_bias_blk];
    let mut row = 0usize;
    for (p, l) in hidden.iter_mut().zip(&w.layers) {
        p.row0 = row;
        for (o, wrow) in l.weight.chunks(l.n_in).enumerate() {
            let (blk, lane) = (o / LANES, o % LANES);
            let sc = channel_scale(wrow);
            scale[p.bias_blk0 + blk].0[lane] = sc;
            for (i, &v) in wrow.iter().enumerate() {
                put(p, blk, lane, i, v, sc);
            }
        }
        row += p.n_blk * rows_per_blk(l.n_in);
    }
    let last = &w.layers[hidden.len()];
    let mut out_rows = vec![ZERO_BLOCK; out.n_blk];
    for (i, &v) in last.weight.iter().enumerate() {
        out_rows[i / LANES].0[i % LANES] = v;
    }
    out.row0 = 0;
    (scale, out_rows)
}

/// Quantises the hidden layers of `w` into the int8 quad layout (`[blk][quad][lane][4]`).
fn int8_store(
    w: &MlpWeights,
    hidden: &mut [LayerPlan],
    out: &mut LayerPlan,
    n_bias_blk: usize,
) -> Int8Store {
    let n_quads: usize = hidden.iter().map(|p| p.n_blk * int8::quads(p.n_in)).sum();
    let mut quads = vec![QuadBlock([0; 4 * LANES]); n_quads.max(1)];
    let (scale, out) = quantise_hidden(
        w,
        hidden,
        out,
        n_bias_blk,
        int8::quads,
        int8_channel_scale,
        |p, blk, lane, i, v, sc| {
            let nq = int8::quads(p.n_in);
            quads[p.row0 + blk * nq + i / 4].0[4 * lane + i % 4] = int8_code(v, sc);
        },
    );
    Int8Store {
        rows: quads,
        scale,
        out,
    }
}

/// Quantises the hidden layers of `w` into the int16 pair layout ([`int16::pair_row`]).
fn int16_store(
    w: &MlpWeights,
    hidden: &mut [LayerPlan],
    out: &mut LayerPlan,
    n_bias_blk: usize,
) -> Int16Store {
    let n_pairs: usize = hidden.iter().map(|p| p.n_blk * int16::pairs(p.n_in)).sum();
    let mut pairs = vec![PairBlock([0; 2 * LANES]); n_pairs.max(1)];
    let (scale, out) = quantise_hidden(
        w,
        hidden,
        out,
        n_bias_blk,
        int16::pairs,
        int16_channel_scale,
        |p, blk, lane, i, v, sc| {
            let np = int16::pairs(p.n_in);
            pairs[int16::pair_row(p.row0, p.n_blk, np, blk, i / 2)].0[2 * lane + i % 2] =
                int16_code(v, sc);
        },
    );
    Int16Store {
        rows: pairs,
        scale,
        out,
    }
}

impl Mlp {
    /// Lays out `w` for inference with the given storage precision, on the fastest path the CPU supports
    /// ([`KernelPath::detect`]). Fails if `w` does not pass [`MlpWeights::validate`].
    pub fn new(w: &MlpWeights, dtype: StorageDtype) -> Result<Self, MlpShapeError> {
        w.validate()?;
        let n_layers = w.layers.len();
        let n_hidden = n_layers - 1;
        // Plan the rows: hidden layer k has n_blk(out) * n_in rows, the output layer n_blk(in) rows.
        let mut hidden = [LayerPlan::default(); limits::MAX_HIDDEN_LAYERS];
        let mut row = 0usize;
        let mut bias_blk = 0usize;
        let mut max_blk = 1usize;
        for (k, l) in w.layers[..n_hidden].iter().enumerate() {
            let n_blk = blocks(l.n_out);
            hidden[k] = LayerPlan {
                n_in: l.n_in,
                n_blk,
                row0: row,
                bias_blk0: bias_blk,
            };
            row += n_blk * l.n_in;
            bias_blk += n_blk;
            max_blk = max_blk.max(n_blk);
        }
        let last = &w.layers[n_hidden];
        debug_assert_eq!(last.activation, Activation::Identity);
        let mut out = LayerPlan {
            n_in: last.n_in,
            n_blk: blocks(last.n_in),
            row0: row,
            bias_blk0: 0,
        };
        let n_rows = row + out.n_blk;

        // Fill f32 rows first (zero padded), then encode if needed.
        let mut rows = vec![ZERO_BLOCK; n_rows];
        let mut bias = vec![ZERO_BLOCK; bias_blk.max(1)];
        for (k, l) in w.layers[..n_hidden].iter().enumerate() {
            let p = hidden[k];
            for o in 0..l.n_out {
                let (blk, lane) = (o / LANES, o % LANES);
                for i in 0..l.n_in {
                    rows[p.row0 + blk * l.n_in + i].0[lane] = l.weight[o * l.n_in + i];
                }
                bias[p.bias_blk0 + blk].0[lane] = l.bias[o];
            }
        }
        for (i, &v) in last.weight.iter().enumerate() {
            rows[out.row0 + i / LANES].0[i % LANES] = v;
        }
        let store = match dtype {
            StorageDtype::Int8 => {
                Store::Int8(int8_store(w, &mut hidden[..n_hidden], &mut out, bias.len()))
            }
            StorageDtype::Int16 => Store::Int16(int16_store(
                w,
                &mut hidden[..n_hidden],
                &mut out,
                bias.len(),
            )),
            StorageDtype::F32 => Store::F32(rows),
            StorageDtype::F16 | StorageDtype::Bf16 => {
                let mut hb = vec![HalfBlock([0; 2 * LANES]); n_rows.div_ceil(2)];
                for (r, blk) in rows.iter().enumerate() {
                    for (lane, &v) in blk.0.iter().enumerate() {
                        hb[r / 2].0[(r % 2) * LANES + lane] = encode_half(v, dtype);
                    }
                }
                Store::Half(hb)
            }
        };
        let n_in = w.n_inputs();
        let net = Net {
            n_in,
            mean: padded_blocks(&w.norm.mean, 0.0),
            scale: padded_blocks(&w.norm.scale, 1.0),
            hidden,
            n_hidden,
            out,
            out_bias: last.bias[0],
            store,
            bias,
        };
        let scratch = Scratch {
            xin: vec![ZERO_BLOCK; blocks(n_in)],
            a: vec![ZERO_BLOCK; max_blk],
            b: vec![ZERO_BLOCK; max_blk],
            // Two bytes per value (int16), a multiple of 4 (int8 quads).
            q: vec![
                ByteBlock([0; 4 * LANES]);
                (2 * max_blk.max(blocks(n_in)) * LANES).div_ceil(4 * LANES)
            ],
        };
        Ok(Self {
            net,
            scratch,
            dtype,
            path: KernelPath::detect(),
        })
    }

    /// Forces the implementation [`Mlp::forward`] uses. Fails if the running CPU cannot execute it.
    pub fn with_path(mut self, path: KernelPath) -> Result<Self, PathUnavailable> {
        if !path.is_available() {
            return Err(PathUnavailable(path));
        }
        self.path = path;
        Ok(self)
    }

    /// The implementation [`Mlp::forward`] runs.
    pub fn path(&self) -> KernelPath {
        self.path
    }

    /// Number of raw inputs.
    pub fn n_inputs(&self) -> usize {
        self.net.n_in
    }

    /// Storage precision.
    pub fn dtype(&self) -> StorageDtype {
        self.dtype
    }

    /// Bytes of weight storage the kernel streams per inference (padding included, biases excluded).
    pub fn weight_bytes(&self) -> usize {
        self.net.weight_spans().iter().map(|s| s.len()).sum()
    }

    /// One inference on a raw (un-normalised) input; returns the single output (joint-side friction, Nm).
    ///
    /// Never allocates and never panics. Returns `f32::NAN` if `x.len() != self.n_inputs()` or if any
    /// input is NaN or infinite or normalises to a non-finite value (a NaN would otherwise be silently
    /// clipped to 0 by a ReLU).
    pub fn forward(&mut self, x: &[f32]) -> f32 {
        if !normalise(&self.net, x, &mut self.scratch.xin) {
            return f32::NAN;
        }
        let net = &self.net;
        let s = &mut self.scratch;
        let code = match (self.dtype, &net.store) {
            (StorageDtype::F32, Store::F32(_)) => dt::F32,
            (StorageDtype::F16, Store::Half(_)) => dt::F16,
            (StorageDtype::Bf16, Store::Half(_)) => dt::BF16,
            (StorageDtype::Int8, Store::Int8(_)) => dt::INT8,
            (StorageDtype::Int16, Store::Int16(_)) => dt::INT16,
            _ => return f32::NAN, // unreachable by construction
        };
        match self.path {
            #[cfg(target_arch = "x86_64")]
            KernelPath::Avx512Vnni if code == dt::INT8 => x86::forward_vnni(net, s),
            #[cfg(target_arch = "x86_64")]
            KernelPath::Avx512Vnni if code == dt::INT16 => x86_int16::forward_vnni(net, s),
            #[cfg(target_arch = "x86_64")]
            KernelPath::Avx512 if code == dt::INT16 => x86_int16::forward_avx512(net, s),
            #[cfg(target_arch = "x86_64")]
            KernelPath::Avx2Fma if code == dt::INT16 => x86_int16::forward_avx2(net, s),
            _ if code == dt::INT16 => int16::forward_portable(net, s),
            #[cfg(target_arch = "x86_64")]
            KernelPath::Avx512 | KernelPath::Avx512Vnni => x86::forward_avx512(net, s, code),
            #[cfg(target_arch = "x86_64")]
            KernelPath::Avx2Fma => x86::forward_avx2(net, s, code),
            _ if code == dt::INT8 => int8::forward_portable(net, s),
            _ => portable::forward(net, s, code),
        }
    }
}

impl Net {
    /// Every byte range holding weights of this net (for int8 also the per-channel scales), in the
    /// order the kernel streams them; unused slots are empty. Each span starts 64-byte aligned.
    pub(crate) fn weight_spans(&self) -> [&[u8]; 3] {
        fn bytes<T: Copy>(v: &[T]) -> &[u8] {
            // SAFETY: only instantiated with `Block`, `HalfBlock`, `QuadBlock` and `PairBlock`: `repr(C)` arrays of
            // plain numbers whose size equals their alignment (64), so there are no padding bytes and
            // every byte is initialised; the slice borrows `v`.
            unsafe { std::slice::from_raw_parts(v.as_ptr().cast::<u8>(), std::mem::size_of_val(v)) }
        }
        match &self.store {
            Store::F32(v) => [bytes(v), &[], &[]],
            Store::Half(v) => [bytes(v), &[], &[]],
            Store::Int8(st) => [bytes(&st.rows), bytes(&st.scale), bytes(&st.out)],
            Store::Int16(st) => [bytes(&st.rows), bytes(&st.scale), bytes(&st.out)],
        }
    }

    /// Rows in the weight store (int8: quad rows, int16: pair rows of the hidden layers).
    fn n_rows(&self) -> usize {
        match &self.store {
            Store::F32(v) => v.len(),
            Store::Half(v) => 2 * v.len(),
            Store::Int8(st) => st.rows.len(),
            Store::Int16(st) => st.rows.len(),
        }
    }

    /// Rows of the output layer's store.
    fn n_out_rows(&self) -> usize {
        match &self.store {
            Store::Int8(st) => st.out.len(),
            Store::Int16(st) => st.out.len(),
            _ => self.n_rows(),
        }
    }

    /// Per-channel weight scale blocks (int8, int16).
    fn n_scale_blocks(&self) -> Option<usize> {
        match &self.store {
            Store::Int8(st) => Some(st.scale.len()),
            Store::Int16(st) => Some(st.scale.len()),
            _ => None,
        }
    }

    /// Checks that every row, bias block and activation block the kernels touch exists. True by
    /// construction; the SIMD paths check it once per call so their raw-pointer loads stay in bounds
    /// even if that invariant were ever broken.
    pub(crate) fn fits(&self, s: &Scratch) -> bool {
        let mut prev_blk = blocks(self.n_in);
        if s.xin.len() < prev_blk || self.n_hidden > self.hidden.len() {
            return false;
        }
        let n_scale = self.n_scale_blocks();
        for p in &self.hidden[..self.n_hidden] {
            // int8: quad rows; the kernels read 4·ceil(n_in/4) inputs and as many quantised bytes.
            // int16: pair rows; 2·ceil(n_in/2) inputs and twice as many quantised bytes.
            let (rows, n_x, q_bytes) = match &self.store {
                Store::Int8(_) => (
                    int8::quads(p.n_in),
                    4 * int8::quads(p.n_in),
                    4 * int8::quads(p.n_in),
                ),
                // (the SIMD quantisers write whole blocks of codes)
                Store::Int16(_) => {
                    let np = int16::pairs(p.n_in);
                    (np, 2 * np, 2 * LANES * (2 * np).div_ceil(LANES))
                }
                _ => (p.n_in, p.n_in, 0),
            };
            let ok = n_x <= prev_blk * LANES
                && q_bytes <= s.q.len() * 4 * LANES
                && n_scale.is_none_or(|n| p.bias_blk0 + p.n_blk <= n)
                && p.row0 + p.n_blk * rows <= self.n_rows()
                && p.bias_blk0 + p.n_blk <= self.bias.len()
                && p.n_blk <= s.a.len()
                && p.n_blk <= s.b.len();
            if !ok {
                return false;
            }
            prev_blk = p.n_blk;
        }
        self.out.n_blk <= prev_blk && self.out.row0 + self.out.n_blk <= self.n_out_rows()
    }
}

/// `v` in blocks, the last one padded with `pad`.
fn padded_blocks(v: &[f32], pad: f32) -> Vec<Block> {
    v.chunks(LANES)
        .map(|c| {
            let mut b = Block([pad; LANES]);
            b.0[..c.len()].copy_from_slice(c);
            b
        })
        .collect()
}

/// Writes `(x − mean) / scale` into `xin` (the zero padding past `n_in` is never touched).
/// Returns false if `x` has the wrong length or a non-finite value.
fn normalise(net: &Net, x: &[f32], xin: &mut [Block]) -> bool {
    let n = net.n_in;
    let n_blk = n.div_ceil(LANES);
    if x.len() != n || net.mean.len() < n_blk || net.scale.len() < n_blk || xin.len() < n_blk {
        return false;
    }
    // One block at a time as fixed-size arrays, so that each is straight-line vector code, with the
    // finiteness test on a whole block's exponent bits (a per-element test keeps the loop scalar).
    #[inline(always)]
    fn block(d: &mut Block, x: &[f32; LANES], m: &Block, s: &Block) -> bool {
        // Indexing fixed-size arrays compiles to vector code; the equivalent four-way `zip` did not
        // (scalar `vdivss`, seen in the disassembly).
        #[allow(clippy::needless_range_loop)]
        for k in 0..LANES {
            d.0[k] = (x[k] - m.0[k]) / s.0[k];
        }
        let mut bad = 0u32;
        for v in d.0 {
            bad |= u32::from(v.to_bits() & 0x7f80_0000 == 0x7f80_0000);
        }
        bad == 0
    }
    let mut ok = true;
    let (whole, tail) = x.as_chunks::<LANES>();
    for (((d, xs), m), s) in xin.iter_mut().zip(whole).zip(&net.mean).zip(&net.scale) {
        ok &= block(d, xs, m, s);
    }
    // The partial last block element by element (assembling it into an array first costs a
    // store-forwarding stall); its padding already holds 0.
    if let (Some(d), Some(m), Some(s)) = (
        xin.get_mut(whole.len()),
        net.mean.get(whole.len()),
        net.scale.get(whole.len()),
    ) {
        for (k, &xv) in tail.iter().enumerate() {
            d.0[k] = (xv - m.0[k]) / s.0[k];
            ok &= d.0[k].is_finite();
        }
    }
    ok
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mlp::{DenseLayer, Normalisation};

    fn net(sizes: &[usize]) -> MlpWeights {
        let mut seed = 0x1234_5678_u32;
        let mut rnd = move || {
            seed ^= seed << 13;
            seed ^= seed >> 17;
            seed ^= seed << 5;
            (seed as f32 / u32::MAX as f32) - 0.5
        };
        let n = sizes.len() - 1;
        let layers = (0..n)
            .map(|k| DenseLayer {
                n_in: sizes[k],
                n_out: sizes[k + 1],
                weight: (0..sizes[k] * sizes[k + 1]).map(|_| rnd()).collect(),
                bias: (0..sizes[k + 1]).map(|_| rnd() * 0.1 + 0.05).collect(),
                activation: if k + 1 == n {
                    Activation::Identity
                } else {
                    Activation::Relu
                },
            })
            .collect();
        MlpWeights {
            norm: Normalisation::identity(sizes[0]),
            layers,
        }
    }

    #[test]
    fn wrong_length_and_non_finite_give_nan() {
        let w = net(&[3, 17, 1]);
        for p in KernelPath::available() {
            let mut m = Mlp::new(&w, StorageDtype::F32)
                .unwrap()
                .with_path(p)
                .unwrap();
            assert!(m.forward(&[0.1, 0.2]).is_nan());
            assert!(m.forward(&[0.1, 0.2, 0.3, 0.4]).is_nan());
            assert!(m.forward(&[0.1, f32::NAN, 0.3]).is_nan());
            assert!(m.forward(&[0.1, f32::INFINITY, 0.3]).is_nan());
            assert!(m.forward(&[0.1, 0.2, 0.3]).is_finite());
        }
    }

    #[test]
    fn a_non_finite_input_anywhere_gives_nan_and_the_next_call_recovers() {
        // 37 inputs: two whole blocks and a partial one, which the normalisation treats differently.
        let mut w = net(&[37, 16, 1]);
        w.norm.scale[36] = 1e-30; // a finite input that normalises to infinity
        for p in KernelPath::available() {
            for dtype in StorageDtype::ALL {
                let mut m = Mlp::new(&w, dtype).unwrap().with_path(p).unwrap();
                let x = vec![1e-31f32; 37];
                let clean = m.forward(&x);
                assert!(clean.is_finite(), "{p} {dtype:?}");
                for k in 0..37 {
                    for bad in [f32::NAN, f32::INFINITY, f32::NEG_INFINITY] {
                        let mut y = x.clone();
                        y[k] = bad;
                        assert!(m.forward(&y).is_nan(), "{p} {dtype:?}: input {k} = {bad}");
                    }
                }
                let mut y = x.clone();
                y[36] = 1e10;
                assert!(
                    m.forward(&y).is_nan(),
                    "{p} {dtype:?}: overflow in the tail"
                );
                assert_eq!(m.forward(&x).to_bits(), clean.to_bits(), "{p} {dtype:?}");
            }
        }
    }

    #[test]
    fn layout_padding_and_sizes() {
        let w = net(&[5, 17, 33, 1]);
        let m = Mlp::new(&w, StorageDtype::F32).unwrap();
        // rows: 2 blocks * 5 + 3 blocks * 17 + 3 output rows = 64 rows of 64 bytes
        assert_eq!(m.weight_bytes(), (2 * 5 + 3 * 17 + 3) * 64);
        let h = Mlp::new(&w, StorageDtype::F16).unwrap();
        assert_eq!(h.weight_bytes(), (2 * 5 + 3 * 17 + 3) * 32);
        assert_eq!(m.n_inputs(), 5);
        assert_eq!(h.dtype(), StorageDtype::F16);
    }

    #[test]
    fn portable_matches_reference_small() {
        let w = net(&[7, 20, 1]);
        let mut m = Mlp::new(&w, StorageDtype::F32)
            .unwrap()
            .with_path(KernelPath::Portable)
            .unwrap();
        let x = [0.3, -0.2, 0.1, 0.5, -0.4, 0.25, 0.05];
        let want = w.forward_reference(&x)[0];
        let got = m.forward(&x);
        assert!(
            (got - want).abs() <= 1e-5 * want.abs().max(1e-3),
            "{got} vs {want}"
        );
    }
}
