//! Velocity bands, temperature bins and residual statistics per bin: the one banding used by
//! `frictl eval` (its per-band RMSE, its drift monitor) and by `frictl train` (the reference residuals
//! it stores in its report).
//!
//! What it is: [`DEFAULT_BAND_EDGES_RAD_S`] and [`band_of`] (band j is `edges[j] ≤ |ṡ| < edges[j+1]`, the
//! last one open); [`temperature_bin_of`] (bin k is `k·w ≤ T < (k+1)·w` °C); [`ResidualSums`], the
//! running count, sums and sum of squares of a residual (label − τ̂_F) and [`ResidualStats`], its
//! n / mean / mean along the motion / RMSE; [`ResidualProfile`], those statistics over all rows, per |ṡ| band and per
//! temperature bin, built by [`ResidualProfile::from_rows`] — the JSON object `frictl eval --drift`
//! prints and `frictl train --report` stores as `residual_reference`.
//!
//! What it is not: prediction (the caller supplies residuals) or a verdict (that is
//! `frictl eval --drift`).

use serde::{Deserialize, Serialize};

/// Default |ṡ| band edges [rad/s]: stick/creep, slow, medium, fast sliding, and the rest (≥ 1 rad/s).
pub const DEFAULT_BAND_EDGES_RAD_S: [f64; 5] = [0.0, 0.02, 0.1, 0.5, 1.0];

/// Default width of a temperature bin [°C].
pub const DEFAULT_TEMPERATURE_BIN_C: f64 = 5.0;

/// Index of the band of `|sdot_rad_s|` (None below the first edge or for a non-finite velocity).
pub fn band_of(edges: &[f64], sdot_rad_s: f64) -> Option<usize> {
    let v = sdot_rad_s.abs();
    if !v.is_finite() || edges.first().is_none_or(|e| v < *e) {
        return None;
    }
    Some(edges.iter().rposition(|e| v >= *e).unwrap_or(0))
}

/// Index k of the temperature bin `[k·width_c, (k+1)·width_c)` of `temperature_c` (None for a
/// non-finite temperature — no sensor — or a width that is not finite and > 0).
pub fn temperature_bin_of(width_c: f64, temperature_c: f64) -> Option<i64> {
    if !(temperature_c.is_finite() && width_c.is_finite() && width_c > 0.0) {
        return None;
    }
    Some((temperature_c / width_c).floor() as i64)
}

/// Running count, sums and sum of squares of a residual [Nm].
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ResidualSums {
    /// Rows.
    pub n: usize,
    /// Σ residual [Nm].
    pub sum_nm: f64,
    /// Σ residual² [Nm²].
    pub sum_sq_nm2: f64,
    /// Σ residual·sign(ṡ) [Nm] (0 for ṡ = 0).
    pub sum_along_motion_nm: f64,
}

impl ResidualSums {
    /// Adds one residual at joint velocity `sdot_rad_s`.
    pub fn add(&mut self, residual_nm: f64, sdot_rad_s: f64) {
        self.n += 1;
        self.sum_nm += residual_nm;
        self.sum_sq_nm2 += residual_nm * residual_nm;
        if sdot_rad_s != 0.0 && sdot_rad_s.is_finite() {
            self.sum_along_motion_nm += residual_nm * sdot_rad_s.signum();
        }
    }

    /// Adds another set's sums.
    pub fn merge(&mut self, o: &Self) {
        self.n += o.n;
        self.sum_nm += o.sum_nm;
        self.sum_sq_nm2 += o.sum_sq_nm2;
        self.sum_along_motion_nm += o.sum_along_motion_nm;
    }

    /// n, mean and RMSE (None over zero rows).
    pub fn stats(&self) -> ResidualStats {
        let n = self.n as f64;
        ResidualStats {
            n: self.n,
            mean_residual_nm: (self.n > 0).then(|| self.sum_nm / n),
            mean_along_motion_nm: (self.n > 0).then(|| self.sum_along_motion_nm / n),
            rmse_nm: (self.n > 0).then(|| (self.sum_sq_nm2 / n).sqrt()),
        }
    }
}

/// Residual statistics of one set of rows; residual = label − τ̂_F [Nm].
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct ResidualStats {
    /// Rows.
    pub n: usize,
    /// Mean signed residual [Nm] (None over zero rows): > 0 means the model under-predicts.
    pub mean_residual_nm: Option<f64>,
    /// Mean of residual·sign(ṡ) [Nm] (None over zero rows): > 0 means the friction opposing the
    /// motion is larger than the model says. A Coulomb or viscous change moves this mean while the
    /// signed mean, pooled over both directions, can stay put. Absent (null) in older files.
    #[serde(default)]
    pub mean_along_motion_nm: Option<f64>,
    /// RMSE [Nm] (None over zero rows).
    pub rmse_nm: Option<f64>,
}

/// One |ṡ| band's statistics: `lo_rad_s ≤ |ṡ| < hi_rad_s` (`hi_rad_s` null = unbounded).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct BandResiduals {
    /// Lower edge [rad/s].
    pub lo_rad_s: f64,
    /// Upper edge [rad/s] (None for the last band).
    pub hi_rad_s: Option<f64>,
    /// The statistics.
    #[serde(flatten)]
    pub stats: ResidualStats,
}

/// One temperature bin's statistics: `lo_c ≤ T < hi_c`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct TemperatureResiduals {
    /// Lower edge [°C].
    pub lo_c: f64,
    /// Upper edge [°C].
    pub hi_c: f64,
    /// The statistics.
    #[serde(flatten)]
    pub stats: ResidualStats,
}

/// Residual statistics over all rows, per |ṡ| band and per temperature bin.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct ResidualProfile {
    /// |ṡ| band edges [rad/s] of `bands` (the last band is open).
    pub band_edges_rad_s: Vec<f64>,
    /// Width of the temperature bins [°C].
    pub temperature_bin_c: f64,
    /// Every row.
    pub all: ResidualStats,
    /// Per |ṡ| band, one entry per edge (empty bands have n = 0).
    pub bands: Vec<BandResiduals>,
    /// Per temperature bin, ascending; only bins with rows (empty without a temperature).
    pub temperature: Vec<TemperatureResiduals>,
}

impl ResidualProfile {
    /// The profile of `rows` = (ṡ [rad/s], T [°C] or NaN, residual [Nm]); rows with a non-finite
    /// residual are skipped.
    pub fn from_rows(
        rows: impl IntoIterator<Item = (f64, f64, f64)>,
        band_edges_rad_s: &[f64],
        temperature_bin_c: f64,
    ) -> Self {
        let mut all = ResidualSums::default();
        let mut bands = vec![ResidualSums::default(); band_edges_rad_s.len()];
        let mut temps: std::collections::BTreeMap<i64, ResidualSums> = Default::default();
        for (sdot, t, r) in rows {
            if !r.is_finite() {
                continue;
            }
            all.add(r, sdot);
            if let Some(b) = band_of(band_edges_rad_s, sdot) {
                bands[b].add(r, sdot);
            }
            if let Some(k) = temperature_bin_of(temperature_bin_c, t) {
                temps.entry(k).or_default().add(r, sdot);
            }
        }
        Self {
            band_edges_rad_s: band_edges_rad_s.to_vec(),
            temperature_bin_c,
            all: all.stats(),
            bands: bands
                .iter()
                .enumerate()
                .map(|(j, s)| BandResiduals {
                    lo_rad_s: band_edges_rad_s[j],
                    hi_rad_s: band_edges_rad_s.get(j + 1).copied(),
                    stats: s.stats(),
                })
                .collect(),
            temperature: temps
                .iter()
                .map(|(k, s)| TemperatureResiduals {
                    lo_c: *k as f64 * temperature_bin_c,
                    hi_c: (*k + 1) as f64 * temperature_bin_c,
                    stats: s.stats(),
                })
                .collect(),
        }
    }

    /// The statistics of the temperature bin starting at `lo_c` (None if the profile has no row there).
    pub fn temperature_bin(&self, lo_c: f64) -> Option<&ResidualStats> {
        self.temperature
            .iter()
            .find(|t| (t.lo_c - lo_c).abs() < 1e-9 * self.temperature_bin_c.max(1.0))
            .map(|t| &t.stats)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bands_cover_every_velocity_from_the_first_edge() {
        let e = DEFAULT_BAND_EDGES_RAD_S;
        assert_eq!(band_of(&e, 0.0), Some(0));
        assert_eq!(band_of(&e, -0.019), Some(0));
        assert_eq!(band_of(&e, 0.02), Some(1));
        assert_eq!(band_of(&e, -0.7), Some(3));
        assert_eq!(band_of(&e, 1.0), Some(4));
        assert_eq!(band_of(&e, 50.0), Some(4));
        assert_eq!(band_of(&e, f64::NAN), None);
        assert_eq!(band_of(&[0.1, 1.0], 0.05), None);
    }

    #[test]
    fn profile_counts_means_and_rmses_per_band_and_temperature_bin() {
        assert_eq!(temperature_bin_of(5.0, 27.0), Some(5));
        assert_eq!(temperature_bin_of(5.0, -0.1), Some(-1));
        assert_eq!(temperature_bin_of(5.0, f64::NAN), None);
        assert_eq!(temperature_bin_of(0.0, 27.0), None);
        let rows = [
            (0.01, 26.0, 1.0),
            (0.01, 31.0, 3.0),
            (-0.3, 31.0, -2.0),
            (2.0, f64::NAN, 2.0),
            (2.0, 26.0, f64::NAN),
        ];
        let p = ResidualProfile::from_rows(rows, &[0.0, 0.02, 1.0], 5.0);
        assert_eq!(p.all.n, 4);
        assert_eq!(p.all.mean_residual_nm, Some(1.0));
        assert!((p.all.rmse_nm.unwrap() - (18.0f64 / 4.0).sqrt()).abs() < 1e-12);
        let n: Vec<usize> = p.bands.iter().map(|b| b.stats.n).collect();
        assert_eq!(n, [2, 1, 1]);
        assert_eq!(p.bands[0].stats.mean_residual_nm, Some(2.0));
        // residual·sign(ṡ): (1 + 3 + 2 + 2) / 4 with the −0.3 rad/s row's −2 flipped.
        assert_eq!(p.all.mean_along_motion_nm, Some(2.0));
        assert_eq!(p.bands[1].stats.mean_along_motion_nm, Some(2.0));
        assert_eq!(p.bands[2].hi_rad_s, None);
        assert_eq!(p.temperature.len(), 2);
        assert_eq!((p.temperature[0].lo_c, p.temperature[0].hi_c), (25.0, 30.0));
        assert_eq!(p.temperature_bin(30.0).unwrap().n, 2);
        assert_eq!(p.temperature_bin(30.0).unwrap().mean_residual_nm, Some(0.5));
        assert!(p.temperature_bin(35.0).is_none());
        // The JSON keys (flattened statistics) and a round trip.
        let v = serde_json::to_value(&p).unwrap();
        assert_eq!(v["bands"][0]["mean_residual_nm"], 2.0);
        assert_eq!(v["bands"][2]["hi_rad_s"], serde_json::Value::Null);
        assert_eq!(v["temperature"][1]["lo_c"], 30.0);
        assert_eq!(v["temperature"][1]["n"], 2);
        let back: ResidualProfile = serde_json::from_value(v).unwrap();
        assert_eq!(back.bands, p.bands);
        assert_eq!(back.temperature[1].stats.n, 2);
    }
}
