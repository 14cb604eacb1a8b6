//! The semantic assignment on the GPU, folded into each Gaussian's state pass by pass while
//! the evidence rows are still on the device: the host never holds the evidence matrix
//! (classes x Gaussians), only a few words per Gaussian. Same result as
//! [`super::assign_semantic_near`] (the plain host version the tests compare against):
//! the most evidence wins; ties go to the neighbours' evidence, then to the class with
//! more evidence over the whole scene, else the Gaussian stays undecided.
//!
//! Kernels: `fuse/class_mass` sums each row exactly (the scene mass), `fuse/assign_fold`
//! folds a pass's rows into the per-Gaussian state.

use anyhow::{ensure, Context, Result};
use bytemuck::{Pod, Zeroable};

use super::assign::Assignment;
use super::partial::EvidenceKind;
use crate::contract::params::{FoldParams, MassParams};
use crate::gpu::kernel_table::ids;
use crate::gpu::{Buffer, BufferRange, Gpu, Recorder};
use crate::render::chunks::{chunk_len, chunks, part_of};

/// One Gaussian's running assignment; mirrors `FoldState` in glsl/fuse/assign_fold.comp
/// (std430: three uint64, two uint, 32 bytes).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
struct FoldState {
    /// The winner's evidence (0: nothing seen).
    value: u64,
    /// The winner's evidence summed over the neighbours.
    near: u64,
    /// The Gaussian's evidence over every class folded so far.
    total: u64,
    class: u32,
    /// 1 when another class equals the winner on evidence, neighbours and scene rank.
    tied: u32,
}

const STATE_BYTES: u64 = std::mem::size_of::<FoldState>() as u64;

/// Workgroup size of `fuse/class_mass`: a span of one row is a multiple of it.
const MASS_GROUP: u32 = 256;
/// Workgroups summing one row at most: enough to fill a GPU with a pass's rows, few enough
/// that the per-workgroup reduction is a small part of the work.
const MASS_SPANS: u32 = 64;
/// Gaussians one of them sums at least (16 per invocation).
const MIN_MASS_SPAN: u32 = 16 * MASS_GROUP;

/// The assignment of one fusion run while its passes go by.
pub struct GpuAssigner<'a> {
    gpu: &'a Gpu,
    n: u32,
    kind: EvidenceKind,
    /// [n][k] nearest neighbours (`NO_NEIGHBOUR` where fewer exist); 4 bytes when k = 0.
    knn: Buffer,
    k: u32,
    state: Buffer,
    /// Each class's rank by scene mass among the classes folded so far.
    ranks: Buffer,
    /// Each class's exact scene mass, once its pass has run.
    masses: Vec<Option<u128>>,
    /// Gaussians per fold dispatch, so every range it binds fits one binding.
    chunk: u32,
}

impl<'a> GpuAssigner<'a> {
    /// An assigner for `classes` compact classes of `n` Gaussians whose evidence is summed
    /// as `kind`; `knn` ([n][k]) breaks ties by the neighbours' evidence.
    pub fn new(
        gpu: &'a Gpu,
        n: usize,
        classes: usize,
        kind: EvidenceKind,
        knn: Option<(&[u32], usize)>,
    ) -> Result<GpuAssigner<'a>> {
        ensure!(
            gpu.caps().int64,
            "the GPU assignment needs shaderInt64, which {} lacks",
            gpu.caps().name
        );
        let (knn_rows, k) = knn.unwrap_or((&[], 0));
        ensure!(
            knn_rows.len() == n * k,
            "knn holds {} entries, not {n} x {k}",
            knn_rows.len()
        );
        let per_gaussian = STATE_BYTES.max(4 * k as u64);
        let group = ids::FUSE_ASSIGN_FOLD.info().workgroup_size[0];
        let max_range = gpu.caps().max_storage_buffer_range;
        let chunk = chunk_len(per_gaussian, 0, max_range)
            .with_context(|| {
                format!("one granule of Gaussians' fold state passes the {max_range}-byte binding limit")
            })?
            .min(gpu.caps().max_workgroup_count[0].saturating_mul(group));
        let state = gpu.buffer("assign-state", (n as u64 * STATE_BYTES).max(STATE_BYTES))?;
        let mut rec = Recorder::new(gpu)?;
        rec.fill(&state, 0, state.size(), 0);
        rec.submit_and_wait()?;
        let knn = if k == 0 {
            gpu.buffer("assign-knn", 4)?
        } else {
            gpu.buffer_from("assign-knn", knn_rows)?
        };
        Ok(GpuAssigner {
            gpu,
            n: n as u32,
            kind,
            knn,
            k: k as u32,
            state,
            ranks: gpu.buffer("assign-ranks", 4 * classes.max(1) as u64)?,
            masses: vec![None; classes],
            chunk,
        })
    }

    /// Folds rows `row_begin..row_begin + rows` of `evidence` ([rows][n] entries of the
    /// assigner's kind) into every Gaussian's state.
    pub fn fold(&mut self, evidence: &Buffer, row_begin: usize, rows: usize) -> Result<()> {
        ensure!(
            rows as u64 <= self.gpu.caps().max_workgroup_count[1] as u64,
            "{rows} classes in one pass are more than one dispatch covers: lower --mem-budget"
        );
        let masses = self.scene_masses(evidence, rows)?;
        for (r, mass) in masses.into_iter().enumerate() {
            self.masses[row_begin + r] = Some(mass);
        }
        self.gpu.upload(&self.ranks, 0, &mass_ranks(&self.masses))?;
        let evidence_addr = evidence.address_words(4)?;
        let mut rec = Recorder::new(self.gpu)?;
        for range in chunks(self.n, self.chunk) {
            let params = FoldParams {
                evidence_addr,
                n: self.n,
                words: self.words(),
                first: range.start,
                count: range.len() as u32,
                row_begin: row_begin as u32,
                rows: rows as u32,
                k: self.k,
            };
            let knn = match self.k {
                0 => BufferRange::whole(&self.knn),
                k => part_of(&self.knn, &range, 4 * k as u64),
            };
            rec.dispatch_ranges(
                ids::FUSE_ASSIGN_FOLD,
                &[
                    ("knn", knn),
                    ("scene_rank", BufferRange::whole(&self.ranks)),
                    ("state", part_of(&self.state, &range, STATE_BYTES)),
                ],
                &params,
                ids::FUSE_ASSIGN_FOLD.groups_for(params.count),
            )?;
        }
        rec.submit_and_wait()?;
        Ok(())
    }

    /// The exact sum of each of the `rows` rows of `evidence` over all Gaussians.
    fn scene_masses(&self, evidence: &Buffer, rows: usize) -> Result<Vec<u128>> {
        let span = self
            .n
            .div_ceil(MASS_SPANS)
            .max(MIN_MASS_SPAN)
            .next_multiple_of(MASS_GROUP);
        let spans = self.n.div_ceil(span).max(1);
        let partials = self
            .gpu
            .buffer("class-mass", rows.max(1) as u64 * spans as u64 * 16)?;
        let params = MassParams {
            n: self.n,
            words: self.words(),
            span,
            spans,
            evidence_addr: evidence.address_words(4)?,
        };
        let mut rec = Recorder::new(self.gpu)?;
        rec.dispatch(
            ids::FUSE_CLASS_MASS,
            &[("partials", &partials)],
            &params,
            [spans, rows as u32, 1],
        )?;
        rec.submit_and_wait()?;
        let words: Vec<[u32; 4]> = self.gpu.read(&partials)?;
        Ok(words
            .chunks(spans as usize)
            .take(rows)
            .map(|row| {
                row.iter()
                    .map(|&[lo, hi, carries, _]| wide_sum(lo, hi, carries))
                    .sum()
            })
            .collect())
    }

    /// Evidence words per entry.
    fn words(&self) -> u32 {
        (self.kind.bytes() / 4) as u32
    }

    /// Reads every Gaussian's state back: the winning class (None where unseen or tied)
    /// and its share of the Gaussian's evidence.
    pub fn finish(self) -> Result<Assignment> {
        let states: Vec<FoldState> = self.gpu.download(&self.state, 0, self.n as usize)?;
        let widen = |v: u64| self.kind.widen(v);
        let decided = |s: &FoldState| s.value > 0 && s.tied == 0;
        Ok(Assignment {
            class: states
                .iter()
                .map(|s| decided(s).then_some(s.class as usize))
                .collect(),
            confidence: states
                .iter()
                .map(|s| match decided(s) {
                    true => (widen(s.value) / widen(s.total)) as f32,
                    false => 0.0,
                })
                .collect(),
        })
    }
}

/// A workgroup's 96-bit sum: 64 bits (`lo`, `hi`) and the carries out of them.
fn wide_sum(lo: u32, hi: u32, carries: u32) -> u128 {
    ((carries as u128) << 64) | ((hi as u128) << 32) | lo as u128
}

/// Each class's rank among the distinct masses known (0 for the smallest; classes not yet
/// folded rank 0 too: no folded class's winner is one of them).
fn mass_ranks(masses: &[Option<u128>]) -> Vec<u32> {
    let mut distinct: Vec<u128> = masses.iter().flatten().copied().collect();
    distinct.sort_unstable();
    distinct.dedup();
    masses
        .iter()
        .map(|m| m.map_or(0, |m| distinct.partition_point(|&d| d < m) as u32))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ranks_order_masses_and_share_equal_ones() {
        let ranks = mass_ranks(&[Some(5), None, Some(2), Some(5), Some(9)]);
        assert_eq!(ranks, vec![1, 0, 0, 1, 2]);
    }

    #[test]
    fn wide_sums_keep_their_carries() {
        assert_eq!(wide_sum(1, 0, 0), 1);
        assert_eq!(wide_sum(0, 1, 0), 1 << 32);
        assert_eq!(wide_sum(7, 0, 3), (3u128 << 64) + 7);
    }
}
