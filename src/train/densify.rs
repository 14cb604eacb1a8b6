//! Adaptive density control of 3DGS (Kerbl et al. 2023, `densify_and_prune`) on the GPU:
//! prune, clone and split in one planned step, with a hard cap on the model size.
//!
//! A step has two halves. [`Densifier::plan`] classifies every Gaussian and lays out the
//! new set on the GPU (one submission, then one download of a few counters).
//! [`Densifier::apply`] then builds each parameter tensor of the new set from the old one by
//! a gather, so the caller passes its tensors generically: any width, one [`Role`] each.
//!
//! Semantics, per Gaussian i with `avg_grad = grad_accum / grad_count` (0 where the count
//! is 0):
//! - **prune** when `sigmoid(opacity_logit) < min_opacity`, or (with `prune_large`)
//!   `max(exp(log_scales)) > 0.1 * extent`. Pruning looks at the original Gaussians only; a
//!   pruned Gaussian is never densified.
//! - a survivor with `avg_grad >= grad_threshold` is a **candidate**. Candidates whose
//!   largest scale is `<= percent_dense * extent` are **cloned** (the Gaussian stays and a
//!   copy is added), the others **split** (replaced by two children, each with
//!   `mean + R(q) * (exp(log_scales) * z)`, `z ~ N(0, I)`, and `log_scales - ln(1.6)`).
//! - **cap**: each densified Gaussian adds exactly one, so at most
//!   `max_gaussians - survivors` candidates are densified: those with the largest
//!   `avg_grad` (f32, as the GPU divides), ties broken by the lower index. The result never
//!   exceeds `max_gaussians` (the input must not exceed it either).
//! - Adam moments: kept Gaussians (the original of a clone included) keep theirs; every new
//!   Gaussian (a clone's copy, both split children) starts at zero.
//! - Not modelled: 3DGS's screen-space size pruning (`max_radii2D`), which needs the
//!   rasterizer's per-view radii.
//!
//! **Order of the new set**: the original order, each Gaussian replaced by its outputs:
//! nothing if pruned, itself if kept, itself then its copy if cloned, child 0 then child 1
//! if split. (Densified Gaussians stay next to their neighbours in memory.)
//!
//! **Split RNG** (counter-based, so the children do not depend on the dispatch): child
//! `c` (0 or 1) of Gaussian `i` hashes `h = pcg4d(i, c, seed as u32, (seed >> 32) as u32)`
//! (Jarzynski and Olano 2020), maps each word to `u_k = ((h_k >> 8) + 0.5) / 2^24` and
//! takes Box-Muller pairs `r0 = sqrt(-2 ln u0)`, `a0 = pi * (2 u1 - 1)`,
//! `r1 = sqrt(-2 ln u2)`, `a1 = pi * (2 u3 - 1)`:
//! `z = (r0 cos a0, r0 sin a0, r1 cos a1)`. The quaternion is normalized before use
//! (glsl/train/densify_common.glsl: `split_normal`).

use anyhow::{ensure, Context, Result};

use crate::contract::params::{
    DensifyClassifyParams, DensifyCompactParams, DensifyLayoutParams, DensifySelectParams,
    GatherParams, ResetOpacityParams,
};
use crate::gpu::kernel_table::ids;
use crate::gpu::{Buffer, Gpu, GpuCount, PrefixScan, RadixSort, Recorder};
use crate::render::chunks::{chunk_len, chunks, part_of};
use crate::render::gpu_scene::ParamTensor;

use crate::contract::{
    self, DENSIFY_WG_SIZE as WG_SIZE, DS_N_PLUS1, ROLE_COPY, ROLE_LOG_SCALES, ROLE_MEANS,
    ROLE_MOMENT,
};

/// Plan status words, as indices into the downloaded status.
const DS_SURVIVORS: usize = contract::DS_SURVIVORS as usize;
const DS_CANDIDATES: usize = contract::DS_CANDIDATES as usize;
const DS_DENSIFIED: usize = contract::DS_DENSIFIED as usize;
const DS_CLONED: usize = contract::DS_CLONED as usize;
const DS_SPLIT: usize = contract::DS_SPLIT as usize;
const DS_NEW_N: usize = contract::DS_NEW_N as usize;
const DS_WORDS: u64 = contract::DS_WORDS as u64;

/// Opacity that 3DGS's opacity reset caps every Gaussian at.
pub const OPACITY_RESET: f32 = 0.01;

/// Thresholds of one densify-and-prune step; the defaults are 3DGS's.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DensifyConfig {
    /// Average 2D-mean gradient (NDC units) from which a Gaussian is densified.
    pub grad_threshold: f32,
    /// Fraction of the scene extent that separates clone (at most) from split (above).
    pub percent_dense: f32,
    /// Scene extent (3DGS: the radius of the cameras times 1.1).
    pub extent: f32,
    /// Gaussians with a lower opacity are pruned.
    pub min_opacity: f32,
    /// Also prune Gaussians whose largest scale exceeds 0.1 * extent.
    pub prune_large: bool,
    /// Hard cap on the Gaussians after the step.
    pub max_gaussians: u32,
    /// Seed of the split children's offsets.
    pub seed: u64,
}

impl Default for DensifyConfig {
    fn default() -> Self {
        DensifyConfig {
            grad_threshold: 0.0002,
            percent_dense: 0.01,
            extent: 1.0,
            min_opacity: 0.005,
            prune_large: false,
            max_gaussians: u32::MAX,
            seed: 0,
        }
    }
}

impl DensifyConfig {
    fn validate(&self) -> Result<()> {
        ensure!(
            self.grad_threshold.is_finite(),
            "densify: grad_threshold must be finite, got {}",
            self.grad_threshold
        );
        ensure!(
            self.percent_dense > 0.0 && self.percent_dense.is_finite(),
            "densify: percent_dense must be positive, got {}",
            self.percent_dense
        );
        ensure!(
            self.extent > 0.0 && self.extent.is_finite(),
            "densify: extent must be positive, got {}",
            self.extent
        );
        ensure!(
            (0.0..=1.0).contains(&self.min_opacity),
            "densify: min_opacity must be in [0, 1], got {}",
            self.min_opacity
        );
        Ok(())
    }

    /// ln(fraction * extent), computed in f64 on the host: the kernels compare log-scales
    /// against it without exp, so they agree with any device's exp.
    fn ln_extent(&self, fraction: f64) -> f32 {
        (fraction * self.extent as f64).ln() as f32
    }
}

/// The per-Gaussian tensors a plan reads (f32, structure-of-arrays, `n` Gaussians).
#[derive(Clone, Copy)]
pub struct DensifyInputs<'a> {
    pub n: u32,
    /// `[n * 3]`
    pub log_scales: &'a Buffer,
    /// `[n * 4]`, w x y z, unnormalized
    pub quats: &'a Buffer,
    /// `[n]`
    pub opacity_logits: &'a Buffer,
    /// `[n]`: sum over views of the 2D-mean gradient norm
    pub grad_accum: &'a Buffer,
    /// `[n]`: views in which the Gaussian was visible
    pub grad_count: &'a Buffer,
}

impl DensifyInputs<'_> {
    /// Checks the count against the cap and every buffer against the count.
    fn check(&self, config: &DensifyConfig) -> Result<()> {
        let n = self.n;
        ensure!(
            n <= config.max_gaussians,
            "densify: {n} Gaussians already exceed max_gaussians = {}",
            config.max_gaussians
        );
        let n64 = n as u64;
        for (name, buf, width) in [
            ("log_scales", self.log_scales, 3),
            ("quats", self.quats, 4),
            ("opacity_logits", self.opacity_logits, 1),
            ("grad_accum", self.grad_accum, 1),
            ("grad_count", self.grad_count, 1),
        ] {
            ensure!(
                buf.size() >= n64 * width * 4,
                "densify: {name} holds {} bytes, {n} Gaussians need {}",
                buf.size(),
                n64 * width * 4
            );
        }
        Ok(())
    }
}

/// The outcome of [`Densifier::plan`]: counts for logging, and the key to apply it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct DensifyPlan {
    /// Gaussians before the step.
    pub n: u32,
    /// Gaussians after the step: `n - pruned + cloned + split`.
    pub new_n: u32,
    pub pruned: u32,
    /// Gaussians cloned (each adds one copy).
    pub cloned: u32,
    /// Gaussians split (each replaced by two children).
    pub split: u32,
    /// Survivors whose gradient asked for densification, before the cap.
    pub candidates: u32,
    /// Which plan of its densifier this is: apply refuses a plan that a later one replaced.
    generation: u64,
}

impl DensifyPlan {
    /// Candidates left out by `max_gaussians`.
    pub fn capped(&self) -> u32 {
        self.candidates - self.cloned - self.split
    }
}

/// How [`Densifier::apply`] builds a tensor of the new set from the old one.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Role {
    /// Every output is a copy of its source (quats, opacity logits, SH, semantic logits).
    Copy,
    /// An Adam moment (m or v) of any parameter: kept Gaussians keep it, new ones get 0.
    AdamMoment,
    /// Means (width 3): split children add their offset (computed by the plan from the
    /// parents' scales and rotations).
    Means,
    /// Log-scales (width 3): split children get `log_scales - ln(1.6)`.
    LogScales,
    /// Every output is 0 (gradient statistics, restarted after the step).
    Zeroed,
}

impl Role {
    /// How a Gaussian parameter tensor is rebuilt: split children move their means and
    /// shrink their scales; they copy everything else.
    pub fn of(param: ParamTensor) -> Role {
        match param {
            ParamTensor::Means => Role::Means,
            ParamTensor::LogScales => Role::LogScales,
            ParamTensor::Quats | ParamTensor::OpacityLogits | ParamTensor::Sh => Role::Copy,
        }
    }
}

/// Scratch of a plan, sized for `n_cap` Gaussians in and `slot_cap` out.
struct PlanBuffers {
    n_cap: u64,
    slot_cap: u64,
    status: Buffer,
    /// `[n + 1]` flags and their exclusive scan: where each candidate is compacted to.
    candidate_flags: Buffer,
    candidate_offsets: Buffer,
    /// Compacted candidates: descending-gradient sort keys and their Gaussian indices.
    candidate_keys: Buffer,
    candidate_ids: Buffer,
    /// `[n + 1]` output slots per Gaussian (0, 1, 2) and their exclusive scan.
    out_count: Buffer,
    out_offsets: Buffer,
    /// Per output slot: source Gaussian, kind (SLOT_*), mean offset (xyz, 0 unless split).
    slot_source: Buffer,
    slot_kind: Buffer,
    slot_mean_delta: Buffer,
    scan: PrefixScan,
    sort: RadixSort,
}

impl PlanBuffers {
    fn new(gpu: &Gpu, n_cap: u64, slot_cap: u64) -> Result<PlanBuffers> {
        let b = |name: &str, bytes: u64| gpu.buffer(name, bytes);
        Ok(PlanBuffers {
            n_cap,
            slot_cap,
            status: b("densify-status", DS_WORDS * 4)?,
            candidate_flags: b("candidate_flags", (n_cap + 1) * 4)?,
            candidate_offsets: b("candidate_offsets", (n_cap + 1) * 4)?,
            candidate_keys: b("candidate_keys", n_cap * 4)?,
            candidate_ids: b("candidate_ids", n_cap * 4)?,
            out_count: b("out_count", (n_cap + 1) * 4)?,
            out_offsets: b("out_offsets", (n_cap + 1) * 4)?,
            slot_source: b("slot_source", slot_cap * 4)?,
            slot_kind: b("slot_kind", slot_cap * 4)?,
            slot_mean_delta: b("slot_mean_delta", slot_cap * 12)?,
            scan: PrefixScan::new(gpu, n_cap + 1)?,
            sort: RadixSort::new(gpu, n_cap)?,
        })
    }
}

impl PlanBuffers {
    /// Records the choice of what each Gaussian becomes: classify (prune, candidate,
    /// output slots), compact the candidates, sort them by gradient when the cap bites,
    /// and select the densified ones.
    fn record_select(
        &self,
        rec: &mut Recorder,
        inputs: &DensifyInputs,
        config: &DensifyConfig,
    ) -> Result<()> {
        let n = inputs.n;
        // The opacity threshold moves to logit space on the host (in f64), as the scale
        // thresholds move to log space.
        let logit = |p: f64| (p / (1.0 - p)).ln();
        let classify = DensifyClassifyParams {
            log_scales_addr: inputs.log_scales.address_words(4)?,
            opacity_logits_addr: inputs.opacity_logits.address_words(4)?,
            grad_accum_addr: inputs.grad_accum.address_words(4)?,
            grad_count_addr: inputs.grad_count.address_words(4)?,
            candidate_flags_addr: self.candidate_flags.address_words(4)?,
            out_count_addr: self.out_count.address_words(4)?,
            n,
            grad_threshold: config.grad_threshold,
            opacity_logit_min: logit(config.min_opacity as f64) as f32,
            ln_prune_scale: if config.prune_large {
                config.ln_extent(0.1)
            } else {
                f32::INFINITY
            },
        };
        // One write of the whole status (zeros and n + 1): two overlapping fills would
        // race without a barrier between them.
        let mut status = [0u32; DS_WORDS as usize];
        status[DS_N_PLUS1 as usize] = n + 1;
        rec.update(&self.status, 0, bytemuck::cast_slice(&status));
        rec.barrier();
        rec.dispatch(
            ids::TRAIN_DENSIFY_CLASSIFY,
            &[("status", &self.status)],
            &classify,
            ids::TRAIN_DENSIFY_CLASSIFY.groups_for(n + 1),
        )?;
        rec.barrier();
        self.scan.record(
            rec,
            &self.candidate_flags,
            &self.candidate_offsets,
            GpuCount::at(&self.status, DS_N_PLUS1),
        )?;
        self.record_compact(rec, inputs, config)?;
        rec.dispatch(
            ids::TRAIN_DENSIFY_SELECT,
            &[("status", &self.status)],
            &DensifySelectParams {
                candidate_ids_addr: self.candidate_ids.address_words(4)?,
                out_count_addr: self.out_count.address_words(4)?,
            },
            ids::TRAIN_DENSIFY_SELECT.groups_for(n),
        )?;
        rec.barrier();
        Ok(())
    }

    /// Records compacting the candidates into sort keys and, when the cap can leave some
    /// out, their sort.
    fn record_compact(
        &self,
        rec: &mut Recorder,
        inputs: &DensifyInputs,
        config: &DensifyConfig,
    ) -> Result<()> {
        let n64 = inputs.n as u64;
        rec.dispatch(
            ids::TRAIN_DENSIFY_COMPACT,
            &[("status", &self.status)],
            &DensifyCompactParams {
                grad_accum_addr: inputs.grad_accum.address_words(4)?,
                grad_count_addr: inputs.grad_count.address_words(4)?,
                candidate_flags_addr: self.candidate_flags.address_words(4)?,
                candidate_offsets_addr: self.candidate_offsets.address_words(4)?,
                candidate_keys_addr: self.candidate_keys.address_words(4)?,
                candidate_ids_addr: self.candidate_ids.address_words(4)?,
                n: inputs.n,
                max_gaussians: config.max_gaussians,
            },
            ids::TRAIN_DENSIFY_COMPACT.groups_for(inputs.n + 1),
        )?;
        rec.barrier();
        // Only a budget below 2n can leave candidates out; then the largest gradients go
        // first. Otherwise every candidate is densified and their order does not matter.
        if 2 * n64 > config.max_gaussians as u64 {
            self.sort.record(
                rec,
                &self.candidate_keys,
                &self.candidate_ids,
                GpuCount::at(&self.status, DS_CANDIDATES as u32),
                32,
            )?;
        }
        Ok(())
    }

    /// Records the layout of the new set: each Gaussian's first output slot (a scan of
    /// its output counts), and per slot its source, kind and mean offset.
    fn record_layout(
        &self,
        rec: &mut Recorder,
        inputs: &DensifyInputs,
        config: &DensifyConfig,
    ) -> Result<()> {
        self.scan.record(
            rec,
            &self.out_count,
            &self.out_offsets,
            GpuCount::at(&self.status, DS_N_PLUS1),
        )?;
        let layout = DensifyLayoutParams {
            n: inputs.n,
            ln_split_scale: config.ln_extent(config.percent_dense as f64),
            seed: [config.seed as u32, (config.seed >> 32) as u32],
            log_scales_addr: inputs.log_scales.address_words(4)?,
            quats_addr: inputs.quats.address_words(16)?,
            out_offsets_addr: self.out_offsets.address_words(4)?,
            slot_source_addr: self.slot_source.address_words(4)?,
            slot_kind_addr: self.slot_kind.address_words(4)?,
            slot_mean_delta_addr: self.slot_mean_delta.address_words(4)?,
        };
        rec.dispatch(
            ids::TRAIN_DENSIFY_LAYOUT,
            &[("status", &self.status)],
            &layout,
            ids::TRAIN_DENSIFY_LAYOUT.groups_for(inputs.n + 1),
        )?;
        Ok(())
    }

    /// Downloads the plan's counts (after its submission) into `plan`, checking that they
    /// agree with each other and the cap.
    fn read_counts(&self, gpu: &Gpu, plan: &mut DensifyPlan, config: &DensifyConfig) -> Result<()> {
        let status: Vec<u32> = gpu.download(&self.status, 0, DS_WORDS as usize)?;
        plan.new_n = status[DS_NEW_N];
        plan.pruned = plan.n - status[DS_SURVIVORS];
        plan.cloned = status[DS_CLONED];
        plan.split = status[DS_SPLIT];
        plan.candidates = status[DS_CANDIDATES];
        let densified = status[DS_DENSIFIED];
        ensure!(
            plan.cloned + plan.split == densified
                && plan.new_n == status[DS_SURVIVORS] + densified
                && plan.new_n <= config.max_gaussians,
            "densify: inconsistent plan counts {status:?}"
        );
        Ok(())
    }
}

/// Grows a capacity by half again when it must grow, within `limit`.
fn grow(current: u64, need: u64, limit: u64) -> u64 {
    if need <= current {
        current
    } else {
        need.max((current + current / 2).min(limit))
    }
}

/// Plans and applies densify-and-prune steps; reuses its scratch buffers across steps.
pub struct Densifier {
    gpu: Gpu,
    bufs: Option<PlanBuffers>,
    generation: u64,
}

impl Densifier {
    pub fn new(gpu: &Gpu) -> Densifier {
        Densifier {
            gpu: gpu.clone(),
            bufs: None,
            generation: 0,
        }
    }

    /// The most Gaussians one plan can take in: one invocation per Gaussian in one dispatch
    /// dimension, and every `[n + 1]` array indexable (the kernels reach them by address).
    fn max_n(&self) -> u64 {
        let caps = self.gpu.caps();
        (i32::MAX as u64 - 1).min(caps.max_workgroup_count[0] as u64 * WG_SIZE as u64 - 1)
    }

    fn ensure(&mut self, n: u64, slots: u64) -> Result<()> {
        let n_limit = self.max_n();
        // Every slot's mean offset (3 floats) indexable by the kernels' signed 32-bit index.
        let slot_limit = i32::MAX as u64 / 3;
        ensure!(
            n <= n_limit && slots <= slot_limit,
            "densify: {n} Gaussians ({slots} after the step) exceed this device's limits \
             ({n_limit} in, {slot_limit} out)"
        );
        let fits = self
            .bufs
            .as_ref()
            .is_some_and(|b| n <= b.n_cap && slots <= b.slot_cap);
        if !fits {
            let (n_cap, slot_cap) = match &self.bufs {
                Some(b) => (
                    grow(b.n_cap, n, n_limit),
                    grow(b.slot_cap, slots, slot_limit),
                ),
                None => (n, slots),
            };
            self.bufs = None; // free before allocating the larger set
            self.bufs = Some(PlanBuffers::new(&self.gpu, n_cap.max(1), slot_cap.max(1))?);
        }
        Ok(())
    }

    /// Decides which Gaussians are pruned, cloned and split, and lays out the new set on
    /// the GPU. Waits for the GPU and downloads the counts. The plan stays valid for
    /// [`Densifier::apply`] until the next call.
    pub fn plan(&mut self, inputs: &DensifyInputs, config: &DensifyConfig) -> Result<DensifyPlan> {
        config.validate()?;
        inputs.check(config)?;
        let n = inputs.n;
        self.generation += 1;
        let mut plan = DensifyPlan {
            n,
            new_n: 0,
            pruned: 0,
            cloned: 0,
            split: 0,
            candidates: 0,
            generation: self.generation,
        };
        if n == 0 {
            return Ok(plan);
        }
        let n64 = n as u64;
        let slots = (2 * n64).min(config.max_gaussians as u64);
        self.ensure(n64, slots)?;
        let b = self.bufs.as_ref().expect("ensured");
        let mut rec = Recorder::new(&self.gpu)?;
        b.record_select(&mut rec, inputs, config)?;
        b.record_layout(&mut rec, inputs, config)?;
        rec.submit_and_wait()?;
        b.read_counts(&self.gpu, &mut plan, config)?;
        Ok(plan)
    }

    /// Records the building of one tensor of the new set (`width` f32 per Gaussian) from
    /// `tensor`, the same tensor of the set the plan was made on, and returns the new
    /// buffer (`plan.new_n * width` f32). Submit `rec` before reading it, and keep this
    /// densifier and `tensor` alive until then.
    pub fn apply(
        &self,
        rec: &mut Recorder,
        plan: &DensifyPlan,
        tensor: &Buffer,
        width: u32,
        role: Role,
    ) -> Result<Buffer> {
        let elements = self.check_apply(plan, tensor, width, role)?;
        let out = self.gpu.buffer(tensor.name(), elements * 4)?;
        let role = match role {
            Role::Zeroed => {
                rec.fill(&out, 0, elements * 4, 0);
                rec.barrier();
                return Ok(out);
            }
            Role::Copy => ROLE_COPY,
            Role::AdamMoment => ROLE_MOMENT,
            Role::Means => ROLE_MEANS,
            Role::LogScales => ROLE_LOG_SCALES,
        };
        if elements == 0 {
            return Ok(out);
        }
        let params = GatherParams {
            elements: 0, // per part
            width,
            role,
            ln_split_shrink: 1.6f64.ln() as f32,
            first_slot: 0,
            src_first: 0,
            src_count: plan.n,
            // Set by record_gather.
            slot_source_addr: [0; 2],
            slot_kind_addr: [0; 2],
            slot_mean_delta_addr: [0; 2],
        };
        self.record_gather(rec, tensor, &out, &params, plan)?;
        Ok(out)
    }

    /// Checks that `plan` is this densifier's latest and that `tensor` fits it; returns
    /// the floats of the tensor after the step.
    fn check_apply(
        &self,
        plan: &DensifyPlan,
        tensor: &Buffer,
        width: u32,
        role: Role,
    ) -> Result<u64> {
        ensure!(
            plan.generation == self.generation,
            "densify: this plan was replaced by a later plan of the same densifier"
        );
        ensure!(
            width > 0,
            "densify: {}: width must be positive",
            tensor.name()
        );
        if matches!(role, Role::Means | Role::LogScales) {
            ensure!(
                width == 3,
                "densify: {}: {role:?} has width 3, got {width}",
                tensor.name()
            );
        }
        let in_bytes = plan.n as u64 * width as u64 * 4;
        ensure!(
            tensor.size() >= in_bytes,
            "densify: {} holds {} bytes, {} Gaussians of width {width} need {in_bytes}",
            tensor.name(),
            tensor.size(),
            plan.n
        );
        // Gathered in parts that fit one binding each (`record_gather`).
        Ok(plan.new_n as u64 * width as u64)
    }

    /// Records the gather of `tensor` into `out` by the plan's slots: in parts of slots
    /// and of source Gaussians whose ranges of the two tensors each fit one binding.
    fn record_gather(
        &self,
        rec: &mut Recorder,
        tensor: &Buffer,
        out: &Buffer,
        whole: &GatherParams,
        plan: &DensifyPlan,
    ) -> Result<()> {
        let b = self
            .bufs
            .as_ref()
            .expect("a plan with Gaussians has buffers");
        let row_bytes = whole.width as u64 * 4;
        let caps = self.gpu.caps();
        let part = chunk_len(row_bytes, 0, caps.max_storage_buffer_range)
            .context("densify: one Gaussian's row is wider than one binding")?;
        for slots in chunks(plan.new_n, part) {
            for sources in chunks(plan.n, part) {
                let params = GatherParams {
                    elements: slots.len() as u32 * whole.width,
                    first_slot: slots.start,
                    src_first: sources.start,
                    src_count: sources.len() as u32,
                    slot_source_addr: b.slot_source.address_words(4)?,
                    slot_kind_addr: b.slot_kind.address_words(4)?,
                    slot_mean_delta_addr: b.slot_mean_delta.address_words(4)?,
                    ..*whole
                };
                // A 2D grid: one element per invocation can pass 65,535 workgroups.
                let total = (params.elements as u64).div_ceil(WG_SIZE as u64);
                let gx = total.min(caps.max_workgroup_count[0] as u64);
                let gy = total.div_ceil(gx);
                rec.dispatch_ranges(
                    ids::TRAIN_DENSIFY_GATHER,
                    &[
                        ("src", part_of(tensor, &sources, row_bytes)),
                        ("dst", part_of(out, &slots, row_bytes)),
                    ],
                    &params,
                    [gx as u32, gy as u32, 1],
                )?;
            }
        }
        rec.barrier();
        Ok(())
    }
}

/// Records 3DGS's opacity reset on `n` Gaussians: every opacity becomes at most
/// `max_opacity` ([`OPACITY_RESET`] in 3DGS), i.e. `opacity_logits = min(opacity_logits,
/// logit(max_opacity))`, and the opacity's Adam moments (`moments`, `[n]` each) restart
/// at zero.
pub fn reset_opacity(
    rec: &mut Recorder,
    n: u32,
    opacity_logits: &Buffer,
    moments: &[&Buffer],
    max_opacity: f32,
) -> Result<()> {
    ensure!(
        max_opacity > 0.0 && max_opacity < 1.0,
        "opacity reset: max_opacity must be in (0, 1), got {max_opacity}"
    );
    let bytes = n as u64 * 4;
    for buf in std::iter::once(&opacity_logits).chain(moments) {
        ensure!(
            buf.size() >= bytes,
            "opacity reset: {} holds {} bytes, {n} Gaussians need {bytes}",
            buf.name(),
            buf.size()
        );
    }
    let p = max_opacity as f64;
    let params = ResetOpacityParams {
        opacity_logits_addr: opacity_logits.address_words(4)?,
        n,
        max_logit: (p / (1.0 - p)).ln() as f32,
    };
    rec.dispatch(
        ids::TRAIN_DENSIFY_RESET_OPACITY,
        &[],
        &params,
        ids::TRAIN_DENSIFY_RESET_OPACITY.groups_for(n),
    )?;
    for m in moments {
        rec.fill(m, 0, bytes, 0);
    }
    rec.barrier();
    Ok(())
}
