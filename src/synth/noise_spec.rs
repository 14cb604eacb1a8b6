//! The `--noise` grammar: comma-separated `key=value` pairs (or `none`), e.g.
//! `flicker=0.3,boundary=2,consistent=0.6,salt=0.01,missing=0.05`.

use std::fmt;
use std::str::FromStr;

use anyhow::{bail, Context, Error, Result};
use serde::{Deserialize, Serialize};

/// Help text for the keys, shared by `--help` and error messages.
// No line continuation before the first line: it would eat the indentation.
pub const NOISE_KEYS_HELP: &str = "  flicker=P             each (view, object) pair is relabeled with probability P to a look-alike
                        class (chair->armchair/sofa, table->desk, tv->monitor, ...), independently
                        per view (objects picked by `consistent` are exempt)
  boundary=K            object edges move by up to K pixels (a smooth random warp per view;
                        only pixels within K px of an edge change), whole number 0..=64
  consistent=Q          pick objects that are visible in many views and give each the same wrong
                        (look-alike) class in a fraction Q of the train views that see it (whole
                        views, on Q's side of half: 0.6 of 4 views is 3); Q > 0.5 is the
                        majority-wrong case; recorded in labels_noisy/noise.json
  consistent_objects=N  how many objects `consistent` picks (default 1)
  salt=S                a fraction S of pixels gets a random different class
  missing=M             random blobs cover a fraction M of each view with the ignore label
  seed=N                seed of the noise only (default: --seed), to vary noise on a fixed room
Rates P, Q, S, M are in [0, 1]. `none` writes noise-free copies of the labels.
Order per view: relabel objects (consistent, flicker), boundary warp, salt, missing.";

const KEYS: &[&str] = &[
    "flicker",
    "boundary",
    "consistent",
    "consistent_objects",
    "salt",
    "missing",
    "seed",
];
const MAX_BOUNDARY: u32 = 64;

/// Requested label-noise levels; all zero is noise-free.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct NoiseSpec {
    pub flicker: f64,
    pub boundary: u32,
    pub consistent: f64,
    pub consistent_objects: usize,
    pub salt: f64,
    pub missing: f64,
    /// Noise seed; `None` uses the scene seed.
    pub seed: Option<u64>,
}

impl Default for NoiseSpec {
    fn default() -> Self {
        NoiseSpec {
            flicker: 0.0,
            boundary: 0,
            consistent: 0.0,
            consistent_objects: 1,
            salt: 0.0,
            missing: 0.0,
            seed: None,
        }
    }
}

fn rate(key: &str, value: &str) -> Result<f64> {
    let x: f64 = value
        .parse()
        .with_context(|| format!("noise '{key}': '{value}' is not a number"))?;
    if !(0.0..=1.0).contains(&x) {
        bail!("noise '{key}' must be a rate in [0, 1], got {value}");
    }
    Ok(x)
}

impl FromStr for NoiseSpec {
    type Err = Error;

    fn from_str(s: &str) -> Result<Self> {
        let s = s.trim();
        if s.is_empty() {
            bail!("empty noise spec (use e.g. 'flicker=0.3,salt=0.01' or 'none')\nkeys:\n{NOISE_KEYS_HELP}");
        }
        let mut spec = NoiseSpec::default();
        if s == "none" {
            return Ok(spec);
        }
        let mut seen: Vec<&str> = Vec::new();
        for item in s.split(',') {
            let item = item.trim();
            let Some((key, value)) = item.split_once('=') else {
                bail!(
                    "noise spec item '{item}' is not key=value (keys: {})",
                    KEYS.join(", ")
                );
            };
            let (key, value) = (key.trim(), value.trim());
            if !KEYS.contains(&key) {
                bail!(
                    "unknown noise key '{key}' (keys: {})\n{NOISE_KEYS_HELP}",
                    KEYS.join(", ")
                );
            }
            if seen.contains(&key) {
                bail!("noise key '{key}' given twice");
            }
            seen.push(key);
            match key {
                "flicker" => spec.flicker = rate(key, value)?,
                "consistent" => spec.consistent = rate(key, value)?,
                "salt" => spec.salt = rate(key, value)?,
                "missing" => spec.missing = rate(key, value)?,
                "boundary" => {
                    spec.boundary = value
                        .parse()
                        .ok()
                        .filter(|k| *k <= MAX_BOUNDARY)
                        .with_context(|| format!("noise 'boundary' must be a whole number of pixels 0..={MAX_BOUNDARY}, got '{value}'"))?;
                }
                "consistent_objects" => {
                    spec.consistent_objects = value
                        .parse()
                        .ok()
                        .filter(|n| *n >= 1)
                        .with_context(|| format!("noise 'consistent_objects' must be a whole number >= 1, got '{value}'"))?;
                }
                _ => {
                    spec.seed = Some(value.parse().with_context(|| {
                        format!("noise 'seed' must be a whole number, got '{value}'")
                    })?);
                }
            }
        }
        Ok(spec)
    }
}

/// The canonical spec: non-default keys in a fixed order (`none` when noise-free).
/// A rate as text that parses back to it, in scientific notation where plain decimals
/// would run to hundreds of digits (`1e-300`).
fn short_rate(rate: f64) -> String {
    if rate != 0.0 && !(1e-4..1e6).contains(&rate.abs()) {
        format!("{rate:e}")
    } else {
        rate.to_string()
    }
}

impl fmt::Display for NoiseSpec {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let mut items = Vec::new();
        let d = NoiseSpec::default();
        if self.flicker != d.flicker {
            items.push(format!("flicker={}", short_rate(self.flicker)));
        }
        if self.boundary != d.boundary {
            items.push(format!("boundary={}", self.boundary));
        }
        if self.consistent != d.consistent {
            items.push(format!("consistent={}", short_rate(self.consistent)));
        }
        if self.consistent_objects != d.consistent_objects {
            items.push(format!("consistent_objects={}", self.consistent_objects));
        }
        if self.salt != d.salt {
            items.push(format!("salt={}", short_rate(self.salt)));
        }
        if self.missing != d.missing {
            items.push(format!("missing={}", short_rate(self.missing)));
        }
        if let Some(seed) = self.seed {
            items.push(format!("seed={seed}"));
        }
        if items.is_empty() {
            write!(f, "none")
        } else {
            write!(f, "{}", items.join(","))
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_all_keys_and_round_trips() {
        let s: NoiseSpec = "flicker=0.3, boundary=2,consistent=0.6,consistent_objects=2,salt=0.01,missing=0.05,seed=9".parse().unwrap();
        assert_eq!(
            s,
            NoiseSpec {
                flicker: 0.3,
                boundary: 2,
                consistent: 0.6,
                consistent_objects: 2,
                salt: 0.01,
                missing: 0.05,
                seed: Some(9)
            }
        );
        assert_eq!(s.to_string().parse::<NoiseSpec>().unwrap(), s);
        assert_eq!("none".parse::<NoiseSpec>().unwrap(), NoiseSpec::default());
        assert_eq!(NoiseSpec::default().to_string(), "none");
        // Tiny rates are written short, and still read back exactly.
        let tiny: NoiseSpec = "flicker=1e-300,salt=0.000012345".parse().unwrap();
        assert_eq!(tiny.to_string(), "flicker=1e-300,salt=1.2345e-5");
        assert_eq!(tiny.to_string().parse::<NoiseSpec>().unwrap(), tiny);
    }

    #[test]
    fn rejects_bad_specs_with_clear_errors() {
        for (bad, needle) in [
            ("", "empty"),
            ("flicker", "key=value"),
            ("flicker=1.5", "[0, 1]"),
            ("salt=-0.1", "[0, 1]"),
            ("missing=abc", "not a number"),
            ("blur=2", "unknown noise key 'blur'"),
            ("boundary=2.5", "whole number"),
            ("boundary=1000", "whole number"),
            ("flicker=0.1,flicker=0.2", "twice"),
            ("consistent_objects=0", ">= 1"),
            ("seed=x", "seed"),
            ("flicker=0.1,", "key=value"),
            ("flicker=NaN", "[0, 1]"),
        ] {
            let err = bad.parse::<NoiseSpec>().unwrap_err().to_string();
            assert!(err.contains(needle), "{bad:?}: {err}");
        }
    }
}
