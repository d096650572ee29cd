//! Minimum-K_p search: bisection on a log scale for the lowest gain that passes a criterion.
//!
//! What this module **is**: [`KpBisection`], a small state machine (`candidate` → run a trial →
//! `report`) so several independent searches (one per joint) can share each trial run. It first
//! checks the upper end. "Passes" is not always monotone in K_p: with K_d fixed at 4/s the damping
//! ratio falls as 1/√K_p, and a compensation that removes friction (the plant's main damping) can
//! make a high gain oscillate while a lower one tracks. So when the upper end fails, the search
//! scans down a log grid of [`SCAN_POINTS`] gains for one that passes (none passing:
//! [`MinKp::NonePassed`]). From the highest passing gain it checks the lower end (if that passes the
//! minimum is at or below it), then halves the log-interval `iterations` times and returns the
//! lowest passing gain found; the answer lies in (`fail`, `pass`] with `pass/fail = (p/lo)^(1/2^it)`,
//! `p` the passing gain the bisection started from. Below `p` the search assumes monotonicity.
//!
//! What it is **not**: no trial execution.

use super::ExperimentError;

/// Result of a search.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(tag = "outcome", rename_all = "snake_case")]
pub enum MinKp {
    /// The lowest passing gain found, and the highest failing one below it.
    Found {
        /// Lowest passing K_p [1/s²].
        kp: f64,
        /// Highest failing K_p [1/s²] (the minimum lies in (fail, kp]).
        fail_kp: f64,
    },
    /// Even the upper end failed: the minimum is above `hi` (not produced by [`KpBisection`], which
    /// scans down from a failing upper end and reports [`MinKp::NonePassed`]; kept for reports).
    AboveRange {
        /// Upper end [1/s²].
        hi: f64,
    },
    /// The lower end passed: the minimum is at or below `lo`.
    BelowRange {
        /// Lower end [1/s²].
        lo: f64,
    },
    /// The upper end failed and so did every gain of the downward scan: nothing in range tracks.
    NonePassed {
        /// Lower end [1/s²].
        lo: f64,
        /// Upper end [1/s²].
        hi: f64,
    },
}

impl MinKp {
    /// A gain to use for follow-up runs: the passing gain, `hi` (above range) or `lo` (below).
    pub fn kp_for_runs(&self) -> f64 {
        match *self {
            MinKp::Found { kp, .. } => kp,
            MinKp::AboveRange { hi } => hi,
            MinKp::BelowRange { lo } => lo,
            MinKp::NonePassed { hi, .. } => hi,
        }
    }

    /// Human-readable, e.g. `550`, `> 30000`, `≤ 10`.
    pub fn display(&self) -> String {
        match *self {
            MinKp::Found { kp, .. } => format!("{}", sig3(kp)),
            MinKp::AboveRange { hi } => format!("> {}", sig3(hi)),
            MinKp::BelowRange { lo } => format!("≤ {}", sig3(lo)),
            MinKp::NonePassed { lo, hi } => format!("none in {}–{}", sig3(lo), sig3(hi)),
        }
    }
}

/// Rounds to 3 significant digits for display.
pub fn sig3(x: f64) -> f64 {
    if x == 0.0 || !x.is_finite() {
        return x;
    }
    let p = 10f64.powi(2 - x.abs().log10().floor() as i32);
    (x * p).round() / p
}

/// Gains tried below a failing upper end before giving up (log-spaced, exclusive of both ends).
pub const SCAN_POINTS: u32 = 4;

#[derive(Clone, Copy, Debug, PartialEq)]
enum Phase {
    CheckHi,
    /// Scanning down after a failing upper end: candidate `k` of [`SCAN_POINTS`].
    ScanDown {
        k: u32,
    },
    CheckLo,
    Bisect {
        fail: f64,
        pass: f64,
        left: u32,
    },
    Done(MinKp),
}

/// Log-scale bisection state (see the module doc).
#[derive(Clone, Debug)]
pub struct KpBisection {
    lo: f64,
    hi: f64,
    iterations: u32,
    phase: Phase,
    /// The passing gain the bisection starts from (`hi`, or the scan's passing gain).
    pass_start: f64,
    /// Every (K_p, passed) evaluated, in order.
    pub history: Vec<(f64, bool)>,
}

impl KpBisection {
    /// A search over `[lo, hi]` (0 < lo < hi) with `iterations` halvings.
    pub fn new(lo: f64, hi: f64, iterations: u32) -> Result<Self, ExperimentError> {
        if !(lo.is_finite() && hi.is_finite() && lo > 0.0 && hi > lo) {
            return Err(ExperimentError::KpRange { lo, hi });
        }
        Ok(Self {
            lo,
            hi,
            iterations,
            phase: Phase::CheckHi,
            pass_start: hi,
            history: vec![],
        })
    }

    /// The next gain to try, or `None` when done.
    pub fn candidate(&self) -> Option<f64> {
        match self.phase {
            Phase::CheckHi => Some(self.hi),
            Phase::ScanDown { k } => {
                Some(self.hi * (self.lo / self.hi).powf(f64::from(k) / f64::from(SCAN_POINTS + 1)))
            }
            Phase::CheckLo => Some(self.lo),
            Phase::Bisect { fail, pass, .. } => Some((fail * pass).sqrt()),
            Phase::Done(_) => None,
        }
    }

    /// Reports whether the current candidate passed.
    pub fn report(&mut self, passed: bool) {
        let Some(kp) = self.candidate() else { return };
        self.history.push((kp, passed));
        self.phase = match self.phase {
            Phase::CheckHi if !passed => Phase::ScanDown { k: 1 },
            Phase::CheckHi => Phase::CheckLo,
            Phase::ScanDown { .. } if passed => {
                self.pass_start = kp;
                Phase::CheckLo
            }
            Phase::ScanDown { k } if k < SCAN_POINTS => Phase::ScanDown { k: k + 1 },
            Phase::ScanDown { .. } => {
                // The upper end failed and nothing below it passed: whether a gain above the
                // range would track cannot be told from failures alone.
                Phase::Done(MinKp::NonePassed {
                    lo: self.lo,
                    hi: self.hi,
                })
            }
            Phase::CheckLo if passed => Phase::Done(MinKp::BelowRange { lo: self.lo }),
            Phase::CheckLo | Phase::Bisect { .. } => {
                let (fail, pass, left) = match self.phase {
                    Phase::Bisect { fail, left, .. } if passed => (fail, kp, left - 1),
                    Phase::Bisect { pass, left, .. } => (kp, pass, left - 1),
                    _ => (self.lo, self.pass_start, self.iterations),
                };
                if left == 0 {
                    Phase::Done(MinKp::Found {
                        kp: pass,
                        fail_kp: fail,
                    })
                } else {
                    Phase::Bisect { fail, pass, left }
                }
            }
            Phase::Done(d) => Phase::Done(d),
        };
    }

    /// The result once done.
    pub fn result(&self) -> Option<MinKp> {
        match self.phase {
            Phase::Done(d) => Some(d),
            _ => None,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn search(threshold: f64, lo: f64, hi: f64, it: u32) -> (MinKp, usize) {
        let mut b = KpBisection::new(lo, hi, it).unwrap();
        let mut n = 0;
        while let Some(kp) = b.candidate() {
            b.report(kp >= threshold);
            n += 1;
            assert!(n < 100);
        }
        (b.result().unwrap(), n)
    }

    #[test]
    fn finds_a_known_threshold_within_the_log_resolution() {
        for &thr in &[13.7, 550.0, 999.0, 4321.0] {
            let (r, n) = search(thr, 10.0, 30000.0, 10);
            let MinKp::Found { kp, fail_kp } = r else {
                panic!("{thr}: {r:?}")
            };
            assert_eq!(n, 12, "2 end checks + 10 halvings");
            assert!(kp >= thr && fail_kp < thr, "{fail_kp} < {thr} ≤ {kp}");
            let resolution = (30000.0f64 / 10.0).powf(1.0 / 1024.0);
            assert!(kp / fail_kp <= resolution * (1.0 + 1e-9), "{kp}/{fail_kp}");
        }
    }

    #[test]
    fn out_of_range_thresholds_are_reported_as_such() {
        assert_eq!(
            search(1e6, 10.0, 1e4, 5).0,
            MinKp::NonePassed { lo: 10.0, hi: 1e4 }
        );
        assert_eq!(search(1.0, 10.0, 1e4, 5).0, MinKp::BelowRange { lo: 10.0 });
        assert_eq!(
            search(1e6, 10.0, 1e4, 5).1,
            1 + SCAN_POINTS as usize,
            "upper end + the downward scan"
        );
        assert!(KpBisection::new(10.0, 5.0, 3).is_err());
        assert!(KpBisection::new(0.0, 5.0, 3).is_err());
    }

    #[test]
    fn a_failing_upper_end_scans_down_then_bisects_below_the_passing_gain() {
        // Passes only in [550, 20000): a high gain oscillates, a low one cannot track.
        let passes = |kp: f64| (550.0..20000.0).contains(&kp);
        let mut b = KpBisection::new(30.0, 1e5, 8).unwrap();
        let mut n = 0;
        while let Some(kp) = b.candidate() {
            b.report(passes(kp));
            n += 1;
            assert!(n < 100);
        }
        let MinKp::Found { kp, fail_kp } = b.result().unwrap() else {
            panic!("{:?}", b.result())
        };
        assert!(kp >= 550.0 && fail_kp < 550.0, "{fail_kp} < 550 ≤ {kp}");
        assert!(kp / fail_kp < 1.05, "resolution {kp}/{fail_kp}");
        // history: the failing upper end, then the scan down to the first passing gain
        assert_eq!(b.history[0], (1e5, false));
        assert!(b.history[1].0 < 1e5 && b.history.iter().any(|&(k, p)| p && k < 20000.0));
    }

    #[test]
    fn display_rounds_to_three_digits() {
        assert_eq!(
            MinKp::Found {
                kp: 553.21,
                fail_kp: 500.0
            }
            .display(),
            "553"
        );
        assert_eq!(MinKp::AboveRange { hi: 30000.0 }.display(), "> 30000");
        assert_eq!(sig3(0.012345), 0.0123);
    }
}
