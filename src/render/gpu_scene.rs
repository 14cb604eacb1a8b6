//! A scene's Gaussians uploaded once, structure-of-arrays as the kernels read them, and
//! [`GaussianParams`], the one list of their parameter tensors.

use std::borrow::Cow;
use std::ops::{Index, Range};

use glam::DVec3;

use crate::gpu::kernel_table::ids;
use crate::gpu::{Buffer, BufferRange, Gpu, GpuError, GpuResult, Recorder};
use crate::scene::gaussians::SemanticLogits;
use crate::scene::{Camera, Gaussians};

use super::chunks::part_of;
use super::SemanticMode;
use crate::contract::params::SoftmaxParams;

/// One of a Gaussian's parameter tensors; a key into [`GaussianParams`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum ParamTensor {
    Means,
    LogScales,
    Quats,
    OpacityLogits,
    Sh,
}

impl ParamTensor {
    /// Every tensor, in the order of [`GaussianParams`]'s fields (and of every loop over
    /// them: uploads, downloads, Adam steps, densify gathers).
    pub const ALL: [ParamTensor; 5] = [
        ParamTensor::Means,
        ParamTensor::LogScales,
        ParamTensor::Quats,
        ParamTensor::OpacityLogits,
        ParamTensor::Sh,
    ];

    /// The tensor's name: its buffer's name, and its binding name in the kernels (the
    /// gradient's is `grad_` + this).
    pub fn name(self) -> &'static str {
        match self {
            ParamTensor::Means => "means",
            ParamTensor::LogScales => "log_scales",
            ParamTensor::Quats => "quats",
            ParamTensor::OpacityLogits => "opacity_logits",
            ParamTensor::Sh => "sh",
        }
    }

    /// Floats per Gaussian: xyz, log-scale xyz, quaternion wxyz, one logit, RGB per SH
    /// coefficient.
    pub fn floats(self, sh_coeffs: u32) -> u32 {
        match self {
            ParamTensor::Means | ParamTensor::LogScales => 3,
            ParamTensor::Quats => 4,
            ParamTensor::OpacityLogits => 1,
            ParamTensor::Sh => 3 * sh_coeffs,
        }
    }
}

/// One value per parameter tensor of a Gaussian set: the tensors themselves (on the device
/// or the host), their gradients, their optimizer state, anything kept per tensor.
///
/// The semantic logits are not a field: fusion scenes have none, their width is the
/// scene's class count (not set by the SH degree), and training treats them apart
/// (`--semantics-only` trains them alone). Holders keep them in an `Option` beside this.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct GaussianParams<T> {
    pub means: T,
    pub log_scales: T,
    pub quats: T,
    pub opacity_logits: T,
    pub sh: T,
}

impl<T> GaussianParams<T> {
    /// Builds each field from its tensor, calling `f` in [`ParamTensor::ALL`] order.
    pub fn from_fn(mut f: impl FnMut(ParamTensor) -> T) -> GaussianParams<T> {
        GaussianParams {
            means: f(ParamTensor::Means),
            log_scales: f(ParamTensor::LogScales),
            quats: f(ParamTensor::Quats),
            opacity_logits: f(ParamTensor::OpacityLogits),
            sh: f(ParamTensor::Sh),
        }
    }

    /// [`GaussianParams::from_fn`] that stops at the first error.
    pub fn try_from_fn<E>(
        f: impl FnMut(ParamTensor) -> Result<T, E>,
    ) -> Result<GaussianParams<T>, E> {
        GaussianParams::from_fn(|p| p).try_map(f)
    }

    /// A reference to every field.
    pub fn as_ref(&self) -> GaussianParams<&T> {
        GaussianParams::from_fn(|p| &self[p])
    }

    /// Applies `f` to every field, in [`ParamTensor::ALL`] order; stops at the first
    /// error.
    pub fn try_map<U, E>(
        self,
        mut f: impl FnMut(T) -> Result<U, E>,
    ) -> Result<GaussianParams<U>, E> {
        Ok(GaussianParams {
            means: f(self.means)?,
            log_scales: f(self.log_scales)?,
            quats: f(self.quats)?,
            opacity_logits: f(self.opacity_logits)?,
            sh: f(self.sh)?,
        })
    }

    /// The fields in [`ParamTensor::ALL`] order.
    pub fn into_array(self) -> [T; 5] {
        [
            self.means,
            self.log_scales,
            self.quats,
            self.opacity_logits,
            self.sh,
        ]
    }

    /// Every tensor with its value, in [`ParamTensor::ALL`] order.
    pub fn iter(&self) -> impl Iterator<Item = (ParamTensor, &T)> {
        ParamTensor::ALL.into_iter().map(move |p| (p, &self[p]))
    }
}

impl<A, B> GaussianParams<(A, B)> {
    /// Pairs per tensor into one set of each.
    pub fn unzip(self) -> (GaussianParams<A>, GaussianParams<B>) {
        let [means, log_scales, quats, opacity_logits, sh] = self.into_array();
        (
            GaussianParams {
                means: means.0,
                log_scales: log_scales.0,
                quats: quats.0,
                opacity_logits: opacity_logits.0,
                sh: sh.0,
            },
            GaussianParams {
                means: means.1,
                log_scales: log_scales.1,
                quats: quats.1,
                opacity_logits: opacity_logits.1,
                sh: sh.1,
            },
        )
    }
}

/// Parameter tensors (or their gradients) downloaded to the host, f32 each.
pub type HostParams = GaussianParams<Vec<f32>>;

impl<T> Index<ParamTensor> for GaussianParams<T> {
    type Output = T;

    fn index(&self, p: ParamTensor) -> &T {
        match p {
            ParamTensor::Means => &self.means,
            ParamTensor::LogScales => &self.log_scales,
            ParamTensor::Quats => &self.quats,
            ParamTensor::OpacityLogits => &self.opacity_logits,
            ParamTensor::Sh => &self.sh,
        }
    }
}

impl GaussianParams<Buffer> {
    /// Downloads the first `n` Gaussians of every tensor, and the `extra` ranges, in one
    /// transfer; returns the tensors and the extra ranges, each as f32.
    pub(crate) fn download_with(
        &self,
        gpu: &Gpu,
        n: u32,
        sh_coeffs: u32,
        extra: &[(&Buffer, u64, u64)],
    ) -> GpuResult<(HostParams, Vec<Vec<f32>>)> {
        let mut ranges: Vec<(&Buffer, u64, u64)> = self
            .iter()
            .map(|(p, b)| (b, 0, n as u64 * p.floats(sh_coeffs) as u64 * 4))
            .collect();
        ranges.extend_from_slice(extra);
        let mut parts = gpu
            .download_many(&ranges)?
            .into_iter()
            .map(|bytes| bytemuck::pod_collect_to_vec::<u8, f32>(&bytes));
        let params = GaussianParams::from_fn(|_| parts.next().expect("one part per range"));
        Ok((params, parts.collect()))
    }
}

/// How many widths of a scene its center may lie from the world origin before the device
/// works relative to the center: float32's relative error (6e-8) times this stays far under
/// a pixel of any view, and scenes built around the origin keep their bytes.
pub const FAR_FROM_ORIGIN: f64 = 16.0;

/// The origin of the device's coordinates for a scene of these means: the center of their
/// bounding box where it lies farther from the world origin than [`FAR_FROM_ORIGIN`] times
/// the box's width (at least a metre), as a georeferenced capture does (10^6 m away, a
/// camera-space point computed in float32 from world coordinates is off by centimetres,
/// which moved Gaussians' center pixels and depths); else the world origin, so a scene
/// around it uploads its means as they are.
pub fn device_origin(means: &[[f32; 3]]) -> DVec3 {
    let points = means.iter().map(|m| DVec3::from(m.map(f64::from)));
    let Some((lo, hi)) = points.fold(None, |acc: Option<(DVec3, DVec3)>, m| {
        Some(acc.map_or((m, m), |(lo, hi)| (lo.min(m), hi.max(m))))
    }) else {
        return DVec3::ZERO;
    };
    let center = 0.5 * (lo + hi);
    let width = (hi - lo).max_element().max(1.0);
    if center.abs().max_element() > FAR_FROM_ORIGIN * width {
        // Whole metres: the world's coordinates of the device's are then exact.
        center.round()
    } else {
        DVec3::ZERO
    }
}

/// `g`'s parameter tensors as the flat f32 arrays the device holds.
fn host_tensors(g: &Gaussians) -> GaussianParams<&[f32]> {
    GaussianParams {
        means: g.means.as_flattened(),
        log_scales: g.log_scales.as_flattened(),
        quats: g.quats.as_flattened(),
        opacity_logits: &g.opacity_logits,
        sh: &g.sh,
    }
}

/// Which attributes of a scene the work on the device reads: each use uploads only those.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum SceneAttributes {
    /// The centers (plain vote).
    Centers,
    /// Centers, scales, rotations and opacity: what projection and blending read apart
    /// from colour (the weighted fusion methods and the occlusion depth).
    Geometry,
    /// Everything: SH colour and semantic logits too (rendering, evaluation, training).
    Full,
}

impl SceneAttributes {
    /// Whether a scene uploaded with these attributes holds tensor `p`.
    pub fn holds(self, p: ParamTensor) -> bool {
        match p {
            ParamTensor::Means => true,
            ParamTensor::Sh => self == SceneAttributes::Full,
            _ => self >= SceneAttributes::Geometry,
        }
    }
}

/// Gaussians on the device. Semantic logits are optional; their softmax is computed on
/// the device the first time the softmax mode asks for it. Tensors a scene was not
/// uploaded with ([`SceneAttributes`]) are 4-byte placeholders.
pub struct GpuScene {
    pub n: u32,
    /// SH degree, and coefficients per colour channel (0: uploaded without colour).
    pub sh_degree: u32,
    pub sh_coeffs: u32,
    /// Semantic channels C (0 without semantics).
    pub channels: u32,
    pub attributes: SceneAttributes,
    /// Per Gaussian, a class index below `channels` (or NO_LABEL) whose one-hot vector
    /// stands in for semantic logits: such a scene renders label maps (the argmax per
    /// pixel, [`crate::render::Rasterizer::last_labels`]) without a C-vector per Gaussian or
    /// per pixel. None for scenes with logits or none.
    pub(crate) class_index: Option<Buffer>,
    pub(crate) params: GaussianParams<Buffer>,
    /// [n * C]
    pub(crate) logits: Option<Buffer>,
    pub(crate) probs: std::sync::OnceLock<Buffer>,
    /// Where the device's coordinates have their origin, in world coordinates
    /// ([`device_origin`]): the means are uploaded relative to it, and every camera a
    /// kernel reads is moved with it ([`GpuScene::local_camera`]).
    pub origin: DVec3,
}

impl GpuScene {
    /// Uploads all of `g` (see [`GpuScene::upload_for`]).
    pub fn upload(gpu: &Gpu, g: &Gaussians) -> GpuResult<GpuScene> {
        GpuScene::upload_for(gpu, g, SceneAttributes::Full)
    }

    /// Uploads the parts of `g` that `attributes` names.
    pub fn upload_for(
        gpu: &Gpu,
        g: &Gaussians,
        attributes: SceneAttributes,
    ) -> GpuResult<GpuScene> {
        // Per-Gaussian kernels run one invocation per Gaussian (and one more for a scan's
        // trailing zero) in one dimension of workgroups of 256: 16.7M Gaussians where the
        // device allows 65,535 workgroups (lavapipe); NVIDIA allows 2^31 - 1.
        let max_n = gpu.caps().max_workgroup_count[0] as u64 * 256 - 1;
        if g.len() as u64 > max_n {
            return Err(GpuError::Limit(format!(
                "a scene of {} Gaussians is more than one dispatch covers on this device \
                 ({max_n}: {} workgroups of 256); split the scene",
                g.len(),
                gpu.caps().max_workgroup_count[0]
            )));
        }
        let (channels, logits) = match &g.semantics {
            Some(s) if s.channels > 0 && attributes == SceneAttributes::Full => (
                s.channels as u32,
                Some(gpu.buffer_from("logits", &s.logits)?),
            ),
            _ => (0, None),
        };
        let origin = device_origin(&g.means);
        let local_means: Option<Vec<f32>> = (origin != DVec3::ZERO).then(|| {
            g.means
                .iter()
                .flat_map(|m| {
                    (DVec3::from(m.map(f64::from)) - origin)
                        .as_vec3()
                        .to_array()
                })
                .collect()
        });
        let mut host = host_tensors(g);
        if let Some(means) = &local_means {
            host.means = means;
        }
        let colour = attributes.holds(ParamTensor::Sh);
        Ok(GpuScene {
            n: g.len() as u32,
            sh_degree: if colour { g.sh_degree } else { 0 },
            sh_coeffs: if colour { g.sh_coeffs() as u32 } else { 0 },
            channels,
            attributes,
            class_index: None,
            params: GaussianParams::try_from_fn(|p| {
                if attributes.holds(p) {
                    gpu.buffer_from(p.name(), host[p])
                } else {
                    gpu.buffer(&format!("{} (not uploaded)", p.name()), 4)
                }
            })?,
            logits,
            probs: std::sync::OnceLock::new(),
            origin,
        })
    }

    /// Means downloaded from the device, moved back into world coordinates.
    pub(crate) fn means_to_world(&self, means: &mut [[f32; 3]]) {
        if self.origin != DVec3::ZERO {
            for m in means {
                *m = (DVec3::from(m.map(f64::from)) + self.origin)
                    .as_vec3()
                    .to_array();
            }
        }
    }

    /// `cam` in the device's coordinates (the world moved by -[`GpuScene::origin`]): what
    /// every kernel that projects this scene's means is given. `cam` itself (no copy) for a
    /// scene uploaded as it is.
    pub(crate) fn local_camera<'c>(&self, cam: &'c Camera) -> Cow<'c, Camera> {
        if self.origin == DVec3::ZERO {
            return Cow::Borrowed(cam);
        }
        Cow::Owned(Camera {
            translation: cam.translation + cam.rotation * self.origin,
            ..cam.clone()
        })
    }

    /// Uploads `g` (without its logits) with one class per Gaussian for label rendering:
    /// `class_index[i]` below `classes`, or NO_LABEL for a Gaussian that blends zeros (it
    /// still occludes).
    pub fn upload_with_classes(
        gpu: &Gpu,
        g: &Gaussians,
        class_index: &[u32],
        classes: u32,
    ) -> GpuResult<GpuScene> {
        assert_eq!(class_index.len(), g.len(), "one class index per Gaussian");
        let mut scene = GpuScene::upload_for(gpu, g, SceneAttributes::Full)?;
        scene.logits = None;
        scene.channels = classes;
        scene.class_index = Some(gpu.buffer_from("class_index", class_index)?);
        Ok(scene)
    }

    /// Bytes this scene holds on the device (parameters and semantic logits).
    pub fn device_bytes(&self) -> u64 {
        let params: u64 = self.params.iter().map(|(_, b)| b.size()).sum();
        params + self.logits.as_ref().map_or(0, |b| b.size())
    }

    /// Gaussians `range` of tensor `p`, for a pass split into chunks; a placeholder (a
    /// tensor not uploaded) is bound whole.
    pub(crate) fn param_range(&self, p: ParamTensor, range: &Range<u32>) -> BufferRange<'_> {
        let buf = &self.params[p];
        if !self.attributes.holds(p) {
            return BufferRange::whole(buf);
        }
        part_of(buf, range, p.floats(self.sh_coeffs) as u64 * 4)
    }

    /// The per-Gaussian semantic vectors blended in `mode` (None without semantics).
    pub(crate) fn semantics(&self, gpu: &Gpu, mode: SemanticMode) -> GpuResult<Option<&Buffer>> {
        let Some(logits) = &self.logits else {
            return Ok(None);
        };
        match mode {
            SemanticMode::RawLogits => Ok(Some(logits)),
            SemanticMode::Softmax => {
                if self.probs.get().is_none() {
                    let mut rec = Recorder::new(gpu)?;
                    self.record_softmax(&mut rec)?;
                    rec.submit_and_wait()?;
                }
                Ok(self.probs.get())
            }
        }
    }

    /// Records (re)computing softmax(logits) into the probabilities the softmax mode
    /// blends; training calls it every iteration since the logits change.
    pub(crate) fn record_softmax(&self, rec: &mut Recorder) -> GpuResult<()> {
        let Some(logits) = &self.logits else {
            return Ok(());
        };
        if self.probs.get().is_none() {
            let bytes = self.n.max(1) as u64 * self.channels as u64 * 4;
            let _ = self.probs.set(rec.gpu().buffer("probs", bytes)?);
        }
        let probs = self.probs.get().expect("set above");
        rec.dispatch(
            ids::RASTER_SOFTMAX,
            &[],
            &SoftmaxParams {
                n: self.n,
                channels: self.channels,
                logits_addr: logits.address_words(4)?,
                probs_addr: probs.address_words(4)?,
            },
            ids::RASTER_SOFTMAX.groups_for(self.n),
        )?;
        rec.barrier();
        Ok(())
    }

    /// Downloads the parameters into `g`'s arrays (which must have this scene's shape:
    /// training changes values, and densification rebuilds `g` to the new count first).
    pub fn download_into(&self, gpu: &Gpu, g: &mut Gaussians) -> GpuResult<()> {
        let logits_bytes = self.n as u64 * self.channels as u64 * 4;
        let extra: Vec<(&Buffer, u64, u64)> =
            self.logits.iter().map(|b| (b, 0, logits_bytes)).collect();
        let (params, mut extra) = self
            .params
            .download_with(gpu, self.n, self.sh_coeffs, &extra)?;
        g.means = bytemuck::cast_slice(&params.means).to_vec();
        self.means_to_world(&mut g.means);
        g.log_scales = bytemuck::cast_slice(&params.log_scales).to_vec();
        g.quats = bytemuck::cast_slice(&params.quats).to_vec();
        g.opacity_logits = params.opacity_logits;
        g.sh = params.sh;
        g.sh_degree = self.sh_degree;
        if let Some(logits) = extra.pop() {
            g.semantics = Some(SemanticLogits {
                channels: self.channels as usize,
                logits,
            });
        }
        Ok(())
    }
}
