//! PNG figures of an evaluation (plotters, bitmap backend).
//!
//! What it is: the figures written into a directory —
//! - `<stem>_friction_vs_velocity.png`: the label τ_F against ṡ (evaluated rows, subsampled), the
//!   fitted static models (CV/SCV) as curves and each PINN's predictions as points; velocities outside
//!   the training range shaded;
//! - `<stem>_timeseries.png`: one chunk over time — label, true friction (simulated data) and every
//!   model's τ̂_F; the stretches outside the training range (s or ṡ) shaded;
//! - `<stem>_hysteresis.png`: τ_F against Δθ (latched at the chunk start, as the daemon latches it)
//!   over the same chunk — the pre-sliding loops a history model can exploit;
//! - `drift_<model>.png` (`--drift`): per |ṡ| band (x: band index, labelled in the text output), the
//!   residual RMSE (top) and mean residual along the motion, (label − τ̂_F)·sign(ṡ) (bottom), of the
//!   new log (filled) next to the reference (hollow), the bands whose check fired outlined in red;
//! - `training_curves.png`: every per-epoch number of a `frictl train` report (`epochs[]`), e.g.
//!   train/validation loss, on a log axis when positive.
//!
//! Text (titles, axis labels, legends) needs a TrueType font: plotters is built with its pure-Rust
//! `ab_glyph` renderer only (no fontconfig / system libraries), and [`init_font`] registers the first
//! file found among `$FRICTL_FONT` and common DejaVu/Liberation/Noto paths. Without one, the figures are
//! drawn without any text (the data are still there) and [`init_font`] says so.
//!
//! What it is not: an interactive or vector plotter; the numbers are in the JSON report.

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use plotters::prelude::*;

use super::{DatasetEval, ModelSpec, chunk_ranges};
use frictionless_dataset::{Dataset, MotionRange};

/// Plotting errors (the message names the figure file).
#[derive(Debug, thiserror::Error)]
#[error("plot {path}: {msg}")]
pub struct PlotError {
    /// Figure file.
    pub path: String,
    /// Reason.
    pub msg: String,
}

fn perr(path: &Path, e: impl std::fmt::Display) -> PlotError {
    PlotError {
        path: path.display().to_string(),
        msg: e.to_string(),
    }
}

/// The charts' coordinate system (linear f64 × f64).
type Xy =
    Cartesian2d<plotters::coord::types::RangedCoordf64, plotters::coord::types::RangedCoordf64>;

/// Figure size [px].
const SIZE: (u32, u32) = (1200, 800);
/// Largest number of scatter points per series.
const MAX_POINTS: usize = 20_000;

/// Font files tried in order after `$FRICTL_FONT`.
const FONT_CANDIDATES: &[&str] = &[
    "/usr/share/fonts/truetype/dejavu/DejaVuSans.ttf",
    "/usr/share/fonts/TTF/DejaVuSans.ttf",
    "/usr/share/fonts/dejavu/DejaVuSans.ttf",
    "/usr/share/fonts/dejavu-sans-fonts/DejaVuSans.ttf",
    "/usr/share/fonts/truetype/liberation/LiberationSans-Regular.ttf",
    "/usr/share/fonts/liberation-sans/LiberationSans-Regular.ttf",
    "/usr/share/fonts/truetype/noto/NotoSans-Regular.ttf",
    "/usr/share/fonts/noto/NotoSans-Regular.ttf",
    "/Library/Fonts/Arial.ttf",
];

static FONT: OnceLock<Option<PathBuf>> = OnceLock::new();

/// Registers a TrueType font for the figures' text (once per process); returns its path, or None
/// when no font was found (figures are then drawn without text).
pub fn init_font() -> Option<PathBuf> {
    FONT.get_or_init(|| {
        let env = std::env::var_os("FRICTL_FONT").map(PathBuf::from);
        let candidates = env
            .into_iter()
            .chain(FONT_CANDIDATES.iter().map(PathBuf::from));
        for p in candidates {
            let Ok(bytes) = std::fs::read(&p) else {
                continue;
            };
            // plotters keeps a 'static reference to the font; the bytes live for the process.
            let bytes: &'static [u8] = Box::leak(bytes.into_boxed_slice());
            if plotters::style::register_font("sans-serif", FontStyle::Normal, bytes).is_ok() {
                return Some(p);
            }
        }
        None
    })
    .clone()
}

fn has_font() -> bool {
    init_font().is_some()
}

const PALETTE: [RGBColor; 8] = [
    RGBColor(220, 50, 32),
    RGBColor(0, 114, 178),
    RGBColor(0, 158, 115),
    RGBColor(204, 121, 167),
    RGBColor(230, 159, 0),
    RGBColor(86, 180, 233),
    RGBColor(120, 60, 160),
    RGBColor(100, 100, 100),
];

/// Colour of model `i`.
fn color(i: usize) -> RGBColor {
    PALETTE[i % PALETTE.len()]
}

/// Every `ceil(n / max)`-th index of `idx`.
fn subsample(idx: &[usize], max: usize) -> Vec<usize> {
    let step = idx.len().div_ceil(max.max(1)).max(1);
    idx.iter().step_by(step).copied().collect()
}

/// `[lo, hi]` covering the finite values' 0.5–99.5 % quantiles, widened by 8 % (never empty).
fn range(values: impl Iterator<Item = f64>) -> (f64, f64) {
    let mut v: Vec<f64> = values.filter(|x| x.is_finite()).collect();
    if v.is_empty() {
        return (-1.0, 1.0);
    }
    v.sort_by(f64::total_cmp);
    let q = |f: f64| v[((v.len() - 1) as f64 * f).round() as usize];
    let (lo, hi) = (q(0.005), q(0.995));
    let pad = ((hi - lo) * 0.08).max(1e-6);
    (lo - pad, hi + pad)
}

/// Draws a chart frame with title and axis descriptions (text only when a font is registered).
fn chart<'a, DB: DrawingBackend + 'a>(
    root: &'a DrawingArea<DB, plotters::coord::Shift>,
    title: &str,
    x: (f64, f64),
    y: (f64, f64),
    x_desc: &str,
    y_desc: &str,
) -> Result<ChartContext<'a, DB, Xy>, String> {
    let text = has_font();
    let mut b = ChartBuilder::on(root);
    b.margin(16);
    if text {
        b.caption(title, ("sans-serif", 26))
            .x_label_area_size(50)
            .y_label_area_size(70);
    }
    let mut c = b
        .build_cartesian_2d(x.0..x.1, y.0..y.1)
        .map_err(|e| e.to_string())?;
    let mut mesh = c.configure_mesh();
    if text {
        mesh.x_desc(x_desc)
            .y_desc(y_desc)
            .label_style(("sans-serif", 16));
    } else {
        mesh.x_labels(0).y_labels(0);
    }
    mesh.draw().map_err(|e| e.to_string())?;
    Ok(c)
}

fn legend<'a, DB: DrawingBackend + 'a>(c: &mut ChartContext<'a, DB, Xy>) -> Result<(), String> {
    if has_font() {
        c.configure_series_labels()
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .label_font(("sans-serif", 18))
            .position(SeriesLabelPosition::UpperLeft)
            .draw()
            .map_err(|e| e.to_string())?;
    }
    Ok(())
}

/// Shading of extrapolation (rows outside the training range).
const EXTRAPOLATION: RGBColor = RGBColor(240, 80, 60);

/// Friction against velocity: label scatter, static-model curves, PINN points; the velocities outside
/// the training range (`range`) shaded.
pub fn friction_vs_velocity(
    path: &Path,
    ds: &Dataset,
    ev: &DatasetEval,
    models: &[ModelSpec],
    training_range: Option<&MotionRange>,
) -> Result<(), PlotError> {
    let idx: Vec<usize> = (0..ds.len()).filter(|&k| ev.mask[k]).collect();
    let pts = subsample(&idx, MAX_POINTS);
    let xr = range(pts.iter().map(|&k| ds.sdot_rad_s[k]));
    let yr = range(pts.iter().map(|&k| ds.tau_f_label_nm[k]));
    // Drawn to a temporary file beside `path` and renamed over it (frictionless::output_file).
    let draw = |tmp: &Path| -> Result<(), String> {
        let root = BitMapBackend::new(tmp, SIZE).into_drawing_area();
        root.fill(&WHITE).map_err(|e| e.to_string())?;
        let mut c = chart(
            &root,
            "friction vs joint velocity",
            xr,
            yr,
            "joint velocity [rad/s]",
            "friction torque [Nm]",
        )?;
        if let Some(r) = training_range {
            let shade = EXTRAPOLATION.mix(0.12).filled();
            let spans = [
                (xr.0, r.sdot_rad_s[0].min(xr.1)),
                (r.sdot_rad_s[1].max(xr.0), xr.1),
            ];
            c.draw_series(
                spans
                    .into_iter()
                    .filter(|(a, b)| a < b)
                    .map(|(a, b)| Rectangle::new([(a, yr.0), (b, yr.1)], shade)),
            )
            .map_err(|e| e.to_string())?
            .label("outside the training range")
            .legend(|(x, y)| {
                Rectangle::new(
                    [(x, y - 5), (x + 20, y + 5)],
                    EXTRAPOLATION.mix(0.3).filled(),
                )
            });
        }
        let grey = RGBColor(60, 60, 60).mix(0.25);
        c.draw_series(
            pts.iter()
                .map(|&k| Circle::new((ds.sdot_rad_s[k], ds.tau_f_label_nm[k]), 1, grey.filled())),
        )
        .map_err(|e| e.to_string())?
        .label("label")
        .legend(|(x, y)| Circle::new((x + 10, y), 3, RGBColor(60, 60, 60).filled()));
        let ppts = subsample(&idx, MAX_POINTS / 4);
        for (i, m) in models.iter().enumerate() {
            let col = color(i);
            if m.name == "none" {
                continue;
            }
            if m.is_static() {
                let n = 800;
                let curve: Vec<(f64, f64)> = (0..=n)
                    .map(|j| {
                        let v = xr.0 + (xr.1 - xr.0) * j as f64 / n as f64;
                        let mut mm = m.model.clone();
                        use frictionless::model::FrictionModel;
                        let t = mm.estimate(&frictionless::features::JointSample {
                            sdot_rad_s: v,
                            ..Default::default()
                        });
                        (v, t)
                    })
                    .collect();
                c.draw_series(LineSeries::new(curve, col.stroke_width(3)))
                    .map_err(|e| e.to_string())?
                    .label(m.name.as_str())
                    .legend(move |(x, y)| {
                        PathElement::new(vec![(x, y), (x + 20, y)], col.stroke_width(3))
                    });
            } else {
                let p = &ev.predictions[i];
                c.draw_series(
                    ppts.iter()
                        .map(|&k| Circle::new((ds.sdot_rad_s[k], p[k]), 1, col.mix(0.5).filled())),
                )
                .map_err(|e| e.to_string())?
                .label(m.name.as_str())
                .legend(move |(x, y)| Circle::new((x + 10, y), 3, col.filled()));
            }
        }
        legend(&mut c)?;
        root.present().map_err(|e| e.to_string())
    };
    frictionless::output_file::write_by_path(path, draw).map_err(|e| perr(path, e))
}

/// The drift figure of one model: per |ṡ| band, RMSE (top panel) and mean residual along the motion
/// (bottom panel),
/// new log filled, reference hollow; a band whose check fired is outlined in red.
pub fn drift_bands(path: &Path, m: &super::drift::ModelDrift) -> Result<(), PlotError> {
    let n = m.new.bands.len();
    let reference = |j: usize| {
        m.reference
            .as_ref()
            .and_then(|r| r.bands.get(j))
            .map(|b| b.stats)
    };
    let fired = |j: usize| {
        let b = &m.new.bands[j];
        let hi = b.hi_rad_s.map_or_else(|| "inf".into(), |h| h.to_string());
        let what = format!("band [{}, {hi}) rad/s", b.lo_rad_s);
        m.checks.iter().any(|c| c.fired && c.what == what)
    };
    // Drawn to a temporary file beside `path` and renamed over it (frictionless::output_file).
    let draw = |tmp: &Path| -> Result<(), String> {
        let root = BitMapBackend::new(tmp, SIZE).into_drawing_area();
        root.fill(&WHITE).map_err(|e| e.to_string())?;
        let (top, bottom) = root.split_vertically(SIZE.1 / 2);
        type Pick = fn(&frictionless_dataset::bands::ResidualStats) -> Option<f64>;
        let panels: [(&DrawingArea<_, _>, &str, &str, Pick); 2] = [
            (&top, "residual RMSE per |sdot| band", "RMSE [Nm]", |s| {
                s.rmse_nm
            }),
            (
                &bottom,
                "mean of (label - prediction)·sign(sdot) per |sdot| band",
                "mean along the motion [Nm]",
                |s| s.mean_along_motion_nm,
            ),
        ];
        for (area, title, ydesc, pick) in panels {
            let vals: Vec<f64> = (0..n)
                .flat_map(|j| {
                    [
                        pick(&m.new.bands[j].stats),
                        reference(j).and_then(|s| pick(&s)),
                    ]
                })
                .flatten()
                .collect();
            let lo = vals.iter().copied().fold(0.0f64, f64::min);
            let hi = vals.iter().copied().fold(0.0f64, f64::max);
            let pad = ((hi - lo) * 0.1).max(1e-3);
            let title = format!("{}: {} ({})", m.model, title, m.verdict);
            let mut c = chart(
                area,
                &title,
                (-0.5, n as f64 - 0.5),
                (lo - pad, hi + pad),
                "|sdot| band index (edges in the text output)",
                ydesc,
            )?;
            let new_col = color(1);
            let ref_col = RGBColor(60, 60, 60);
            c.draw_series((0..n).filter_map(|j| {
                pick(&m.new.bands[j].stats).map(|v| {
                    let x = j as f64;
                    Rectangle::new([(x - 0.38, 0.0), (x - 0.02, v)], new_col.filled())
                })
            }))
            .map_err(|e| e.to_string())?
            .label("new log")
            .legend(move |(x, y)| Rectangle::new([(x, y - 5), (x + 20, y + 5)], new_col.filled()));
            c.draw_series((0..n).filter_map(|j| {
                reference(j).and_then(|s| pick(&s)).map(|v| {
                    let x = j as f64;
                    Rectangle::new([(x + 0.02, 0.0), (x + 0.38, v)], ref_col.stroke_width(2))
                })
            }))
            .map_err(|e| e.to_string())?
            .label("reference")
            .legend(move |(x, y)| {
                Rectangle::new([(x, y - 5), (x + 20, y + 5)], ref_col.stroke_width(2))
            });
            c.draw_series((0..n).filter(|&j| fired(j)).map(|j| {
                let x = j as f64;
                Rectangle::new(
                    [(x - 0.45, lo - pad * 0.5), (x + 0.45, hi + pad * 0.5)],
                    EXTRAPOLATION.stroke_width(2),
                )
            }))
            .map_err(|e| e.to_string())?;
            legend(&mut c)?;
        }
        root.present().map_err(|e| e.to_string())
    };
    frictionless::output_file::write_by_path(path, draw).map_err(|e| perr(path, e))
}

/// The chunk to show: `requested` if it exists in the dataset, else the one with the most evaluated
/// sliding rows.
pub fn pick_chunk(
    ds: &Dataset,
    ev: &DatasetEval,
    v_sliding: f64,
    requested: Option<u32>,
) -> Option<(usize, usize)> {
    let ranges = chunk_ranges(ds);
    if let Some(c) = requested
        && let Some(r) = ranges.iter().find(|(a, _)| ds.chunk[*a] == c)
    {
        return Some(*r);
    }
    ranges
        .into_iter()
        .map(|(a, b)| {
            let n = (a..b)
                .filter(|&k| ev.mask[k] && ds.sdot_rad_s[k].abs() > v_sliding)
                .count();
            (n, a, b)
        })
        .max_by_key(|&(n, a, _)| (n, std::cmp::Reverse(a)))
        .filter(|&(n, _, _)| n > 0)
        .map(|(_, a, b)| (a, b))
}

/// Time series of one chunk `[a, b)`: label, truth and every model; rows with `extrapolated[k]`
/// (outside the training range) shaded.
pub fn timeseries(
    path: &Path,
    ds: &Dataset,
    ev: &DatasetEval,
    models: &[ModelSpec],
    (a, b): (usize, usize),
    extrapolated: &[bool],
) -> Result<(), PlotError> {
    let t0 = ds.time_s[a];
    let mut ys: Vec<f64> = ds.tau_f_label_nm[a..b].to_vec();
    if let Some(t) = &ds.tau_f_true_nm {
        ys.extend_from_slice(&t[a..b]);
    }
    for p in &ev.predictions {
        ys.extend_from_slice(&p[a..b]);
    }
    let yr = range(ys.into_iter());
    let xr = (0.0, (ds.time_s[b - 1] - t0).max(1e-3));
    // Drawn to a temporary file beside `path` and renamed over it (frictionless::output_file).
    let draw = |tmp: &Path| -> Result<(), String> {
        let root = BitMapBackend::new(tmp, SIZE).into_drawing_area();
        root.fill(&WHITE).map_err(|e| e.to_string())?;
        let mut c = chart(
            &root,
            &format!("chunk {}: friction over time", ds.chunk[a]),
            xr,
            yr,
            "time in chunk [s]",
            "friction torque [Nm]",
        )?;
        // Runs of consecutive extrapolated rows as shaded spans.
        let mut spans = Vec::new();
        let mut k = a;
        while k < b {
            if extrapolated.get(k).copied().unwrap_or(false) {
                let start = k;
                while k < b && extrapolated.get(k).copied().unwrap_or(false) {
                    k += 1;
                }
                let end = ds.time_s[(k).min(b - 1)];
                spans.push((ds.time_s[start] - t0, end - t0));
            } else {
                k += 1;
            }
        }
        if !spans.is_empty() {
            let shade = EXTRAPOLATION.mix(0.12).filled();
            c.draw_series(
                spans
                    .into_iter()
                    .map(|(x0, x1)| Rectangle::new([(x0, yr.0), (x1.max(x0 + 1e-3), yr.1)], shade)),
            )
            .map_err(|e| e.to_string())?
            .label("outside the training range")
            .legend(|(x, y)| {
                Rectangle::new(
                    [(x, y - 5), (x + 20, y + 5)],
                    EXTRAPOLATION.mix(0.3).filled(),
                )
            });
        }
        let line =
            |v: &[f64]| -> Vec<(f64, f64)> { (a..b).map(|k| (ds.time_s[k] - t0, v[k])).collect() };
        let dark = RGBColor(40, 40, 40);
        c.draw_series(LineSeries::new(
            line(&ds.tau_f_label_nm),
            dark.stroke_width(2),
        ))
        .map_err(|e| e.to_string())?
        .label("label")
        .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], dark.stroke_width(2)));
        if let Some(t) = &ds.tau_f_true_nm {
            let g = RGBColor(150, 150, 150);
            c.draw_series(LineSeries::new(line(t), g.stroke_width(2)))
                .map_err(|e| e.to_string())?
                .label("true")
                .legend(move |(x, y)| {
                    PathElement::new(vec![(x, y), (x + 20, y)], g.stroke_width(2))
                });
        }
        for (i, m) in models.iter().enumerate() {
            if m.name == "none" {
                continue;
            }
            let col = color(i);
            c.draw_series(LineSeries::new(
                line(&ev.predictions[i]),
                col.stroke_width(2),
            ))
            .map_err(|e| e.to_string())?
            .label(m.name.as_str())
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], col.stroke_width(2)));
        }
        legend(&mut c)?;
        root.present().map_err(|e| e.to_string())
    };
    frictionless::output_file::write_by_path(path, draw).map_err(|e| perr(path, e))
}

/// Δθ–τ_F hysteresis over one chunk (Δθ latched at the chunk start).
pub fn hysteresis(path: &Path, ds: &Dataset, (a, b): (usize, usize)) -> Result<(), PlotError> {
    let d0 = ds.delta_theta_motor_rad[a];
    let dth: Vec<f64> = (a..b).map(|k| ds.delta_theta_motor_rad[k] - d0).collect();
    let xr = range(dth.iter().copied());
    let mut ys = ds.tau_f_label_nm[a..b].to_vec();
    if let Some(t) = &ds.tau_f_true_nm {
        ys.extend_from_slice(&t[a..b]);
    }
    let yr = range(ys.into_iter());
    // Drawn to a temporary file beside `path` and renamed over it (frictionless::output_file).
    let draw = |tmp: &Path| -> Result<(), String> {
        let root = BitMapBackend::new(tmp, SIZE).into_drawing_area();
        root.fill(&WHITE).map_err(|e| e.to_string())?;
        let mut c = chart(
            &root,
            &format!("chunk {}: friction vs transmission deflection", ds.chunk[a]),
            xr,
            yr,
            "delta theta = r*s - theta (latched at chunk start) [motor rad]",
            "friction torque [Nm]",
        )?;
        let dark = RGBColor(40, 40, 40);
        c.draw_series(LineSeries::new(
            dth.iter()
                .zip(&ds.tau_f_label_nm[a..b])
                .map(|(&x, &y)| (x, y)),
            dark.stroke_width(1),
        ))
        .map_err(|e| e.to_string())?
        .label("label")
        .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], dark.stroke_width(2)));
        if let Some(t) = &ds.tau_f_true_nm {
            let col = color(0);
            c.draw_series(LineSeries::new(
                dth.iter().zip(&t[a..b]).map(|(&x, &y)| (x, y)),
                col.stroke_width(1),
            ))
            .map_err(|e| e.to_string())?
            .label("true")
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], col.stroke_width(2)));
        }
        legend(&mut c)?;
        root.present().map_err(|e| e.to_string())
    };
    frictionless::output_file::write_by_path(path, draw).map_err(|e| perr(path, e))
}

/// Per-epoch numeric series of a train report: every numeric key of `epochs[]` except `epoch`,
/// `seconds` and booleans, in first-seen order, as (name, [(epoch, value)]).
pub fn training_series(report: &serde_json::Value) -> Vec<(String, Vec<(f64, f64)>)> {
    let mut out: Vec<(String, Vec<(f64, f64)>)> = Vec::new();
    let Some(epochs) = report.get("epochs").and_then(serde_json::Value::as_array) else {
        return out;
    };
    for (i, e) in epochs.iter().enumerate() {
        let Some(obj) = e.as_object() else { continue };
        let ep = obj
            .get("epoch")
            .and_then(serde_json::Value::as_f64)
            .unwrap_or((i + 1) as f64);
        for (k, v) in obj {
            if k == "epoch" || k == "seconds" {
                continue;
            }
            let Some(x) = v.as_f64() else { continue };
            if !x.is_finite() {
                continue;
            }
            match out.iter_mut().find(|(n, _)| n == k) {
                Some((_, s)) => s.push((ep, x)),
                None => out.push((k.clone(), vec![(ep, x)])),
            }
        }
    }
    out
}

/// Training curves from a train report (tolerant: plots whatever per-epoch numbers exist).
pub fn training_curves(path: &Path, report: &serde_json::Value) -> Result<(), PlotError> {
    let series = training_series(report);
    if series.is_empty() {
        return Err(perr(
            path,
            "the train report has no numeric per-epoch values in `epochs[]`",
        ));
    }
    let all = series.iter().flat_map(|(_, s)| s.iter());
    let (mut x0, mut x1, mut y0, mut y1) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
    for &(x, y) in all {
        x0 = x0.min(x);
        x1 = x1.max(x);
        y0 = y0.min(y);
        y1 = y1.max(y);
    }
    if x1 <= x0 {
        x1 = x0 + 1.0;
    }
    let log = y0 > 0.0;
    // Drawn to a temporary file beside `path` and renamed over it (frictionless::output_file).
    let draw = |tmp: &Path| -> Result<(), String> {
        let root = BitMapBackend::new(tmp, SIZE).into_drawing_area();
        root.fill(&WHITE).map_err(|e| e.to_string())?;
        // A log axis is drawn as log10 of the values on a linear axis (keeps one chart type).
        let tf = |y: f64| if log { y.log10() } else { y };
        let (ly0, ly1) = (tf(y0), tf(y1));
        let pad = ((ly1 - ly0) * 0.05).max(1e-6);
        let mut c = chart(
            &root,
            "training curves",
            (x0, x1),
            (ly0 - pad, ly1 + pad),
            "epoch",
            if log {
                "log10(value)  (loss [Nm^2], RMSE [Nm])"
            } else {
                "value (loss [Nm^2], RMSE [Nm])"
            },
        )?;
        for (i, (name, s)) in series.iter().enumerate() {
            let col = color(i);
            c.draw_series(LineSeries::new(
                s.iter().map(|&(x, y)| (x, tf(y))),
                col.stroke_width(2),
            ))
            .map_err(|e| e.to_string())?
            .label(name.as_str())
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], col.stroke_width(2)));
        }
        legend(&mut c)?;
        root.present().map_err(|e| e.to_string())
    };
    frictionless::output_file::write_by_path(path, draw).map_err(|e| perr(path, e))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn training_series_is_tolerant() {
        let r = serde_json::json!({"epochs": [
            {"epoch": 1, "train_loss": 2.0, "val_loss": null, "is_best": true, "seconds": 0.1},
            {"epoch": 2, "train_loss": 1.0, "val_loss": 1.5, "extra": "x"},
        ]});
        let s = training_series(&r);
        assert_eq!(s.len(), 2);
        assert_eq!(
            s[0],
            ("train_loss".to_string(), vec![(1.0, 2.0), (2.0, 1.0)])
        );
        assert_eq!(s[1], ("val_loss".to_string(), vec![(2.0, 1.5)]));
        assert!(training_series(&serde_json::json!({})).is_empty());
    }

    #[test]
    fn subsample_and_range() {
        let idx: Vec<usize> = (0..100).collect();
        assert_eq!(subsample(&idx, 10).len(), 10);
        assert_eq!(subsample(&idx, 1000).len(), 100);
        let (lo, hi) = range((0..=1000).map(f64::from));
        assert!(lo < 5.0 && hi > 995.0 && hi < 1100.0);
        assert_eq!(range(std::iter::empty()), (-1.0, 1.0));
    }
}
