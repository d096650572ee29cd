//! One plausibility report for an import: the numbers a wrong unit or a wrong `--gap-s` leaves in
//! the signals (sample interval against the chunk gap and against plausible rates, position span,
//! velocity magnitudes), each finding with the likely fix. Run on the read runs before the pipeline;
//! a [`Finding`] with `refuse` set means the import would be empty or meaningless.

use crate::{ImportedRun, Role, Unit};

/// Sample intervals of robot logs [s]: 20 kHz … 20 Hz.
const PLAUSIBLE_DT_S: (f64, f64) = (5e-5, 0.05);
/// Faster than this [s] no robot log is sampled (100 kHz): a time unit is wrong.
const MIN_DT_S: f64 = 1e-5;
/// A joint position span above this [rad] (three turns) is not a harmonic-drive joint's range.
const MAX_SPAN_RAD: f64 = 6.0 * std::f64::consts::PI;
/// A joint speed above this [rad/s] (≈ 290 rpm at the joint) is not a harmonic-drive joint's.
const MAX_SPEED_RAD_S: f64 = 30.0;

/// One finding of [`check`].
#[derive(Clone, Debug, PartialEq)]
pub struct Finding {
    /// The import must be refused (it would be empty or meaningless), not only warned about.
    pub refuse: bool,
    /// What was seen, with the numbers and the likely fix.
    pub message: String,
}

fn median(mut v: Vec<f64>) -> Option<f64> {
    if v.is_empty() {
        return None;
    }
    let mid = v.len() / 2;
    let (_, m, _) = v.select_nth_unstable_by(mid, f64::total_cmp);
    Some(*m)
}

/// The unit among `units` (other than `declared`) in which the raw values would give a value in
/// `range`, as the `--unit ROLE=UNIT` fix; `si` is the value in SI with `declared`.
fn other_unit(role: Role, declared: Unit, si: f64, range: (f64, f64)) -> Option<Unit> {
    let raw = si / declared.factor;
    role.units()
        .iter()
        .copied()
        .filter(|u| u.name != declared.name)
        .find(|u| (range.0..=range.1).contains(&(raw * u.factor)))
}

/// Whether the run's ṡ agrees with the finite differences of its s in magnitude (medians within a
/// factor 5); `None` without both or without motion.
fn time_consistent(r: &ImportedRun) -> Option<bool> {
    let (s, v) = (r.signals.s_rad.as_ref()?, r.signals.sdot_rad_s.as_ref()?);
    let t = &r.signals.time_s;
    let diff: Vec<f64> = (1..t.len())
        .map(|k| ((s[k] - s[k - 1]) / (t[k] - t[k - 1])).abs())
        .collect();
    let (d, m) = (median(diff)?, median(v.iter().map(|x| x.abs()).collect())?);
    if !(d > 1e-9 && m > 1e-9 && d.is_finite()) {
        return None;
    }
    Some((0.2..=5.0).contains(&(m / d)))
}

/// Checks each run: the median sample interval against `gap_s` (the chunk split) and against
/// plausible rates, the span of s and the magnitude of ṡ. `units` are the units the user declared
/// per role (`None`: the format fixes them, e.g. MCAP stamps); a fix is suggested only for those.
pub fn check(runs: &[ImportedRun], gap_s: f64, units: Option<&[(Role, Unit)]>) -> Vec<Finding> {
    let unit =
        |role: Role| units.map(|us| us.iter().find(|u| u.0 == role).map_or(role.si(), |u| u.1));
    let mut out = vec![];
    for r in runs {
        let src = &r.report.source;
        let t = &r.signals.time_s;
        let n = t.len();
        let dts: Vec<f64> = t.windows(2).map(|w| w[1] - w[0]).collect();
        let Some(dt) = median(dts) else { continue };
        // A velocity that agrees with the position's finite differences confirms the time unit.
        let consistent = time_consistent(r);
        let time_fix = unit(Role::Time)
            .filter(|_| consistent != Some(true))
            .and_then(|d| other_unit(Role::Time, d, dt, PLAUSIBLE_DT_S).map(|u| (d, u)));
        let fix = |(d, u): (Unit, Unit)| {
            format!(
                "the time column looks like {}, declared {}: --unit time={}",
                u.name, d.name, u.name
            )
        };
        if dt < MIN_DT_S {
            out.push(Finding {
                refuse: true,
                message: format!(
                    "{src}: the median sample interval is {dt:.3e} s ({:.0} Hz), faster than any \
                     robot log: the {n} rows span {:.3e} s; {}",
                    1.0 / dt,
                    t[n - 1] - t[0],
                    time_fix.map_or(
                        "check the time column's unit (--unit time=s|ms|us)".into(),
                        fix
                    )
                ),
            });
        } else if dt > gap_s {
            out.push(Finding {
                refuse: true,
                message: format!(
                    "{src}: the median sample interval is {dt:.4} s, longer than --gap-s {gap_s} s: \
                     every sample would start its own chunk and the {n} rows would give no \
                     sample; {}",
                    time_fix.map_or_else(
                        || format!(
                            "if the log really is sampled every {dt:.4} s, pass --gap-s {:.3}",
                            3.0 * dt
                        ),
                        fix
                    )
                ),
            });
        }
        if let Some(s) = &r.signals.s_rad {
            let (lo, hi) = s
                .iter()
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &v| {
                    (a.min(v), b.max(v))
                });
            let span = hi - lo;
            if span > MAX_SPAN_RAD {
                let hint = unit(Role::S)
                    .and_then(|d| other_unit(Role::S, d, span, (1e-3, 2.0 * std::f64::consts::PI)))
                    .map_or("check the position's unit and the joint".into(), |u| {
                        format!("it looks like {}: --unit s={}", u.name, u.name)
                    });
                out.push(Finding {
                    refuse: false,
                    message: format!(
                        "{src}: the joint position spans {span:.1} rad ({:.1} turns), more than \
                         a harmonic-drive joint's range; {hint}",
                        span / (2.0 * std::f64::consts::PI)
                    ),
                });
            }
        }
        if let Some(v) = &r.signals.sdot_rad_s {
            let peak = median(v.iter().map(|x| x.abs()).collect::<Vec<_>>()).unwrap_or(0.0);
            if peak > MAX_SPEED_RAD_S {
                let hint = unit(Role::Sdot)
                    .and_then(|d| other_unit(Role::Sdot, d, peak, (1e-3, MAX_SPEED_RAD_S)))
                    .map_or("check the velocity's unit".into(), |u| {
                        format!("it looks like {}: --unit sdot={}", u.name, u.name)
                    });
                out.push(Finding {
                    refuse: false,
                    message: format!(
                        "{src}: the median joint speed is {peak:.1} rad/s, more than a \
                         harmonic-drive joint's; {hint}"
                    ),
                });
            }
        }
    }
    out
}
