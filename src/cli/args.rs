//! Value parsers for the numeric options of every command, in one place: clap calls them
//! while parsing, so a bad value stops the run before any work, and its error names the
//! option, the value and the allowed range ("invalid value 'nan' for '--depth-tol
//! <DEPTH_TOL>': must be a finite number > 0").

use std::str::FromStr;

/// A number that parses and is finite (NaN and infinities are refused).
fn finite<T: FromStr + Copy + Into<f64>>(s: &str) -> Result<T, String> {
    let v: T = s
        .trim()
        .parse()
        .map_err(|_| match s.trim().parse::<f64>() {
            // A number the option's type cannot hold (a width of 99999999999 pixels).
            Ok(x) if x.is_finite() => format!("'{s}' is out of range"),
            _ => format!("'{s}' is not a number"),
        })?;
    if !v.into().is_finite() {
        return Err(format!("must be a finite number, got {s}"));
    }
    Ok(v)
}

/// A finite value within `lo..=hi`, the range spelled as the error says it.
pub fn within<T: FromStr + Copy + Into<f64>>(
    s: &str,
    lo: f64,
    hi: f64,
    range: &str,
) -> Result<T, String> {
    let v: T = finite(s).map_err(|e| format!("{e}; allowed: {range}"))?;
    let x = v.into();
    if x < lo || x > hi {
        return Err(format!("must be {range}, got {s}"));
    }
    Ok(v)
}

/// A finite number > 0 (learning rates, tolerances).
pub fn positive<T: FromStr + Copy + Into<f64>>(s: &str) -> Result<T, String> {
    let v: T = finite(s).map_err(|e| format!("{e}; allowed: a finite number > 0"))?;
    if v.into() <= 0.0 {
        return Err(format!("must be a finite number > 0, got {s}"));
    }
    Ok(v)
}

/// A finite number >= 0 (loss weights, where 0 turns a term off).
pub fn non_negative<T: FromStr + Copy + Into<f64>>(s: &str) -> Result<T, String> {
    within(s, 0.0, f64::INFINITY, "a finite number >= 0")
}

/// A finite number in [0, 1] (colors, probabilities).
pub fn unit_interval<T: FromStr + Copy + Into<f64>>(s: &str) -> Result<T, String> {
    within(s, 0.0, 1.0, "a number in [0, 1]")
}

/// A finite number in [-1, 1] (FlashSplat's background bias gamma).
pub fn signed_unit_interval(s: &str) -> Result<f64, String> {
    within(s, -1.0, 1.0, "a number in [-1, 1]")
}

/// A count that must be at least 1 (iterations, views, pixels, repetitions).
pub fn at_least_one<T: Count>(s: &str) -> Result<T, String> {
    let v: T = s
        .trim()
        .parse()
        .map_err(|_| match s.trim().parse::<u128>() {
            Ok(_) => format!("'{s}' is more than this option takes (at most {})", T::MAX),
            Err(_) => format!("'{s}' is not a whole number >= 1"),
        })?;
    match v.try_into() {
        Ok(n) if n >= 1 => Ok(v),
        _ => Err(format!("must be a whole number >= 1, got {s}")),
    }
}

/// The unsigned types counts are parsed as, and the most each holds (for the error of a
/// count past it).
pub trait Count: FromStr + Copy + TryInto<u64> {
    const MAX: u64;
}

impl Count for u32 {
    const MAX: u64 = u32::MAX as u64;
}

impl Count for u64 {
    const MAX: u64 = u64::MAX;
}

impl Count for usize {
    const MAX: u64 = usize::MAX as u64;
}

/// A size in bytes with an optional K/M/G/T suffix (binary units): 512M, 2G, 1.5T; at least
/// one byte and at most 8,000 PiB (about 2^63 bytes).
pub fn bytes(s: &str) -> Result<u64, String> {
    let s = s.trim();
    let (num, mul) = match s.char_indices().last() {
        Some((i, 'K' | 'k')) => (&s[..i], 1u64 << 10),
        Some((i, 'M' | 'm')) => (&s[..i], 1 << 20),
        Some((i, 'G' | 'g')) => (&s[..i], 1 << 30),
        Some((i, 'T' | 't')) => (&s[..i], 1 << 40),
        _ => (s, 1),
    };
    let v: f64 = num
        .parse()
        .map_err(|_| format!("'{s}' is not a size like 512M or 2G"))?;
    let total = v * mul as f64;
    if !total.is_finite() || !(1.0..=9.2e18).contains(&total) {
        return Err(format!(
            "must be a size from 1 byte to 8000000T (like 512M, 2G or 1T), got {s}"
        ));
    }
    Ok(total as u64)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn refuse_non_finite_and_out_of_range_values_naming_the_range() {
        for bad in ["nan", "NaN", "inf", "-inf", "0", "-1", "x"] {
            let e = positive::<f32>(bad).unwrap_err();
            assert!(
                e.contains("> 0") || e.contains("not a number"),
                "{bad}: {e}"
            );
        }
        assert_eq!(positive::<f64>("0.5"), Ok(0.5));
        assert!(non_negative::<f32>("-0.1").unwrap_err().contains(">= 0"));
        assert_eq!(non_negative::<f32>("0"), Ok(0.0));
        assert!(unit_interval::<f32>("1.5").unwrap_err().contains("[0, 1]"));
        assert!(signed_unit_interval("nan").unwrap_err().contains("[-1, 1]"));
        assert_eq!(signed_unit_interval("-1"), Ok(-1.0));
        assert!(at_least_one::<u32>("0").unwrap_err().contains(">= 1"));
        assert!(at_least_one::<usize>("-3").is_err());
        assert_eq!(at_least_one::<usize>("3"), Ok(3));
        // Whole numbers past the type: too large, with the most it takes.
        let e = at_least_one::<u32>("4294967296").unwrap_err();
        assert!(e.contains("at most 4294967295"), "{e}");
        let e = within::<u32>("99999999999", 1.0, 16384.0, "1..=16384 pixels").unwrap_err();
        assert!(e.contains("out of range; allowed: 1..=16384"), "{e}");
        for bad in ["0", "0.1", "inf", "nan", "-2G", "1e30G", "lots"] {
            assert!(bytes(bad).is_err(), "{bad}");
        }
        assert_eq!(bytes("2G"), Ok(2 << 30));
        assert_eq!(bytes("1.5k"), Ok(1536));
    }
}
