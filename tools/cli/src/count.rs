//! Counts that size an allocation (probes, samples, trials, stream windows): one parser that bounds
//! them before anything is allocated, and one check that a sized run fits the machine's memory.
//!
//! Every such option uses [`parse`] with its bound (`value_parser = count::probes` and the like), so
//! `--probes-only 1e14` is refused by clap naming the flag, the value and the bound instead of
//! aborting on a failed allocation; [`fits_in_memory`] is called once the bytes per item are known
//! (e.g. the model's input width) and refuses, before the run starts, a count whose buffers exceed
//! the memory available.

/// Largest `--probes-only`, `--probes` (distill) and `--samples` (convert): random probe inputs.
pub const MAX_PROBES: usize = 20_000_000;
/// Largest `--trials` of a search (each trial is a training run; the queue holds their draws).
pub const MAX_TRIALS: usize = 1_000_000;
/// Largest `--window-samples` of a streamed import (grid samples held per window).
pub const MAX_WINDOW_SAMPLES: usize = 100_000_000;

/// Parses a count: a non-negative whole number, written as digits (`100000`) or in exponent form
/// (`1e5`), at most `max`. The error names the bound.
pub fn parse(s: &str, max: usize) -> Result<usize, String> {
    let t = s.trim();
    let n: f64 = match t.parse::<u128>() {
        Ok(n) => n as f64,
        Err(_) => match t.parse::<f64>() {
            Ok(v) if v.is_finite() && v >= 0.0 && v.fract() == 0.0 => v,
            _ => return Err(format!("`{s}` is not a whole number ≥ 0")),
        },
    };
    if n > max as f64 {
        return Err(format!(
            "{s} is more than this option's bound of {max} (it sizes an allocation)"
        ));
    }
    // Exact: n ≤ max < 2^53 for every bound here, or it came from the integer parse.
    match t.parse::<usize>() {
        Ok(v) => Ok(v),
        Err(_) => Ok(n as usize),
    }
}

/// [`parse`] bounded by [`MAX_PROBES`].
pub fn probes(s: &str) -> Result<usize, String> {
    parse(s, MAX_PROBES)
}

/// [`parse`] bounded by [`MAX_TRIALS`].
pub fn trials(s: &str) -> Result<usize, String> {
    parse(s, MAX_TRIALS)
}

/// [`parse`] bounded by [`MAX_WINDOW_SAMPLES`].
pub fn window_samples(s: &str) -> Result<usize, String> {
    parse(s, MAX_WINDOW_SAMPLES)
}

/// The memory this process may still use \[bytes\]: `MemAvailable` of `/proc/meminfo` (`None` when
/// it cannot be read, e.g. not Linux).
pub fn available_memory_bytes() -> Option<u64> {
    let text = std::fs::read_to_string("/proc/meminfo").ok()?;
    let line = text.lines().find(|l| l.starts_with("MemAvailable:"))?;
    let kib: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    kib.checked_mul(1024)
}

/// Refuses, before anything is allocated, a run whose buffers (`count` items of `bytes_per_item`
/// bytes) exceed the memory available (`available`, normally [`available_memory_bytes`]; no check
/// when `None`). `what` names the option and its value, e.g. `--probes-only 5000000`.
pub fn fits_in_memory(
    what: &str,
    count: usize,
    bytes_per_item: usize,
    available: Option<u64>,
) -> anyhow::Result<()> {
    let need = count as u128 * bytes_per_item as u128;
    if let Some(avail) = available
        && need > avail as u128
    {
        anyhow::bail!(
            "{what}: needs about {:.1} GB ({count} × {bytes_per_item} bytes), more than the {:.1} GB \
             of memory available; nothing was started (use a smaller count)",
            need as f64 / 1e9,
            avail as f64 / 1e9
        );
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn counts_are_whole_bounded_numbers() {
        assert_eq!(parse("1000", 10_000), Ok(1000));
        assert_eq!(parse("1e3", 10_000), Ok(1000));
        assert_eq!(parse("0", 10), Ok(0));
        let e = parse("1e14", MAX_PROBES).unwrap_err();
        assert!(e.contains(&MAX_PROBES.to_string()), "{e}");
        assert!(parse("100000000000000000000000000000", 10).is_err());
        for bad in ["-1", "1.5", "nan", "inf", "", "x"] {
            assert!(parse(bad, 10).is_err(), "{bad}");
        }
        assert_eq!(probes(&MAX_PROBES.to_string()), Ok(MAX_PROBES));
        assert!(trials(&(MAX_TRIALS + 1).to_string()).is_err());
    }

    #[test]
    fn memory_check_names_the_option_and_the_need() {
        fits_in_memory("--samples 10", 10, 100, Some(10_000)).unwrap();
        fits_in_memory("--samples 10", 10, 100, None).unwrap();
        let e = fits_in_memory("--samples 1000", 1000, 100, Some(10_000))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("--samples 1000") && e.contains("available"),
            "{e}"
        );
    }
}
