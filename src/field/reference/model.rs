//! The whole field for one ray: forward, losses and backward into the flat gradient.
//!
//! Per sample (positions normalized to [0,1]³, `d` the unit view direction):
//! ```text
//! e   = [hash_grid(p), frequency(p)]                       (config.encoding_dim())
//! [h₀, g] = density_mlp(e)                                  σ = exp(h₀), g: geometry feature
//! rgb = sigmoid(color_mlp([sh4(d), g]))
//! f   = feature_mlp(g)                                      (linear)
//! s   = semantic_mlp([relu(f), g]) or semantic_mlp(relu(f))  (C logits; `semantic_input`)
//! value = [rgb, z-depth of the sample, s, f]                (render::Channels order)
//! ```
//! then all values are rendered with one set of weights (`render`); a sample whose weight is
//! below `FieldConfig::head_weight_threshold` (`render::kept_samples`) renders 0 for rgb, s and
//! f and its heads get no gradient. `loss::ray_loss`
//! scores the rendered channels. The backward pass runs the same chain in reverse and adds
//! every parameter's gradient at its place in the `params::ParamLayout` buffer.
use super::activations;
use super::hash_grid::{self, HashGrid};
use super::loss::{self, LossTerms, RayTarget};
use super::mlp::{self, MlpTrace};
use super::real::Real;
use super::render::{self, Channels, Composite};
use super::sampling::{self, Ray, SamplePlan};
use super::{frequency, sh};
use crate::field::config::{ConfigError, FieldConfig};
use crate::field::params::ParamLayout;
use crate::scene::Bounds;

/// A validated config with everything derived from it.
#[derive(Clone, Debug)]
pub struct FieldModel {
    pub config: FieldConfig,
    pub layout: ParamLayout,
    pub grid: HashGrid,
    pub channels: Channels,
    /// The class of what lies beyond the scene box, for the opacity term
    /// (`loss::opacity_loss`); the trainer takes it from its labels
    /// (`PropagationCache::far_class`). None: no such term.
    pub far_class: Option<u32>,
    /// How each MLP's hidden outputs and each layer's dZ are seen; the GPU trainer says which
    /// it stores as bf16 (`Trainer::stored_rows`). Default: exact everywhere.
    pub stored_rows: FieldRows,
}

/// [`mlp::StoredRows`] of each of the field's MLPs.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct FieldRows {
    pub density: mlp::StoredRows,
    pub color: mlp::StoredRows,
    pub feature: mlp::StoredRows,
    pub semantic: mlp::StoredRows,
}

/// One ray's samples, ready for the field.
#[derive(Clone, Debug, PartialEq)]
pub struct SampledRay {
    /// Unit view direction in world space.
    pub dir: [f32; 3],
    /// Sample positions normalized to [0,1]³ by the scene box.
    pub positions: Vec<[f32; 3]>,
    /// Interval lengths δ in metres.
    pub deltas: Vec<f32>,
    /// z-depth of every sample (metres along the camera axis), rendered as the depth channel.
    pub depths: Vec<f32>,
}

/// A sampled ray and what it is trained towards.
#[derive(Clone, Debug, PartialEq)]
pub struct TrainingRay {
    pub samples: SampledRay,
    pub target: RayTarget,
}

/// Everything one sample's backward pass needs.
#[derive(Clone, Debug)]
pub struct SampleTrace<R> {
    pub encoding: Vec<R>,
    pub density: MlpTrace<R>,
    pub sigma: R,
    pub color: MlpTrace<R>,
    pub rgb: [R; 3],
    pub feature: MlpTrace<R>,
    pub semantic: MlpTrace<R>,
    /// The rendered value vector of this sample (`Channels::count()` values).
    pub value: Vec<R>,
    /// Whether the sample reaches the heads (`render::kept_samples`): when not, its colour,
    /// logits and feature render as 0 and the heads get no gradient from it.
    pub kept: bool,
}

/// Everything one ray's backward pass needs.
#[derive(Clone, Debug)]
pub struct RayTrace<R> {
    pub samples: Vec<SampleTrace<R>>,
    pub deltas: Vec<R>,
    /// Sample values, n × `Channels::count()`, as rendered.
    pub values: Vec<R>,
    pub composite: Composite<R>,
}

impl<R: Real> RayTrace<R> {
    /// The rendered channels (`Channels` order).
    pub fn rendered(&self) -> &[R] {
        &self.composite.output
    }
}

impl SampledRay {
    /// Clips `ray` to the scene box and places `cfg.samples_per_ray()` samples (depth-guided
    /// when `measured_depth`, a z-depth in metres, is given). `jitter`: `samples_per_ray()`
    /// values in [0,1). None when the ray misses the box.
    pub fn new(
        cfg: &FieldConfig,
        bounds: &Bounds,
        ray: &Ray,
        measured_depth: Option<f32>,
        jitter: &[f32],
    ) -> Option<Self> {
        let (near, far) = sampling::clip_to_bounds(ray, bounds)?;
        let plan = SamplePlan {
            coarse: cfg.samples_coarse as usize,
            fine: cfg.samples_fine as usize,
            band_half_width: sampling::surface_band_half_width(bounds, cfg.surface_band_fraction),
        };
        let surface_t = measured_depth
            .filter(|d| d.is_finite() && *d > 0.0)
            .map(|d| d / ray.z_per_t);
        let ts = sampling::place_samples(&plan, near, far, surface_t, jitter);
        let deltas = sampling::interval_lengths(&ts, far, cfg.opaque_last_sample());
        Some(SampledRay {
            dir: ray.dir,
            positions: ts
                .iter()
                .map(|&t| sampling::normalize_position(bounds, ray.at(t)))
                .collect(),
            deltas,
            depths: ts.iter().map(|t| t * ray.z_per_t).collect(),
        })
    }
}

impl FieldModel {
    pub fn new(config: FieldConfig) -> Result<FieldModel, ConfigError> {
        config.validate()?;
        Ok(FieldModel {
            layout: ParamLayout::new(&config),
            grid: HashGrid::from_config(&config),
            channels: Channels {
                classes: config.num_classes as usize,
                feature_dim: config.feature_dim as usize,
            },
            config,
            far_class: None,
            stored_rows: FieldRows::default(),
        })
    }

    /// The density MLP's input for a normalized position: [hash grid, frequency]
    /// (`config.encoding_dim()` values).
    pub fn encode_position<R: Real>(&self, params: &[R], pos: [R; 3], out: &mut [R]) {
        let hash_dim = self.grid.output_dim();
        hash_grid::encode(
            &self.grid,
            &params[self.layout.hash_table.clone()],
            pos,
            &mut out[..hash_dim],
        );
        frequency::encode(self.config.encoding.frequencies() as usize, pos, &mut out[hash_dim..]);
    }

    /// Forward pass of one sample. `view_sh`: the 16 SH coefficients of the ray direction;
    /// `depth`: the sample's z-depth (passed through as the depth channel).
    pub fn forward_sample<R: Real>(&self, params: &[R], pos: [R; 3], view_sh: &[R], depth: R) -> SampleTrace<R> {
        let l = &self.layout;
        let mut encoding = vec![R::ZERO; self.config.encoding_dim()];
        self.encode_position(params, pos, &mut encoding);
        let rows = &self.stored_rows;
        let density = mlp::forward_stored(&l.density.dims, &params[l.density.range()], &encoding, &rows.density);
        let sigma = activations::density(density.output()[0]);
        let geometry = &density.output()[1..];

        let color_in: Vec<R> = view_sh.iter().chain(geometry).copied().collect();
        let color = mlp::forward_stored(&l.color.dims, &params[l.color.range()], &color_in, &rows.color);
        let rgb: [R; 3] = std::array::from_fn(|c| activations::sigmoid(color.output()[c]));

        let feature = mlp::forward_stored(&l.feature.dims, &params[l.feature.range()], geometry, &rows.feature);
        let semantic_in: Vec<R> = feature
            .output()
            .iter()
            .map(|f| f.max(R::ZERO))
            .chain(geometry[..self.config.semantic_geometry_dim()].iter().copied())
            .collect();
        let semantic = mlp::forward_stored(
            &l.semantic.dims,
            &params[l.semantic.range()],
            &semantic_in,
            &rows.semantic,
        );

        let mut value = Vec::with_capacity(self.channels.count());
        value.extend_from_slice(&rgb);
        value.push(depth);
        value.extend_from_slice(semantic.output());
        value.extend_from_slice(feature.output());
        SampleTrace {
            encoding,
            density,
            sigma,
            color,
            rgb,
            feature,
            semantic,
            value,
            kept: true,
        }
    }

    /// Forward pass of one ray: every sample, then rendering.
    pub fn forward_ray<R: Real>(&self, params: &[R], ray: &SampledRay) -> RayTrace<R> {
        let mut view_sh = [R::ZERO; sh::SH_COEFFS];
        sh::encode(ray.dir.map(R::of_f32), &mut view_sh);
        let mut samples: Vec<SampleTrace<R>> = ray
            .positions
            .iter()
            .zip(&ray.depths)
            .map(|(p, d)| self.forward_sample(params, p.map(R::of_f32), &view_sh, R::of_f32(*d)))
            .collect();
        let h0: Vec<f32> = samples.iter().map(|s| s.density.output()[0].to_f64() as f32).collect();
        let kept = render::kept_samples(&h0, &ray.deltas, self.config.head_weight_threshold);
        for (sample, kept) in samples.iter_mut().zip(kept) {
            if !kept {
                sample.kept = false;
                for (c, v) in sample.value.iter_mut().enumerate() {
                    if c != Channels::DEPTH {
                        *v = R::ZERO;
                    }
                }
            }
        }
        let sigmas: Vec<R> = samples.iter().map(|s| s.sigma).collect();
        let deltas: Vec<R> = ray.deltas.iter().map(|d| R::of_f32(*d)).collect();
        let values: Vec<R> = samples.iter().flat_map(|s| s.value.iter().copied()).collect();
        let composite = render::composite(&sigmas, &deltas, &values, self.channels.count());
        RayTrace {
            samples,
            deltas,
            values,
            composite,
        }
    }

    /// Backward pass of one ray: adds ∂L/∂params to `grad` (`layout.total` values) given
    /// ∂L/∂rendered (`Channels::count()` values).
    pub fn backward_ray<R: Real>(
        &self,
        params: &[R],
        ray: &SampledRay,
        trace: &RayTrace<R>,
        grad_rendered: &[R],
        grad_left: R,
        grad: &mut [R],
    ) {
        let k = self.channels.count();
        let (grad_sigma, grad_values) = render::composite_backward(
            &trace.composite,
            &trace.deltas,
            &trace.values,
            k,
            grad_rendered,
            grad_left,
        );
        for (i, sample) in trace.samples.iter().enumerate() {
            self.backward_sample(
                params,
                ray.positions[i],
                sample,
                grad_sigma[i],
                &grad_values[i * k..(i + 1) * k],
                grad,
            );
        }
    }

    /// Backward pass of one sample given ∂L/∂σ and ∂L/∂value (the depth channel is data, so
    /// its gradient is dropped).
    pub fn backward_sample<R: Real>(
        &self,
        params: &[R],
        pos: [f32; 3],
        sample: &SampleTrace<R>,
        grad_sigma: R,
        grad_value: &[R],
        grad: &mut [R],
    ) {
        let l = &self.layout;
        let geometry_dim = self.config.geometry_dim as usize;
        let mut grad_geometry = vec![R::ZERO; geometry_dim];
        if sample.kept {
            self.backward_heads(params, sample, grad_value, &mut grad_geometry, grad);
        }

        // Density MLP: output [h₀, g] → encoding.
        let mut grad_density_out = Vec::with_capacity(1 + geometry_dim);
        grad_density_out.push(activations::density_backward(sample.density.output()[0], grad_sigma));
        grad_density_out.extend_from_slice(&grad_geometry);
        let grad_encoding = mlp::backward_stored(
            &l.density.dims,
            &params[l.density.range()],
            &sample.density,
            &grad_density_out,
            &mut grad[l.density.range()],
            &self.stored_rows.density,
        );

        // Hash grid (the frequency part has no parameters).
        let hash_dim = self.grid.output_dim();
        if hash_dim > 0 {
            hash_grid::backward(
                &self.grid,
                pos.map(R::of_f32),
                &grad_encoding[..hash_dim],
                &mut grad[l.hash_table.clone()],
            );
        }
    }

    /// Backward of the three heads of a kept sample: adds their parameters' gradients to
    /// `grad` and ∂L/∂g to `grad_geometry`.
    fn backward_heads<R: Real>(
        &self,
        params: &[R],
        sample: &SampleTrace<R>,
        grad_value: &[R],
        grad_geometry: &mut [R],
        grad: &mut [R],
    ) {
        let l = &self.layout;
        let ch = &self.channels;
        let feature_dim = ch.feature_dim;

        // Semantic head → [relu(f), g].
        let grad_logits = &grad_value[Channels::SEMANTIC..Channels::SEMANTIC + ch.classes];
        let grad_semantic_in = mlp::backward_stored(
            &l.semantic.dims,
            &params[l.semantic.range()],
            &sample.semantic,
            grad_logits,
            &mut grad[l.semantic.range()],
            &self.stored_rows.semantic,
        );
        // Only a share of it reaches the shared field (FieldConfig::semantic_trunk_gradient).
        let trunk = R::of_f32(self.config.semantic_trunk_gradient);
        let grad_semantic_in: Vec<R> = grad_semantic_in.iter().map(|&v| v * trunk).collect();
        let mut grad_f: Vec<R> = grad_value[ch.feature()..ch.feature() + feature_dim].to_vec();
        for ((gf, gs), f) in grad_f
            .iter_mut()
            .zip(&grad_semantic_in[..feature_dim])
            .zip(sample.feature.output())
        {
            if *f > R::ZERO {
                *gf += *gs;
            }
        }
        add_into(grad_geometry, &grad_semantic_in[feature_dim..]);

        // Feature MLP → g.
        let grad_feature_in = mlp::backward_stored(
            &l.feature.dims,
            &params[l.feature.range()],
            &sample.feature,
            &grad_f,
            &mut grad[l.feature.range()],
            &self.stored_rows.feature,
        );
        add_into(grad_geometry, &grad_feature_in);

        // Colour: sigmoid, then the MLP → [sh, g] (the SH part is data).
        let grad_color_out: Vec<R> = (0..3)
            .map(|c| activations::sigmoid_backward(sample.rgb[c], grad_value[Channels::RGB + c]))
            .collect();
        let grad_color_in = mlp::backward_stored(
            &l.color.dims,
            &params[l.color.range()],
            &sample.color,
            &grad_color_out,
            &mut grad[l.color.range()],
            &self.stored_rows.color,
        );
        add_into(grad_geometry, &grad_color_in[sh::SH_COEFFS..]);
    }

    /// Loss of a batch and its gradient: `grad` (`layout.total` values) is overwritten with
    /// ∂L/∂params of the batch loss (see `loss` for how terms are averaged).
    pub fn loss_and_gradient<R: Real>(&self, params: &[R], batch: &[TrainingRay], grad: &mut [R]) -> LossTerms {
        grad.fill(R::ZERO);
        let mut total = LossTerms::default();
        for ray in batch {
            let trace = self.forward_ray(params, &ray.samples);
            let (terms, grad_rendered, grad_left) = self.ray_loss(&trace, &ray.target, batch.len());
            total.add(&terms);
            self.backward_ray(params, &ray.samples, &trace, &grad_rendered, grad_left, grad);
        }
        total
    }

    /// One rendered ray's loss terms (`loss::ray_loss`, with the opacity term counted in the
    /// semantic one), ∂L/∂rendered and ∂L/∂(the transmittance left for an opaque last sample).
    fn ray_loss<R: Real>(&self, trace: &RayTrace<R>, target: &RayTarget, batch_size: usize) -> (LossTerms, Vec<R>, R) {
        let (mut terms, grad_rendered) = loss::ray_loss(
            &self.config.loss,
            self.config.feature_supervision,
            &self.channels,
            trace.rendered(),
            target,
            batch_size,
        );
        let opacity = loss::opacity_loss(
            &self.config.loss,
            render::left_for_opaque_sample(&trace.composite, &trace.deltas),
            target.label,
            self.far_class,
            self.channels.classes,
            batch_size,
        );
        let grad_left = loss::add_opacity(&mut terms, opacity);
        (terms, grad_rendered, grad_left)
    }

    /// Loss of a batch without the gradient (for evaluation and finite differences).
    pub fn loss<R: Real>(&self, params: &[R], batch: &[TrainingRay]) -> LossTerms {
        let mut total = LossTerms::default();
        for ray in batch {
            let trace = self.forward_ray(params, &ray.samples);
            total.add(&self.ray_loss(&trace, &ray.target, batch.len()).0);
        }
        total
    }
}

fn add_into<R: Real>(acc: &mut [R], values: &[R]) {
    for (a, v) in acc.iter_mut().zip(values) {
        *a += *v;
    }
}
