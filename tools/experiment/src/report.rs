//! Tables (markdown, laid out like the paper's), JSON and trace files of an experiment suite.
//!
//! What this module **is**: [`SuiteReport`] collects the results of [`super::suite`] per joint and
//! model, renders the paper's tables ([`SuiteReport::markdown`]: minimum K_p; tracking and friction
//! estimate at the own minimum K_p; disturbance return at the own K_p and at the PINN's K_p for all)
//! and writes per-trial traces as CSV (PlotJuggler/pandas) and, when asked, PNG plots.
//!
//! What it is **not**: no trial execution.

use std::collections::BTreeMap;
use std::io::Write;
use std::path::Path;

use super::ExperimentError;
use super::metrics::{DisturbanceMetrics, TrackCriterion, TrackMetrics};
use super::run::{JointTrace, Pulse};
use super::search::{MinKp, sig3};
use super::session::ORACLE_LABEL;
use super::suite::{DisturbanceResult, MinKpResult, SearchStep, TrackResult};

/// Model column order of every table (the oracle column only appears when it ran).
pub const MODEL_ORDER: [&str; 5] = ["none", "CV", "SCV", "PINN", ORACLE_LABEL];

/// Everything measured for one (joint, model).
#[derive(Clone, Debug, Default, serde::Serialize, serde::Deserialize)]
pub struct Cell {
    /// Minimum K_p search result.
    pub min_kp: Option<MinKp>,
    /// Trials of the search.
    pub search: Vec<SearchStep>,
    /// Tracking at the minimum K_p.
    pub track_at_min_kp: Option<TrackMetrics>,
    /// Tracking at a given K_p (`frictl experiment track`).
    pub track: Option<(f64, TrackMetrics)>,
    /// Tracking at the common low K_p (the PINN's).
    pub track_at_low_kp: Option<(f64, TrackMetrics)>,
    /// Disturbance at the own minimum K_p: (K_p, metrics).
    pub disturbance_own_kp: Option<(f64, DisturbanceMetrics)>,
    /// Disturbance at the common low K_p.
    pub disturbance_low_kp: Option<(f64, DisturbanceMetrics)>,
}

/// Results of a suite, keyed by joint name then model label.
#[derive(Clone, Debug, Default, serde::Serialize, serde::Deserialize)]
pub struct SuiteReport {
    /// `lockstep` or `realtime`.
    pub mode: String,
    /// Plant seed.
    pub seed: u64,
    /// Tracking criterion of the K_p search.
    pub criterion: Option<TrackCriterion>,
    /// K_d [1/s].
    pub kd_per_s: f64,
    /// Reference description per joint.
    pub references: BTreeMap<String, String>,
    /// frictiond's friction-compensation law per joint (kfc, clip, τ̂_F LPF).
    pub configuration: BTreeMap<String, String>,
    /// Disturbance pulse per joint.
    pub pulses: BTreeMap<String, Pulse>,
    /// Where the common low K_p came from per joint (normally "PINN").
    pub low_kp_source: BTreeMap<String, String>,
    /// joint → model → cell.
    pub joints: BTreeMap<String, BTreeMap<String, Cell>>,
    /// Wall-clock seconds of the suite.
    pub wall_s: f64,
    /// Trials run.
    pub trials: usize,
}

fn fmt_opt(v: Option<f64>, digits: usize) -> String {
    match v {
        Some(x) if x.is_finite() => format!("{x:.digits$}"),
        _ => "–".into(),
    }
}

impl SuiteReport {
    /// The cell of (joint, model), created if missing.
    pub fn cell(&mut self, joint: &str, model: &str) -> &mut Cell {
        self.joints
            .entry(joint.to_owned())
            .or_default()
            .entry(model.to_owned())
            .or_default()
    }

    /// Stores min-K_p results.
    pub fn add_min_kp(&mut self, names: &[String; 2], rs: &[MinKpResult]) {
        for r in rs {
            let c = self.cell(&names[r.index], &r.model);
            c.min_kp = Some(r.min_kp);
            c.search = r.steps.clone();
            c.track_at_min_kp = r.at_min.as_ref().map(|t| t.metrics);
        }
    }

    /// Stores tracking results; `low` = at the common low K_p.
    pub fn add_track(&mut self, names: &[String; 2], rs: &[TrackResult], low: bool) {
        for r in rs {
            let c = self.cell(&names[r.index], &r.model);
            let v = Some((r.kp_per_s2, r.metrics));
            if low {
                c.track_at_low_kp = v;
            } else {
                c.track = v;
            }
        }
    }

    /// Stores disturbance results; `low` = at the common low K_p.
    pub fn add_disturbance(&mut self, names: &[String; 2], rs: &[DisturbanceResult], low: bool) {
        for r in rs {
            let c = self.cell(&names[r.index], &r.model);
            let v = Some((r.kp_per_s2, r.metrics));
            if low {
                c.disturbance_low_kp = v;
            } else {
                c.disturbance_own_kp = v;
            }
        }
    }

    fn models_of(&self, joint: &str) -> Vec<&'static str> {
        let m = &self.joints[joint];
        MODEL_ORDER
            .iter()
            .copied()
            .filter(|k| m.contains_key(*k))
            .collect()
    }

    /// Table columns: none, CV, SCV, PINN, and the oracle if any joint ran it.
    fn columns(&self) -> Vec<&'static str> {
        let oracle = self.joints.values().any(|m| m.contains_key(ORACLE_LABEL));
        MODEL_ORDER
            .iter()
            .copied()
            .filter(|k| *k != ORACLE_LABEL || oracle)
            .collect()
    }

    /// `| joint | none | CV | SCV | PINN |` (plus the oracle) and its separator row.
    fn header(&self) -> String {
        let cols = self.columns();
        format!(
            "| joint | {} |\n|---|{}\n",
            cols.join(" | "),
            "---|".repeat(cols.len())
        )
    }

    /// The tables as markdown.
    pub fn markdown(&self) -> String {
        let mut s = String::new();
        let crit = self.criterion.map_or(String::new(), |c| {
            format!(
                "tracking RMSE ≤ {:.0} % of the sine amplitude, evaluated after the first {} period(s)",
                100.0 * c.frac_of_amplitude,
                c.skip_periods
            )
        });
        s += &format!(
            "Closed-loop experiments on the virtual joints ({} mode, seed {}, K_d = {} 1/s; K_p in 1/s² on the acceleration set-point).\n\n",
            self.mode, self.seed, self.kd_per_s
        );
        for (j, r) in &self.references {
            s += &format!("- {j}: {r}");
            if let Some(p) = self.pulses.get(j) {
                s += &format!(
                    "; disturbance {} Nm from {} s for {} s",
                    p.torque_nm, p.start_s, p.duration_s
                );
            }
            s += "\n";
        }
        for (j, c) in &self.configuration {
            s += &format!("- {j} frictiond law: {c}\n");
        }
        let any = |f: &dyn Fn(&Cell) -> bool| self.joints.values().any(|m| m.values().any(f));
        if any(&|c| c.min_kp.is_some()) {
            s += &self.min_kp_md(&crit);
        }
        s += &self.fixed_kp_md();
        s += &format!(
            "\n{} trials, {:.1} s wall clock.\n",
            self.trials, self.wall_s
        );
        s
    }

    /// The minimum-K_p table and the metrics at each model's minimum K_p (`crit`: the criterion).
    fn min_kp_md(&self, crit: &str) -> String {
        let mut s = String::new();
        s += &format!(
            "\n**Minimum K_p that tracks the sine** ({crit}; paper: ankle roll 13000 / 1000 / 900 / 550, knee 1000 / 100 / 70 / 30)\n\n"
        );
        s += &self.header();
        for (j, m) in &self.joints {
            s += &format!("| {j} |");
            for k in self.columns() {
                let v = m
                    .get(k)
                    .and_then(|c| c.min_kp)
                    .map_or("–".into(), |x| x.display());
                s += &format!(" {v} |");
            }
            s += "\n";
        }
        s += "\n**At each model's minimum K_p**: tracking RMSE [rad], friction estimate τ̂_F/kfc vs true friction RMSE [Nm], friction left uncompensated (RMS) [Nm]\n\n";
        s += "| joint | model | K_p | tracking RMSE | τ̂_F RMSE | residual friction |\n|---|---|---|---|---|---|\n";
        for (j, m) in &self.joints {
            for k in self.models_of(j) {
                let c = &m[k];
                if let (Some(kp), Some(t)) = (c.min_kp, c.track_at_min_kp) {
                    s += &format!(
                        "| {j} | {k} | {} | {:.4} | {} | {:.3} |\n",
                        kp.display(),
                        t.rmse_rad,
                        fmt_opt(Some(t.friction_est_rmse_nm), 3),
                        t.residual_friction_rms_nm
                    );
                }
            }
        }
        s
    }

    /// The tables of the trials at a fixed K_p: sine tracking at the given one, the disturbance at
    /// each model's own and at the common low one, and tracking at the low one.
    fn fixed_kp_md(&self) -> String {
        let mut s = String::new();
        let any = |f: &dyn Fn(&Cell) -> bool| self.joints.values().any(|m| m.values().any(f));
        if any(&|c| c.track.is_some()) {
            s += "\n**Sine tracking at the given K_p**\n\n| joint | model | K_p | tracking RMSE [rad] | max error [rad] | τ̂_F RMSE [Nm] | residual friction [Nm] | τ_des RMS [Nm] |\n|---|---|---|---|---|---|---|---|\n";
            for (j, m) in &self.joints {
                for k in self.models_of(j) {
                    if let Some((kp, t)) = m[k].track {
                        s += &format!(
                            "| {j} | {k} | {} | {:.4} | {:.4} | {} | {:.3} | {:.3} |\n",
                            sig3(kp),
                            t.rmse_rad,
                            t.max_abs_err_rad,
                            fmt_opt(Some(t.friction_est_rmse_nm), 3),
                            t.residual_friction_rms_nm,
                            t.tau_des_rms_nm
                        );
                    }
                }
            }
        }
        if any(&|c| c.disturbance_own_kp.is_some()) {
            s += "\n**Disturbance at each model's own K_p** (paper Tables III/IV): position RMSE after release [rad]\n\n";
            s += &self.header();
            s += &self.row_table(|c| c.disturbance_own_kp);
        }
        if any(&|c| c.disturbance_low_kp.is_some()) {
            let src: Vec<String> = self
                .low_kp_source
                .iter()
                .map(|(j, w)| format!("{j}: {w}"))
                .collect();
            s += &format!(
                "\n**Disturbance at the same low K_p for all** (paper Table V; K_p from {}): position RMSE after release [rad] (paper: ankle roll 0.19 / 0.2 / 0.21 / 0.046, knee 0.21 / 0.11 / 0.097 / 0.017)\n\n",
                src.join(", ")
            );
            s += &self.header();
            s += &self.row_table(|c| c.disturbance_low_kp);
        }
        if any(&|c| c.track_at_low_kp.is_some()) {
            s += "\n**Sine tracking at the same low K_p**: tracking RMSE [rad]\n\n";
            s += &self.header();
            for (j, m) in &self.joints {
                s += &format!("| {j} |");
                for k in self.columns() {
                    let v = m
                        .get(k)
                        .and_then(|c| c.track_at_low_kp)
                        .map_or("–".into(), |(kp, t)| {
                            format!("{:.4} (K_p {})", t.rmse_rad, sig3(kp))
                        });
                    s += &format!(" {v} |");
                }
                s += "\n";
            }
        }
        s
    }

    fn row_table(&self, f: impl Fn(&Cell) -> Option<(f64, DisturbanceMetrics)>) -> String {
        let mut s = String::new();
        for (j, m) in &self.joints {
            s += &format!("| {j} |");
            for k in self.columns() {
                let v = m.get(k).and_then(&f).map_or("–".into(), |(kp, d)| {
                    format!(
                        "{:.4} (K_p {}, max {:.3})",
                        d.rmse_after_release_rad,
                        sig3(kp),
                        d.max_deflection_rad
                    )
                });
                s += &format!(" {v} |");
            }
            s += "\n";
        }
        s
    }
}

/// Writes a trace as CSV (`t_s,s_des_rad,s_rad,s_true_rad,tau_des_nm,tau_f_hat_nm,tau_f_true_nm,i_applied_a,tau_ext_nm,flags,sdot_rad_s,sdot_true_rad_s,theta_motor_rad,omega_motor_rad_s`).
pub fn write_trace_csv(path: &Path, tr: &JointTrace) -> Result<(), ExperimentError> {
    let mut w = frictionless::output_file::AtomicFile::create(path).map_err(|source| {
        ExperimentError::Create {
            path: path.to_owned(),
            source,
        }
    })?;
    writeln!(
        w,
        "t_s,s_des_rad,s_rad,s_true_rad,tau_des_nm,tau_f_hat_nm,tau_f_true_nm,i_applied_a,tau_ext_nm,flags,\
         sdot_rad_s,sdot_true_rad_s,theta_motor_rad,omega_motor_rad_s"
    )?;
    let at = |v: &[f64], i: usize| v.get(i).copied().unwrap_or(f64::NAN);
    for i in 0..tr.t_s.len() {
        writeln!(
            w,
            "{:.3},{:.6e},{:.6e},{:.6e},{:.6e},{:.6e},{:.6e},{:.6e},{:.6e},{},{:.9e},{:.9e},{:.12e},{:.9e}",
            tr.t_s[i],
            tr.s_des_rad[i],
            tr.s_rad[i],
            tr.s_true_rad[i],
            tr.tau_des_nm[i],
            tr.tau_f_hat_nm[i],
            tr.tau_f_true_nm[i],
            tr.i_applied_a[i],
            tr.tau_ext_nm[i],
            tr.flags[i],
            at(&tr.sdot_rad_s, i),
            at(&tr.sdot_true_rad_s, i),
            at(&tr.theta_motor_rad, i),
            at(&tr.omega_motor_rad_s, i),
        )?;
    }
    w.commit()?;
    Ok(())
}

/// Writes one PNG per trace to `out/plots/<name>.png`: three stacked panels over time — position
/// (s_d and s), friction (τ̂_F as applied by frictiond, and the true τ_F; τ_ext when a disturbance
/// acted) and τ_des. Text needs a font (see `frictionless_eval::plot::init_font`); without one the
/// curves are drawn without labels.
pub fn write_plots(out: &Path, traces: &[(String, JointTrace)]) -> Result<(), ExperimentError> {
    use plotters::prelude::*;
    if traces.is_empty() {
        return Ok(());
    }
    let dir = out.join("plots");
    std::fs::create_dir_all(&dir).map_err(|source| ExperimentError::Create {
        path: dir.clone(),
        source,
    })?;
    let font = frictionless_eval::plot::init_font().is_some();
    for (name, tr) in traces {
        if tr.t_s.len() < 2 {
            continue;
        }
        let path = dir.join(format!("{}.png", slug(name)));
        let perr = |e: &dyn std::fmt::Display| ExperimentError::Plot {
            path: path.clone(),
            reason: e.to_string(),
        };
        // Drawn to a temporary file beside `path` and renamed over it (frictionless::output_file).
        let draw = |tmp: &Path| -> Result<(), ExperimentError> {
            let root = BitMapBackend::new(tmp, (1200, 900)).into_drawing_area();
            root.fill(&WHITE).map_err(|e| perr(&e))?;
            let panels = root.split_evenly((3, 1));
            let t0 = tr.t_s[0];
            let t1 = *tr.t_s.last().expect("len ≥ 2");
            // stride so at most ~4000 points per series
            let stride = (tr.t_s.len() / 4000).max(1);
            type Series<'a> = (&'a str, &'a [f64], RGBColor);
            let f_hat_label = if tr.model == ORACLE_LABEL {
                format!("kfc·τ_F,true added to τ_des (oracle, kfc {})", tr.kfc)
            } else {
                format!("τ̂_F (frictiond, {}, kfc {})", tr.model, tr.kfc)
            };
            let title0 = format!("{} — {} — K_p {} 1/s²", name, tr.name, sig3(tr.kp_per_s2));
            let specs: [(String, &str, Vec<Series>); 3] = [
                (
                    title0,
                    "s [rad]",
                    vec![
                        ("s_d", &tr.s_des_rad[..], BLACK),
                        ("s (measured)", &tr.s_rad[..], BLUE),
                    ],
                ),
                (
                    "friction".into(),
                    "torque [Nm]",
                    vec![
                        ("τ_F true", &tr.tau_f_true_nm[..], RED),
                        (f_hat_label.as_str(), &tr.tau_f_hat_nm[..], BLUE),
                        ("τ_ext", &tr.tau_ext_nm[..], GREEN),
                    ],
                ),
                (
                    "desired torque".into(),
                    "τ_des [Nm]",
                    vec![("τ_des", &tr.tau_des_nm[..], MAGENTA)],
                ),
            ];
            for (area, (title, ylabel, series)) in panels.iter().zip(specs.iter()) {
                let panel = Panel {
                    title,
                    ylabel,
                    series,
                };
                draw_panel(area, &panel, &tr.t_s, (t0, t1), stride, font).map_err(|e| perr(&e))?;
            }
            root.present().map_err(|e| perr(&e))?;
            Ok(())
        };
        frictionless::output_file::write_by_path(&path, draw).map_err(|e| perr(&e))?;
    }
    Ok(())
}

/// One panel of a trial's figure: its title, y-axis label and series (label, values, colour).
struct Panel<'a> {
    title: &'a str,
    ylabel: &'a str,
    series: &'a [(&'a str, &'a [f64], plotters::style::RGBColor)],
}

/// Draws `panel` over the times `t_s` (x range `t0`..`t1`, every `stride`-th point) on `area`, with
/// captions, axis labels and legend when a font is available; a panel with no finite value is left
/// blank.
fn draw_panel(
    area: &plotters::drawing::DrawingArea<
        plotters::backend::BitMapBackend<'_>,
        plotters::coord::Shift,
    >,
    panel: &Panel,
    t_s: &[f64],
    (t0, t1): (f64, f64),
    stride: usize,
    font: bool,
) -> Result<(), String> {
    use plotters::prelude::*;
    let Panel {
        title,
        ylabel,
        series,
    } = *panel;
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for (_, ys, _) in series {
        for y in ys.iter().filter(|y| y.is_finite()) {
            lo = lo.min(*y);
            hi = hi.max(*y);
        }
    }
    if !lo.is_finite() {
        return Ok(());
    }
    let pad = ((hi - lo) * 0.05).max(1e-6);
    let mut b = ChartBuilder::on(area);
    b.margin(8).x_label_area_size(30).y_label_area_size(60);
    if font {
        b.caption(title, ("sans-serif", 16));
    }
    let mut chart = b
        .build_cartesian_2d(t0..t1, (lo - pad)..(hi + pad))
        .map_err(|e| e.to_string())?;
    let mut mesh = chart.configure_mesh();
    if font {
        mesh.x_desc("t [s]").y_desc(ylabel);
    } else {
        mesh.disable_x_axis().disable_y_axis();
    }
    mesh.draw().map_err(|e| e.to_string())?;
    for (label, ys, color) in series {
        let pts = t_s
            .iter()
            .zip(ys.iter())
            .step_by(stride)
            .filter(|(_, y)| y.is_finite())
            .map(|(t, y)| (*t, *y));
        let s = chart
            .draw_series(LineSeries::new(pts, color))
            .map_err(|e| e.to_string())?;
        if font {
            let c = *color;
            s.label(*label)
                .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], c));
        }
    }
    if font {
        chart
            .configure_series_labels()
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .draw()
            .map_err(|e| e.to_string())?;
    }
    Ok(())
}

/// File-name-safe lower-case version of `s`.
pub fn slug(s: &str) -> String {
    s.chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() {
                c.to_ascii_lowercase()
            } else {
                '_'
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn markdown_has_one_row_per_joint_and_the_values() {
        let mut r = SuiteReport {
            mode: "lockstep".into(),
            kd_per_s: 4.0,
            criterion: Some(TrackCriterion {
                frac_of_amplitude: 0.1,
                skip_periods: 1.0,
            }),
            ..SuiteReport::default()
        };
        r.cell("l_knee", "none").min_kp = Some(MinKp::Found {
            kp: 1234.5,
            fail_kp: 1000.0,
        });
        r.cell("l_knee", "PINN").min_kp = Some(MinKp::BelowRange { lo: 3.0 });
        r.cell("l_ankle_roll", "SCV").min_kp = Some(MinKp::AboveRange { hi: 30000.0 });
        let md = r.markdown();
        assert!(md.contains("| l_knee | 1230 | – | – | ≤ 3 |"), "{md}");
        assert!(
            md.contains("| l_ankle_roll | – | – | > 30000 | – |"),
            "{md}"
        );
        assert!(md.contains("10 % of the sine amplitude"), "{md}");
        assert!(
            !md.contains("Disturbance"),
            "no disturbance results, no table"
        );
    }
}
