//! Per-kernel GPU times read from timestamp queries.

use serde::Serialize;

/// A timestamp recorded with [`super::Recorder::mark`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Mark(pub(crate) u32);

/// One timed dispatch: the time from the previous timestamp to the end of this kernel.
#[derive(Clone, Debug, Serialize)]
pub struct KernelTime {
    pub kernel: &'static str,
    pub ns: f64,
}

/// Time per kernel, summed over its dispatches.
#[derive(Clone, Debug, Serialize)]
pub struct KernelTotal {
    pub kernel: &'static str,
    pub dispatches: usize,
    pub ns: f64,
}

impl KernelTotal {
    /// Adds each of `more` to `totals`' entry for its kernel (a new entry at the end if none).
    pub fn add_all(totals: &mut Vec<KernelTotal>, more: impl IntoIterator<Item = KernelTotal>) {
        for k in more {
            match totals.iter_mut().find(|t| t.kernel == k.kernel) {
                Some(t) => {
                    t.dispatches += k.dispatches;
                    t.ns += k.ns;
                }
                None => totals.push(k),
            }
        }
    }
}

/// GPU timings of one submission. Empty (all zero) when the device has no timestamps.
#[derive(Clone, Debug, Default)]
pub struct Timings {
    /// Absolute timestamps in ns; index 0 is the start of the command buffer.
    stamps_ns: Vec<f64>,
    pub dispatches: Vec<KernelTime>,
    pub available: bool,
}

impl Timings {
    pub(crate) fn new(
        stamps_ns: &[f64],
        labels: &[Option<&'static str>],
        available: bool,
    ) -> Timings {
        let dispatches = labels
            .iter()
            .enumerate()
            .filter_map(|(i, l)| {
                l.map(|kernel| KernelTime {
                    kernel,
                    ns: stamps_ns[i + 1] - stamps_ns[i],
                })
            })
            .collect();
        Timings {
            stamps_ns: stamps_ns.to_vec(),
            dispatches,
            available,
        }
    }

    /// Nanoseconds between two marks of the same recorder.
    pub fn between(&self, from: Option<Mark>, to: Option<Mark>) -> Option<f64> {
        match (from, to) {
            (Some(a), Some(b)) if self.available => {
                Some(self.stamps_ns[b.0 as usize] - self.stamps_ns[a.0 as usize])
            }
            _ => None,
        }
    }

    /// Nanoseconds from the start of the command buffer to its last timestamp.
    pub fn total_ns(&self) -> f64 {
        match (self.stamps_ns.first(), self.stamps_ns.last()) {
            (Some(a), Some(b)) if self.available => b - a,
            _ => 0.0,
        }
    }

    /// Per-kernel totals, in order of first dispatch.
    pub fn by_kernel(&self) -> Vec<KernelTotal> {
        let mut out = Vec::new();
        self.add_to(&mut out);
        out
    }

    /// Adds this submission's dispatches to per-kernel totals (of many submissions).
    pub fn add_to(&self, totals: &mut Vec<KernelTotal>) {
        let each = self.dispatches.iter().map(|d| KernelTotal {
            kernel: d.kernel,
            dispatches: 1,
            ns: d.ns,
        });
        KernelTotal::add_all(totals, each);
    }
}
