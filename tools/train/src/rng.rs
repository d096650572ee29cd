//! Counter-based random streams for the trainer.
//!
//! Every random draw of a training run is derived from the run's seed and *where* it happens (epoch, step,
//! layer, row chunk), never from a generator that advances across the run. So the "RNG state" of a run is
//! its seed plus its step/epoch counters, which the checkpoint stores; a resumed run draws exactly what an
//! uninterrupted run would, and the number of rayon threads cannot change any draw.
//!
//! The dropout generator is hand-written (xorshift64*): it fills millions of mask entries per step, and the
//! measured alternative (ChaCha Bernoulli sampling, as burn does) dominated a whole training profile.
//! Shuffling and initialisation use `rand_chacha` (quality matters, speed does not).

/// Stream tags, so different uses of the same counters never share a stream.
pub(crate) mod tag {
    /// Weight initialisation.
    pub const INIT: u64 = 0x1A17_0000_0000_0001;
    /// Per-epoch shuffle of the training rows.
    pub const SHUFFLE: u64 = 0x5EF0_0000_0000_0002;
    /// Dropout masks.
    pub const DROPOUT: u64 = 0xD50F_0000_0000_0003;
    /// Chunk split into train/validation/test sets.
    pub const SPLIT: u64 = 0x5B17_0000_0000_0004;
    /// Hyper-parameter draws of a random search trial.
    pub const SEARCH: u64 = 0x5EA2_0000_0000_0005;
}

/// The SplitMix64 finaliser: a bijective 64-bit mixer.
#[inline]
pub(crate) fn splitmix(mut z: u64) -> u64 {
    z = z.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// Hashes a seed and a list of counters into one 64-bit stream key.
pub(crate) fn derive(seed: u64, parts: &[u64]) -> u64 {
    parts.iter().fold(splitmix(seed), |h, &p| splitmix(h ^ p))
}

/// xorshift64* (Vigna): 64 output bits per call, a handful of instructions.
pub(crate) struct XorShift64Star {
    state: u64,
}

impl XorShift64Star {
    /// A generator for the given key (a zero key is replaced: xorshift must not start at 0).
    #[inline]
    pub(crate) fn new(key: u64) -> Self {
        Self {
            state: if key == 0 { 0x2545_F491_4F6C_DD1D } else { key },
        }
    }

    /// Next 64 random bits.
    #[inline]
    pub(crate) fn next_u64(&mut self) -> u64 {
        let mut x = self.state;
        x ^= x >> 12;
        x ^= x << 25;
        x ^= x >> 27;
        self.state = x;
        x.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn derive_separates_counters() {
        assert_ne!(
            derive(1, &[tag::DROPOUT, 0, 1]),
            derive(1, &[tag::DROPOUT, 1, 0])
        );
        assert_ne!(derive(1, &[tag::DROPOUT]), derive(2, &[tag::DROPOUT]));
        assert_eq!(derive(7, &[1, 2, 3]), derive(7, &[1, 2, 3]));
    }

    #[test]
    fn xorshift_16bit_lanes_are_roughly_uniform() {
        // The dropout pass compares 16-bit lanes against a threshold: check the kept fraction.
        let mut g = XorShift64Star::new(derive(3, &[4]));
        let threshold = (0.1f64 * 65536.0).round() as u16;
        let (mut kept, mut total) = (0u64, 0u64);
        for _ in 0..100_000 {
            let mut bits = g.next_u64();
            for _ in 0..4 {
                kept += u64::from((bits as u16) >= threshold);
                total += 1;
                bits >>= 16;
            }
        }
        let frac = kept as f64 / total as f64;
        assert!((frac - 0.9).abs() < 0.003, "kept fraction {frac}");
    }
}
