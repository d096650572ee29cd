//! Inlinable `exp`, `ln`, `powf` and `tanh`: the project's one set of fast transcendental kernels.
//!
//! What it is: branch-light f64 kernels that the compiler inlines into hot loops — the simulator's
//! 20 kHz plant step (latency-bound: the independent transcendental calls of one physics step
//! overlap instead of serialising through libm calls, which were ≈ 45–55 % of its instructions)
//! and the friction-fit's vectorised least-squares pass ([`exp_lanes`], [`ln_lanes`]: the same
//! kernels written one loop per operation over a lane array, so LLVM emits SIMD code with table
//! gathers). Hand-written because no well-kept crate offers inlinable, FMA-based kernels with a
//! stated error bound (the `libm` crate is a port of the out-of-line algorithms).
//!
//! Error bounds (checked against libm by the unit tests below over dense sweeps):
//! - [`exp`]: relative error ≤ 3e-16 (≈ 1 ulp) on [−708, 709]; 0 below −708 (libm returns a
//!   subnormal < 3e-308 there); libm above 709;
//! - [`ln`]: absolute error ≤ 4e-16 + 4e-16·|ln x| for finite normal x > 0;
//! - [`powf`]: x^y for x ≥ 0, relative error ≤ 4e-16·(1 + |y·ln x|) + 4e-16;
//! - [`tanh`]: absolute error ≤ 1e-15 (relative ≤ 1e-15 for |x| < 1/16), exactly ±1 for |x| ≥ 20;
//! - [`exp_lanes`], [`ln_lanes`]: the same values as [`exp`] and [`ln`] per lane, except that
//!   [`exp_lanes`] gives +∞ above 709 (branch-free).
//!
//! What it is not: general-purpose libm replacements (no NaN/∞ propagation guarantees beyond what is
//! stated, no subnormal inputs for [`ln`]); reference computations keep calling libm.

/// log₂ e.
const LOG2_E: f64 = std::f64::consts::LOG2_E;
/// ln 2 split so that k·LN2_HI is exact for |k| < 2¹¹ (fdlibm's split).
const LN2_HI: f64 = 0.693_147_180_369_123_8; // 0x3fe62e42fee00000
/// ln 2 − LN2_HI.
const LN2_LO: f64 = 1.908_214_929_270_587_7e-10; // 0x3dea39ef35793c76

/// 2^(j/64), j = 0..63, each correctly rounded (generated with Python's `decimal` at 60 digits).
#[rustfmt::skip]
static EXP2_TABLE: [f64; 64] = [
    1.0,
    1.0108892860517005,
    1.0218971486541166,
    1.0330248790212284,
    1.0442737824274138,
    1.0556451783605572,
    1.0671404006768237,
    1.0787607977571199,
    1.0905077326652577,
    1.102382583307841,
    1.1143867425958924,
    1.1265216186082418,
    1.1387886347566916,
    1.1511892299529827,
    1.1637248587775775,
    1.1763969916502812,
    1.189207115002721,
    1.202156731452703,
    1.215247359980469,
    1.22848053610687,
    1.241857812073484,
    1.255380757024691,
    1.2690509571917332,
    1.2828700160787783,
    1.2968395546510096,
    1.3109612115247644,
    1.3252366431597413,
    1.339667524053303,
    1.3542555469368927,
    1.3690024229745905,
    1.383909881963832,
    1.3989796725383112,
    std::f64::consts::SQRT_2, // 2^(32/64)
    1.42961333839197,
    1.4451808069770467,
    1.460917794180647,
    1.4768261459394993,
    1.4929077282912648,
    1.5091644275934228,
    1.5255981507445384,
    1.5422108254079407,
    1.559004400237837,
    1.5759808451078865,
    1.593142151342267,
    1.6104903319492543,
    1.6280274218573478,
    1.645755478153965,
    1.6636765803267364,
    1.681792830507429,
    1.7001063537185235,
    1.718619298122478,
    1.7373338352737062,
    1.7562521603732995,
    1.7753764925265212,
    1.7947090750031072,
    1.8142521755003989,
    1.8340080864093424,
    1.8539791250833855,
    1.8741676341103,
    1.8945759815869656,
    1.9152065613971474,
    1.9360617934922943,
    1.9571441241754002,
    1.978456026387951,
];

/// e^x. Range reduction x = (64·m + j)·ln2/64 + r with |r| ≤ ln2/128 (Cody–Waite, exact products),
/// e^x = 2^m · 2^(j/64) · e^r with the table above and the degree-5 Taylor polynomial of e^r − 1
/// (truncation < 4e-17 relative) in Estrin form; 2^m through the exponent bits. ≈ 25 instructions
/// and ≈ 30 cycles of latency from x to the result (the plant's step is one long dependency chain
/// through two of these, so latency is what counts), no call.
#[inline(always)]
pub fn exp(x: f64) -> f64 {
    if x < -708.0 {
        return 0.0;
    }
    if x > 709.0 {
        return x.exp(); // cold: never reached by the plant; keeps 2^m inside the exponent range
    }
    exp_in_range(x)
}

/// [`exp`] without the range checks, for call sites that bound x ∈ [−708, 709] themselves (the
/// result is garbage outside; checked in debug builds).
#[inline(always)]
pub fn exp_in_range(x: f64) -> f64 {
    debug_assert!((-708.0..=709.0).contains(&x), "exp_in_range({x})");
    const INV_STEP: f64 = 64.0 * LOG2_E;
    const STEP_HI: f64 = LN2_HI / 64.0;
    const STEP_LO: f64 = LN2_LO / 64.0;
    // k = round(x·64/ln2) by the 1.5·2^52 shifter: one FMA, and k is in the low mantissa bits
    let shifted = x.mul_add(INV_STEP, SHIFTER);
    let k = shifted.to_bits() as i64; // low bits: k modulo 2^51 (two's complement for k < 0)
    let kf = shifted - SHIFTER;
    let r = (-kf).mul_add(STEP_LO, (-kf).mul_add(STEP_HI, x));
    // x ∈ [−708, 709] gives m = ⌊k/64⌋ ∈ [−1022, 1022]: 2^m is a normal number
    let m = ((k << 13) >> 19) as u64; // sign-extend the 51-bit k, then ⌊k/64⌋
    let t = EXP2_TABLE[(k & 63) as usize] * f64::from_bits(m.wrapping_add(1023) << 52);
    // e^r − 1 = r + r²·(1/2 + r/6) + r⁴·(1/24 + r/120)
    let r2 = r * r;
    let r4 = r2 * r2;
    let a = r.mul_add(1.0 / 6.0, 0.5);
    let b = r.mul_add(1.0 / 120.0, 1.0 / 24.0);
    let q = r4.mul_add(b, r2.mul_add(a, r));
    t.mul_add(q, t)
}

/// 1/c_j with c_j = 1 + (j + ½)/64, j = 0..63, rounded to f64.
#[rustfmt::skip]
static LN_INV_C: [f64; 64] = [
    0.9922480620155039,
    0.9770992366412213,
    0.9624060150375939,
    0.9481481481481482,
    0.9343065693430657,
    0.920863309352518,
    0.9078014184397163,
    0.8951048951048951,
    0.8827586206896552,
    0.8707482993197279,
    0.8590604026845637,
    0.847682119205298,
    0.8366013071895425,
    0.8258064516129032,
    0.8152866242038217,
    0.8050314465408805,
    0.7950310559006211,
    0.7852760736196319,
    0.7757575757575758,
    0.7664670658682635,
    0.757396449704142,
    0.7485380116959064,
    0.7398843930635838,
    0.7314285714285714,
    0.7231638418079096,
    0.7150837988826816,
    0.7071823204419889,
    0.6994535519125683,
    0.6918918918918919,
    0.6844919786096256,
    0.6772486772486772,
    0.6701570680628273,
    0.6632124352331606,
    0.6564102564102564,
    0.649746192893401,
    0.6432160804020101,
    0.6368159203980099,
    0.6305418719211823,
    0.624390243902439,
    0.6183574879227053,
    0.6124401913875598,
    0.6066350710900474,
    0.6009389671361502,
    0.5953488372093023,
    0.5898617511520737,
    0.5844748858447488,
    0.579185520361991,
    0.5739910313901345,
    0.5688888888888889,
    0.5638766519823789,
    0.5589519650655022,
    0.5541125541125541,
    0.5493562231759657,
    0.5446808510638298,
    0.540084388185654,
    0.5355648535564853,
    0.5311203319502075,
    0.5267489711934157,
    0.5224489795918368,
    0.5182186234817814,
    0.5140562248995983,
    0.5099601593625498,
    0.5059288537549407,
    0.5019607843137255,
];

/// −ln(LN_INV_C[j]) of the f64 values above, correctly rounded (Python `decimal`, 80 digits).
#[rustfmt::skip]
static LN_LOG_C: [f64; 64] = [
    0.007782140442054963,
    0.023167059281534418,
    0.03831886430213666,
    0.05324451451881224,
    0.06795066190850778,
    0.08244366921107454,
    0.09672962645855114,
    0.11081436634029011,
    0.12470347850095725,
    0.1384023228591192,
    0.151916042025842,
    0.16524957289530717,
    0.17840765747281825,
    0.19139485299962947,
    0.20421554142869083,
    0.2168739383006143,
    0.2293741010648459,
    0.24171993688714513,
    0.25391520998096345,
    0.2659635484971379,
    0.2778684510034563,
    0.2896332925830427,
    0.30126133057816185,
    0.3127557100038969,
    0.324119468654212,
    0.3353555419211378,
    0.3464667673462086,
    0.3574558889218038,
    0.36832556115870757,
    0.3790783529349695,
    0.38971675114002524,
    0.40024316412701266,
    0.4106599249852683,
    0.42096929464412963,
    0.43117346481837143,
    0.4412745608048752,
    0.4512746441394586,
    0.46117571512217015,
    0.470979715218791,
    0.48068852934575196,
    0.4903039880451939,
    0.49982786955644926,
    0.5092619017898079,
    0.5186077642080457,
    0.5278670896208424,
    0.5370414658968837,
    0.5461324375981356,
    0.5551415075405016,
    0.564070138284803,
    0.5729197535617854,
    0.5816917396346225,
    0.5903874466021763,
    0.5990081896460834,
    0.6075552502245418,
    0.616029877215514,
    0.6244332880118936,
    0.6327666695710378,
    0.6410311794209312,
    0.6492279466251097,
    0.65735807270836,
    0.6654226325450905,
    0.6734226752121667,
    0.6813592248079031,
    0.689233281238809,
];

/// ln x for finite normal x > 0 (0, subnormals, ∞ and NaN are not handled; callers guard).
/// x = 2^e·m, m ∈ [1, 2); c_j is the centre of the 1/64-wide interval holding m, so
/// r = m/c_j − 1 (one FMA with the tabulated 1/c_j) has |r| ≤ 1/128 and
/// ln x = e·ln 2 − ln(1/c_j) + ln(1 + r) with the degree-7 series of ln(1 + r) (truncation
/// < 2e-18). No division: ≈ 35 cycles of latency.
#[inline(always)]
pub fn ln(x: f64) -> f64 {
    let bits = x.to_bits();
    let e = ((bits >> 52) & 0x7ff) as i64 - 1023;
    let j = ((bits >> 46) & 63) as usize;
    let m = f64::from_bits((bits & 0x000f_ffff_ffff_ffff) | 0x3ff0_0000_0000_0000);
    let r = m.mul_add(LN_INV_C[j], -1.0);
    // ln(1 + r) = r − r²/2 + r³/3 − r⁴/4 + r⁵/5 − r⁶/6 + r⁷/7 (Estrin)
    let r2 = r * r;
    let r4 = r2 * r2;
    let p01 = r.mul_add(-0.5, 1.0); // 1 − r/2
    let p23 = r.mul_add(-0.25, 1.0 / 3.0);
    let p45 = r.mul_add(-1.0 / 6.0, 0.2);
    let p67 = 1.0 / 7.0;
    let lo = r2.mul_add(p23, p01);
    let hi = r2.mul_add(p67, p45);
    let poly = r * r4.mul_add(hi, lo);
    let ef = e as f64;
    ef.mul_add(LN2_HI, LN_LOG_C[j]) + ef.mul_add(LN2_LO, poly)
}

/// x^y for x ≥ 0 and finite y > 0 as e^{y·ln x}; exactly 0 for x < 1e-300 (where x^y < 1e-300·y
/// is negligible against anything it is added to in the plant).
#[inline(always)]
pub fn powf(x: f64, y: f64) -> f64 {
    if x < 1e-300 {
        return 0.0;
    }
    exp(y * ln(x))
}

/// tanh x: exactly ±1 for |x| ≥ 20 (where libm's tanh is ±1 too), the odd Taylor series to x¹³ for
/// |x| < 1/16 (truncation < 1e-19 relative), else (1 − e^{−2|x|})/(1 + e^{−2|x|}).
#[inline(always)]
pub fn tanh(x: f64) -> f64 {
    let a = x.abs();
    if a >= 20.0 {
        return 1.0_f64.copysign(x);
    }
    if a < 0.0625 {
        let x2 = x * x;
        const C: [f64; 7] = [
            1.0,
            -1.0 / 3.0,
            2.0 / 15.0,
            -17.0 / 315.0,
            62.0 / 2835.0,
            -1382.0 / 155_925.0,
            21_844.0 / 6_081_075.0,
        ];
        let p = C[6]
            .mul_add(x2, C[5])
            .mul_add(x2, C[4])
            .mul_add(x2, C[3])
            .mul_add(x2, C[2])
            .mul_add(x2, C[1])
            .mul_add(x2, C[0]);
        return x * p;
    }
    let e = exp_in_range(-2.0 * a); // a < 20
    ((1.0 - e) / (1.0 + e)).copysign(x)
}

/// 1.5·2⁵²: adding it rounds an f64 of magnitude < 2⁵¹ to an integer held in the low mantissa bits
/// (a float→int conversion without `cvtpd2qq`, which AVX2 lacks).
const SHIFTER: f64 = 6_755_399_441_055_744.0;

/// [`exp`] on each lane, branch-free (vectorisable): 0 below −708, +∞ above 709. Written as one
/// loop per operation, the shape LLVM reliably turns into SIMD code.
#[inline(always)]
// max/min instead of clamp: clamp's NaN/ordering checks keep LLVM from vectorising the loop.
#[allow(clippy::manual_clamp)]
pub fn exp_lanes<const N: usize>(x: &[f64; N]) -> [f64; N] {
    let mut y = [0.0; N];
    for l in 0..N {
        y[l] = exp_in_range(x[l].max(-708.0).min(709.0));
    }
    for l in 0..N {
        y[l] = if x[l] < -708.0 { 0.0 } else { y[l] };
    }
    for l in 0..N {
        y[l] = if x[l] > 709.0 { f64::INFINITY } else { y[l] };
    }
    y
}

/// [`ln`] on each lane (finite normal x > 0), branch-free (vectorisable).
#[inline(always)]
pub fn ln_lanes<const N: usize>(x: &[f64; N]) -> [f64; N] {
    let mut y = [0.0; N];
    for l in 0..N {
        y[l] = ln(x[l]);
    }
    y
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Deterministic sweep: uniform grid plus a log-spaced grid (no RNG needed).
    fn sweep(lo: f64, hi: f64, n: usize) -> impl Iterator<Item = f64> {
        (0..=n).map(move |i| lo + (hi - lo) * i as f64 / n as f64)
    }

    #[test]
    fn constants_and_tables_are_what_they_claim() {
        assert_eq!(LN2_HI.to_bits(), 0x3fe6_2e42_fee0_0000);
        assert_eq!(LN2_LO.to_bits(), 0x3dea_39ef_3579_3c76);
        assert_eq!(LN2_HI + LN2_LO, std::f64::consts::LN_2);
        for (j, &t) in EXP2_TABLE.iter().enumerate() {
            let want = (j as f64 / 64.0).exp2();
            assert!((t - want).abs() <= f64::EPSILON * want, "2^({j}/64)");
        }
        for j in 0..64 {
            let c = 1.0 + (j as f64 + 0.5) / 64.0;
            assert!((LN_INV_C[j] - 1.0 / c).abs() <= f64::EPSILON / c, "1/c_{j}");
            let want = -LN_INV_C[j].ln();
            assert!(
                (LN_LOG_C[j] - want).abs() <= f64::EPSILON * want.abs(),
                "ln c_{j}"
            );
        }
    }

    #[test]
    fn exp_is_within_1_ulp_of_libm() {
        let mut worst = 0.0f64;
        for x in sweep(-708.0, 709.0, 2_000_003).chain(sweep(-1.0, 1.0, 1_000_001)) {
            let (a, b) = (exp(x), x.exp());
            let rel = ((a - b) / b).abs();
            worst = worst.max(rel);
            assert!(rel <= 3e-16, "exp({x}) = {a} vs libm {b} (rel {rel:e})");
        }
        eprintln!("exp: worst relative error vs libm {worst:e}");
        assert_eq!(exp(0.0), 1.0);
        assert_eq!(exp(-800.0), 0.0);
        assert_eq!(exp(800.0), f64::INFINITY);
        assert_eq!(exp(709.5), 709.5f64.exp());
        assert!(exp(-707.9) > 0.0 && exp(-707.9) < 1e-307);
    }

    #[test]
    fn ln_is_within_bound_of_libm() {
        for x in sweep(1e-3, 10.0, 1_000_001)
            .chain((0..=600_000).map(|i| 10f64.powf(-300.0 + i as f64 * 1e-3)))
        {
            let (a, b) = (ln(x), x.ln());
            let bound = 4e-16 + 4e-16 * b.abs();
            assert!((a - b).abs() <= bound, "ln({x}) = {a} vs libm {b}");
        }
        assert!(ln(1.0).abs() <= 4e-16);
        assert!((ln(std::f64::consts::E) - 1.0).abs() <= 8e-16);
    }

    #[test]
    fn powf_is_within_bound_of_libm() {
        for y in [0.2, 0.7, 1.0, 1.5, 2.0, 5.0] {
            for x in
                sweep(0.0, 200.0, 400_001).chain((0..=20_000).map(|i| 1e-12 * 1.001f64.powi(i)))
            {
                let (a, b) = (powf(x, y), x.powf(y));
                let bound = if x < 1e-300 {
                    1e-300
                } else {
                    b * (4e-16 * (1.0 + (y * x.ln()).abs()) + 4e-16)
                };
                assert!((a - b).abs() <= bound, "powf({x}, {y}) = {a} vs libm {b}");
            }
        }
    }

    #[test]
    fn tanh_is_within_bound_of_libm() {
        for x in sweep(-25.0, 25.0, 2_000_001).chain(sweep(-0.1, 0.1, 200_001)) {
            let (a, b) = (tanh(x), x.tanh());
            assert!((a - b).abs() <= 1e-15, "tanh({x}) = {a} vs libm {b}");
            if x.abs() < 0.0625 && x != 0.0 {
                assert!(((a - b) / b).abs() <= 1e-15, "tanh({x}) relative");
            }
        }
        assert_eq!(tanh(0.0), 0.0);
        assert_eq!(tanh(30.0), 1.0);
        assert_eq!(tanh(-30.0), -1.0);
    }

    #[test]
    fn lane_exp_and_ln_equal_the_scalar_kernels_and_stay_within_libm_bounds() {
        const LANES: usize = 8;
        let mut xs = vec![
            0.0, -0.0, 1e-300, -1e-12, 0.5, -0.5, 0.3465, -0.3466, 1.0, -1.0, 700.0, -700.0,
        ];
        let mut s = 0x9e37_79b9_7f4a_7c15u64;
        for _ in 0..20_000 {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            xs.push(((s >> 11) as f64 / (1u64 << 53) as f64 - 0.5) * 1400.0);
            xs.push(((s >> 11) as f64 / (1u64 << 53) as f64 - 0.5) * 6.0);
        }
        xs.truncate(xs.len() / LANES * LANES);
        for g in xs.chunks_exact(LANES) {
            let g: &[f64; LANES] = g.try_into().unwrap();
            let e = exp_lanes(g);
            for l in 0..LANES {
                assert_eq!(e[l].to_bits(), exp(g[l]).to_bits(), "exp({})", g[l]);
                let want = g[l].exp();
                let rel = ((e[l] - want) / want).abs();
                assert!(rel <= 3e-16, "exp({}) = {} vs {want}", g[l], e[l]);
            }
            // ln on positive normal values spanning the whole exponent range.
            let mut pos = [0.0; LANES];
            for l in 0..LANES {
                pos[l] = (g[l] * 0.5).exp().max(f64::MIN_POSITIVE);
            }
            let lnv = ln_lanes(&pos);
            for l in 0..LANES {
                let want = pos[l].ln();
                assert_eq!(lnv[l].to_bits(), ln(pos[l]).to_bits());
                assert!(
                    (lnv[l] - want).abs() <= 4e-16 + 4e-16 * want.abs(),
                    "ln({}) = {} vs {want}",
                    pos[l],
                    lnv[l]
                );
            }
        }
        // Outside the range: 0 and +∞, never NaN.
        let e = exp_lanes(&[-710.0, -1e300, 710.0, f64::NEG_INFINITY]);
        assert_eq!(e, [0.0, 0.0, f64::INFINITY, 0.0]);
    }
}
