//! A synthetic friction-like regression task for tests and benchmarks of the trainer.
//!
//! Each row holds `H` joint velocities (rad/s, oldest → newest) followed by `H` values of a second,
//! current-like signal (block-major like the paper's features). The label is a Stribeck–Coulomb–viscous
//! friction of the newest velocity plus a history-dependent term (the velocity change over the window)
//! and a term in the newest second signal, plus noise; the SCV target is the static SCV part alone,
//! as the caller of the trainer would compute it from a fitted SCV model. This is not real robot data.

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};

/// SCV parameters of the synthetic task: Coulomb 0.3 Nm, static 0.5 Nm, Stribeck velocity 0.1 rad/s,
/// viscous 0.2 Nm·s/rad (training-code form, sign() Coulomb, α = 2).
pub const SCV: [f32; 4] = [0.3, 0.5, 0.1, 0.2];

/// τ_F,SCV(v) in the training-code form `(Fc + (Fs − Fc)·exp(−(v/vs)²))·sign(v) + Fv·v`.
pub fn scv_nm(v_rad_s: f32) -> f32 {
    let [fc, fs, vs, fv] = SCV;
    let sign = if v_rad_s > 0.0 {
        1.0
    } else if v_rad_s < 0.0 {
        -1.0
    } else {
        0.0
    };
    (fc + (fs - fc) * (-(v_rad_s / vs).powi(2)).exp()) * sign + fv * v_rad_s
}

/// Generated data: row-major features and both targets.
#[derive(Clone, Debug)]
pub struct SyntheticData {
    /// `n_rows × 2H` features.
    pub x: Vec<f32>,
    /// Label τ_F, Nm.
    pub y_label_nm: Vec<f32>,
    /// SCV prior of each row, Nm.
    pub y_scv_nm: Vec<f32>,
    /// Features per row (2H).
    pub n_inputs: usize,
}

impl SyntheticData {
    /// The data as a trainer [`super::Dataset`].
    pub fn dataset(&self) -> super::Dataset<'_> {
        super::Dataset {
            x: &self.x,
            y_label_nm: &self.y_label_nm,
            y_scv_nm: &self.y_scv_nm,
            n_inputs: self.n_inputs,
        }
    }
}

/// `n_rows` samples with history `history` (so 2·history inputs), reproducible from `seed`.
pub fn friction_task(n_rows: usize, history: usize, seed: u64) -> SyntheticData {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let noise = Normal::new(0.0f32, 0.01).expect("valid sigma");
    let n_inputs = 2 * history;
    let mut x = Vec::with_capacity(n_rows * n_inputs);
    let (mut y, mut s) = (Vec::with_capacity(n_rows), Vec::with_capacity(n_rows));
    let dt_s = 0.01f32;
    for _ in 0..n_rows {
        let v_now: f32 = rng.random_range(-1.0..1.0);
        let acc: f32 = rng.random_range(-3.0..3.0);
        let i_now: f32 = rng.random_range(-1.0..1.0);
        let di: f32 = rng.random_range(-0.5..0.5);
        for k in (0..history).rev() {
            x.push(v_now - acc * dt_s * k as f32 + noise.sample(&mut rng));
        }
        for k in (0..history).rev() {
            x.push(i_now - di * k as f32 / history as f32);
        }
        let scv = scv_nm(v_now);
        s.push(scv);
        y.push(scv + 0.1 * acc + 0.3 * i_now * v_now.abs() + noise.sample(&mut rng));
    }
    SyntheticData {
        x,
        y_label_nm: y,
        y_scv_nm: s,
        n_inputs,
    }
}
