//! Fitting the input normalisation: per-column mean and inter-quartile range (the authors'
//! misnamed `StandardScaler`), on the training split only.
//!
//! Percentiles use linear interpolation between order statistics (NumPy's default `np.percentile`).
//! Columns whose IQR is ≤ [`MIN_IQR`] get scale 1, as the authors' exporter does.
//!
//! One deliberate deviation: when a column's IQR is below [`MIN_IQR_OVER_STD`] × its standard deviation
//! σ, the scale is σ instead. That happens when most samples sit at one value — e.g. a joint velocity
//! that is ≈ 0 for the stuck majority of an excitation log, IQR 4e-6 rad/s against peaks of 3.6 rad/s —
//! where the IQR would blow the moving samples up by 10⁴–10⁶ and training diverges (measured on a
//! simulated ankle-roll log). For bell-shaped data IQR ≈ 1.35 σ, so the authors' rule is unchanged
//! there. The scale is stored in the model, so the daemon applies whatever was fitted.
//!
//! This module does not apply the normalisation to data; the trainer and
//! [`frictionless::mlp::MlpWeights`] do.

use frictionless::mlp::Normalisation;

/// Columns with an inter-quartile range at or below this get scale 1.
pub const MIN_IQR: f32 = 1e-4;

/// A column whose IQR is below this fraction of its standard deviation is scaled by the standard
/// deviation instead (see the module doc).
pub const MIN_IQR_OVER_STD: f64 = 0.1;

/// The `q`-th quantile (0..=1) of `v` with linear interpolation; reorders `v`. `v` must be non-empty.
fn quantile_in_place(v: &mut [f32], q: f64) -> f64 {
    let pos = q * (v.len() - 1) as f64;
    let lo = pos.floor() as usize;
    let frac = pos - lo as f64;
    let (_, &mut lo_val, right) = v.select_nth_unstable_by(lo, f32::total_cmp);
    let lo_val = lo_val as f64;
    if frac == 0.0 || right.is_empty() {
        return lo_val;
    }
    let hi_val = right.iter().copied().fold(f32::INFINITY, f32::min) as f64;
    lo_val + frac * (hi_val - lo_val)
}

/// Fits mean and IQR scale per column of the row-major `x` (`n_rows × n_inputs`, finite values).
///
/// The mean is accumulated in f64. Returns the identity for zero rows.
pub fn fit_normalisation(x: &[f32], n_inputs: usize) -> Normalisation {
    let n_rows = x.len().checked_div(n_inputs).unwrap_or(0);
    if n_rows == 0 {
        return Normalisation::identity(n_inputs);
    }
    let mut col = vec![0f32; n_rows];
    let mut mean = Vec::with_capacity(n_inputs);
    let mut scale = Vec::with_capacity(n_inputs);
    for c in 0..n_inputs {
        let mut sum = 0f64;
        for (r, dst) in col.iter_mut().enumerate() {
            let v = x[r * n_inputs + c];
            sum += v as f64;
            *dst = v;
        }
        let m = sum / n_rows as f64;
        mean.push(m as f32);
        let var = col.iter().map(|&v| (v as f64 - m).powi(2)).sum::<f64>() / n_rows as f64;
        let std = var.sqrt();
        let q75 = quantile_in_place(&mut col, 0.75);
        let q25 = quantile_in_place(&mut col, 0.25);
        let iqr = q75 - q25;
        let s = if iqr >= MIN_IQR_OVER_STD * std {
            iqr
        } else {
            std
        } as f32;
        scale.push(if s > MIN_IQR { s } else { 1.0 });
    }
    Normalisation { mean, scale }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quantiles_match_numpy_linear_rule() {
        // np.percentile([1, 2, 3, 4], 25) = 1.75, 75 → 3.25; [5] → 5.
        let mut v = vec![4.0, 1.0, 3.0, 2.0];
        assert!((quantile_in_place(&mut v, 0.25) - 1.75).abs() < 1e-12);
        assert!((quantile_in_place(&mut v, 0.75) - 3.25).abs() < 1e-12);
        let mut one = vec![5.0];
        assert_eq!(quantile_in_place(&mut one, 0.75), 5.0);
    }

    #[test]
    fn fit_uses_iqr_and_guards_flat_columns() {
        // Column 0: 0..=100 → mean 50, IQR 75 − 25 = 50. Column 1 constant → scale 1.
        let x: Vec<f32> = (0..=100).flat_map(|i| [i as f32, 3.0]).collect();
        let n = fit_normalisation(&x, 2);
        assert!((n.mean[0] - 50.0).abs() < 1e-4);
        assert!((n.scale[0] - 50.0).abs() < 1e-4);
        assert_eq!(n.mean[1], 3.0);
        assert_eq!(n.scale[1], 1.0);
    }

    #[test]
    fn spiky_columns_are_scaled_by_their_standard_deviation() {
        // 90 % of the samples at 0, 10 % at ±2: IQR 0, σ = √(0.1·4) ≈ 0.632.
        let x: Vec<f32> = (0..1000)
            .map(|i| match i % 20 {
                0 => 2.0,
                1 => -2.0,
                _ => 0.0,
            })
            .collect();
        let n = fit_normalisation(&x, 1);
        assert!((n.scale[0] - 0.4f32.sqrt()).abs() < 1e-4, "{}", n.scale[0]);
    }
}
