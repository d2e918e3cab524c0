//! Whole MLPs on the dense layers: the twin of `reference::mlp`.
use super::backward::{DenseBackward, DenseGradients, OutputGradient};
use super::chain::{BackwardChain, ChainDesc, chain_block};
use super::layer::DenseForward;
use super::pipelines::ProductKind;
use super::spec::DenseLayerSpec;
use super::uniform::{MlpPacking, uniform_weight_chunks};
use super::{DenseKernels, ReluMask, RowFormat, RowView};
use crate::field::gpu::keep::HeadRows;
use crate::field::gpu::stage::{Stage, StepShape};
use crate::field::params::MlpLayout;
use crate::gpu::KernelFamily;
use crate::gpu::buffers::storage_buffer_zeroed;
use crate::gpu::{GpuContext, GpuError};

/// Rows at the MLP's input side: the caller's, or rows the pass allocates in the format its
/// kernels read best (bf16 where it stores its hidden rows so), for the caller to write or read
/// through [`MlpPass::input`] and [`MlpPass::input_gradient`].
#[derive(Debug, Clone)]
pub enum InputRows {
    Given(RowView),
    Owned,
}

/// Gradient buffers of an MLP's backward.
#[derive(Debug, Clone)]
pub struct MlpGradients {
    /// The flat gradient buffer; every layer's dW is added at its range.
    pub grads: wgpu::Buffer,
    /// dL/d(output), `output_dim` values per row.
    pub output_grad: RowView,
    /// Where dL/d(input) goes (overwritten); `None` when the input needs no gradient.
    pub input_grad: Option<InputRows>,
    /// The columns of dL/d(input) the caller reads (`None`: all). The others may be left
    /// unwritten: the uniform-weight input gradient writes none of them; the tiled kernels
    /// and the chain write every column.
    pub input_grad_columns: Option<std::ops::Range<u32>>,
}

/// What an MLP reads and writes.
#[derive(Debug, Clone)]
pub struct MlpPassDesc<'a> {
    pub label: &'a str,
    pub layout: &'a MlpLayout,
    pub rows: u32,
    pub params: &'a wgpu::Buffer,
    /// `input_dim` values per row.
    pub input: InputRows,
    /// Where the last layer writes; `None`: a packed buffer the pass allocates.
    pub output: Option<RowView>,
    /// `None` builds a forward-only pass (rendering).
    pub gradients: Option<MlpGradients>,
    /// `Some`: the rows are the samples the keep pass kept, only the first `row_count` of the
    /// `rows` are computed, and the kernels launch for those alone (indirect dispatches).
    pub kept: Option<&'a HeadRows>,
}

/// A whole MLP (ReLU after every hidden layer, linear output, as `reference::mlp`): the forward
/// keeps every layer's output in buffers this pass owns (N × width, packed) for the backward.
pub struct MlpPass {
    /// The packed weight copies its uniform-weight kernels read, refreshed before the forward.
    packing: MlpPacking,
    forward: Vec<DenseForward>,
    backward: Option<Vec<DenseBackward>>,
    /// Every layer's input gradient in one dispatch, where the MLP qualifies (CPU devices;
    /// `chain.rs`); the layers' backwards then record their weight gradients alone.
    chain: Option<BackwardChain>,
    /// Output of layer k (the input of layer k + 1; the last is the MLP's output).
    outputs: Vec<RowView>,
    /// dL/d(input of layer k) for k ≥ 1, packed, owned (none in a chain: registers; none
    /// fused: the layer below's dZ windows).
    hidden_grads: Vec<wgpu::Buffer>,
    /// How those gradients are stored, wherever they are.
    hidden_gradient_rows: RowFormat,
    input: RowView,
    input_grad: Option<RowView>,
    /// Whether the rows are the samples the keep pass kept (the heads) or every sample.
    on_kept_rows: bool,
}

impl MlpPass {
    pub async fn new(
        ctx: &GpuContext,
        pipelines: &mut DenseKernels,
        desc: MlpPassDesc<'_>,
    ) -> Result<MlpPass, GpuError> {
        let MlpPassDesc {
            label,
            layout,
            rows,
            params,
            input,
            output,
            gradients,
            kept,
        } = desc;
        let on_kept_rows = kept.is_some();
        let specs = layer_specs(label, layout, rows)?;
        let layers = specs.len();
        let dims: Vec<u32> = std::iter::once(specs[0].in_dim)
            .chain(specs.iter().map(|s| s.out_dim))
            .collect();

        // dX of layer 0 only where the caller wants the input's gradient; of every later layer
        // whenever there is a backward.
        let input_grads: Vec<bool> = (0..layers)
            .map(|k| gradients.as_ref().is_some_and(|g| k > 0 || g.input_grad.is_some()))
            .collect();
        let packing = MlpPacking::new(ctx, pipelines, label, params, &specs, &input_grads).await?;
        let hidden = hidden_format(ctx, pipelines, &specs, &input_grads, gradients.is_some());
        let input = match input {
            InputRows::Given(view) => view,
            InputRows::Owned => RowView::zeroed(ctx, &format!("{label} input"), hidden, rows, dims[0])?,
        };
        let mut outputs = Vec::with_capacity(layers);
        for (k, spec) in specs.iter().enumerate() {
            let view = match (&output, k + 1 == layers) {
                (Some(view), true) => view.clone(),
                (_, last) => {
                    let format = if last { RowFormat::F32 } else { hidden };
                    RowView::zeroed(ctx, &format!("{} output", spec.label), format, rows, spec.out_dim)?
                }
            };
            outputs.push(view);
        }
        // Without a chain, where every layer's weight gradient reads dZ through windows and the
        // hidden rows are bf16 (so are its windows), a layer's input gradient stores the layer
        // below's dZ straight into that layer's windows: dX masked by the ReLU, from the bits
        // the forward stored, where dX and then dZ were written and dX and Y read back
        // (docs/architecture.md, "Hidden activations in bf16").
        let chain_block = match &gradients {
            Some(gradients) => chain_block(ctx, pipelines, &specs, &packing, gradients.input_grad.is_some()),
            None => None,
        };
        let fused = gradients.is_some() && chain_block.is_none() && hidden == RowFormat::Bf16;
        let mut forward: Vec<DenseForward> = Vec::with_capacity(layers);
        for (k, spec) in specs.iter().enumerate() {
            let layer_input = if k == 0 { &input } else { &outputs[k - 1] };
            let window = packing.window(k, ProductKind::Forward);
            let mask = fused && k + 1 < layers;
            forward.push(
                DenseForward::new(
                    ctx,
                    pipelines,
                    spec,
                    params,
                    (layer_input, &outputs[k]),
                    kept,
                    window,
                    mask,
                )
                .await?,
            );
        }

        let mut hidden_grads = Vec::new();
        let mut hidden_gradient_rows = RowFormat::F32;
        let mut chain = None;
        let mut input_grad = None;
        let backward = match gradients {
            None => None,
            Some(gradients) => {
                let chained = chain_block.is_some();
                input_grad = match &gradients.input_grad {
                    None => None,
                    Some(InputRows::Given(view)) => Some(view.clone()),
                    Some(InputRows::Owned) => Some(RowView::zeroed(
                        ctx,
                        &format!("{label} input gradient"),
                        hidden,
                        rows,
                        dims[0],
                    )?),
                };
                if !chained && layers > 1 {
                    hidden_gradient_rows = hidden;
                }
                // Otherwise the input gradients between hidden layers are stored like the hidden
                // outputs.
                for spec in specs[1..].iter().filter(|_| !chained && !fused) {
                    let words = RowView::words(hidden, rows, spec.in_dim) as usize;
                    hidden_grads.push(storage_buffer_zeroed::<f32>(
                        ctx,
                        &format!("{} input gradient", spec.label),
                        words,
                    )?);
                }
                let hidden_views: Vec<RowView> = hidden_grads
                    .iter()
                    .zip(&specs[1..])
                    .map(|(b, spec)| RowView::packed_as(b, spec.in_dim, hidden))
                    .collect();
                let mut backward: Vec<DenseBackward> = Vec::with_capacity(layers);
                for (k, spec) in specs.iter().enumerate() {
                    let layer_input = if k == 0 { &input } else { &outputs[k - 1] };
                    // A chain writes every layer's dZ (dY never leaves its registers); fused,
                    // the next layer's input gradient writes it.
                    let output_grad = if chained || (fused && k + 1 < layers) {
                        OutputGradient::InWindows
                    } else if k + 1 == layers {
                        OutputGradient::Rows(&gradients.output_grad)
                    } else {
                        OutputGradient::Rows(&hidden_views[k])
                    };
                    let below = match k.checked_sub(1) {
                        Some(below) if fused => Some(backward[below].dz_rows().ok_or_else(|| {
                            GpuError::invalid_argument(&specs[below].label, "a fused layer has no dZ windows")
                        })?),
                        _ => None,
                    };
                    let layer_input_grad = if chained {
                        None
                    } else if k == 0 {
                        input_grad.as_ref()
                    } else if fused {
                        below.as_ref()
                    } else {
                        Some(&hidden_views[k - 1])
                    };
                    let layer_gradients = DenseGradients {
                        grads: &gradients.grads,
                        output_grad,
                        input_grad: layer_input_grad,
                        input_mask: match below {
                            Some(_) => Some(forward[k - 1].relu_mask().ok_or_else(|| {
                                GpuError::invalid_argument(&specs[k - 1].label, "a fused layer stores no ReLU mask")
                            })?),
                            None => None,
                        },
                        kept,
                        input_grad_columns: if k == 0 {
                            gradients.input_grad_columns.clone()
                        } else {
                            None
                        },
                    };
                    let window = packing.window(k, ProductKind::BackwardInput);
                    backward.push(
                        DenseBackward::new(
                            ctx,
                            pipelines,
                            spec,
                            params,
                            (layer_input, &outputs[k]),
                            &layer_gradients,
                            window,
                        )
                        .await?,
                    );
                }
                if let Some(block) = chain_block {
                    let dz = backward
                        .iter()
                        .map(|layer: &DenseBackward| layer.dz_buffer().cloned())
                        .collect::<Option<Vec<_>>>()
                        .ok_or_else(|| GpuError::invalid_argument(label, "a chained layer has no dZ windows"))?;
                    let desc = ChainDesc {
                        label,
                        specs: &specs,
                        block,
                        outputs: &outputs,
                        output_grad: &gradients.output_grad,
                        input_grad: input_grad.as_ref(),
                        dz,
                        row_count: backward[0].row_count(),
                        kept,
                    };
                    chain = Some(BackwardChain::new(ctx, pipelines, &packing, desc).await?);
                }
                Some(backward)
            }
        };
        Ok(MlpPass {
            packing,
            forward,
            backward,
            chain,
            outputs,
            hidden_grads,
            hidden_gradient_rows,
            input,
            input_grad,
            on_kept_rows,
        })
    }

    /// The rows the MLP reads as its input (the caller's, or its own: [`InputRows::Owned`]).
    pub fn input(&self) -> &RowView {
        &self.input
    }

    /// Where the backward writes ∂L/∂input, where it computes it.
    pub fn input_gradient(&self) -> Option<&RowView> {
        self.input_grad.as_ref()
    }

    /// Records every layer's forward, in order, after refreshing the packed weights that both
    /// the forward and the backward read (the parameters do not change between them).
    pub fn record_forward(&self, pass: &mut wgpu::ComputePass<'_>) {
        self.packing.record(pass);
        for layer in &self.forward {
            layer.record(pass);
        }
    }

    /// Records every layer's backward, last layer first. Needs the forward of the same rows
    /// recorded before it, with no parameter update between (it reads the stored outputs and
    /// the weights the forward packed); fails on a forward-only pass.
    pub fn record_backward(&self, pass: &mut wgpu::ComputePass<'_>) -> Result<(), GpuError> {
        let backward = self.backward.as_deref().ok_or_else(|| {
            let label = self.forward.first().map_or("mlp", |layer| layer.spec().label.as_str());
            GpuError::invalid_argument(label, "backward recorded on a pass built without gradients")
        })?;
        self.record_backward_layers(pass, backward);
        Ok(())
    }

    /// The input-gradient chain, if any, then `backward` (this pass's backward layers) from the
    /// last layer down.
    fn record_backward_layers(&self, pass: &mut wgpu::ComputePass<'_>, backward: &[DenseBackward]) {
        if let Some(chain) = &self.chain {
            chain.record(pass);
        }
        for layer in backward.iter().rev() {
            layer.record(pass);
        }
    }

    /// Bytes its forward moves through global memory over `rows` rows (the packing of the
    /// weights and [`DenseForward::global_bytes`] of every layer).
    pub fn forward_bytes(&self, rows: u64) -> u64 {
        self.packing.global_bytes() + self.forward.iter().map(|layer| layer.global_bytes(rows)).sum::<u64>()
    }

    /// Bytes its backward moves over `rows` rows ([`DenseBackward::global_bytes`] of every
    /// layer); 0 for a forward-only pass.
    pub fn backward_bytes(&self, rows: u64) -> u64 {
        let chain = self.chain.as_ref().map_or(0, |chain| chain.global_bytes(rows));
        chain
            + self
                .backward
                .iter()
                .flatten()
                .map(|layer| layer.global_bytes(rows))
                .sum::<u64>()
    }

    /// The padded dZ rows layer `k`'s weight gradient reads, where it reads them through
    /// uniform windows (written by the chain, dX's kernel or a masking kernel each step).
    pub fn layer_dz(&self, k: usize) -> Option<&wgpu::Buffer> {
        self.backward.as_ref()?.get(k)?.dz_buffer()
    }

    /// Whether the input gradients run as one chain (`chain.rs`).
    pub fn chains_input_gradients(&self) -> bool {
        self.chain.is_some()
    }

    /// The MLP's (linear) output.
    pub fn output(&self) -> &RowView {
        &self.outputs[self.outputs.len() - 1]
    }

    /// The bits of which of layer `k`'s outputs are positive, where its forward stores them
    /// (a hidden layer whose next layer's input gradient masks with them).
    pub fn layer_relu_mask(&self, k: usize) -> Option<&ReluMask> {
        self.forward.get(k)?.relu_mask()
    }

    /// Output of layer `k` (ReLU-activated for hidden layers).
    pub fn layer_output(&self, k: usize) -> Option<&RowView> {
        self.outputs.get(k)
    }

    /// dL/d(input of layer k) for k ≥ 1, as written by the backward (`None` in a chain, and
    /// fused, where it is stored masked as layer k - 1's dZ).
    pub fn hidden_gradient(&self, k: usize) -> Option<&wgpu::Buffer> {
        k.checked_sub(1).and_then(|i| self.hidden_grads.get(i))
    }

    pub fn layers(&self) -> impl Iterator<Item = &DenseLayerSpec> {
        self.forward.iter().map(DenseForward::spec)
    }

    /// For each layer's backward: whether dW reads dZ through uniform windows (none: forward only).
    pub fn weight_gradient_windows(&self) -> Vec<bool> {
        self.backward
            .iter()
            .flatten()
            .map(DenseBackward::uses_uniform_windows)
            .collect()
    }

    /// How the hidden layers' outputs are stored (f32 where there are none).
    pub fn hidden_rows(&self) -> RowFormat {
        let last = self.outputs.len().saturating_sub(1);
        self.outputs[..last].first().map_or(RowFormat::F32, |view| view.format)
    }

    /// How the input gradients between hidden layers are stored (as the hidden outputs, in
    /// [`MlpPass::hidden_gradient`] or, fused, masked as the layer below's dZ in
    /// [`MlpPass::layer_dz`]; f32 where there are none, e.g. in a chain, which keeps them in
    /// registers).
    pub fn hidden_gradient_rows(&self) -> RowFormat {
        self.hidden_gradient_rows
    }

    /// The kernel family each layer's forward (and input gradient) runs.
    pub fn layer_families(&self) -> impl Iterator<Item = KernelFamily> + '_ {
        self.forward.iter().map(DenseForward::family)
    }
}

/// The layers of an MLP of `layout` over `rows` rows: ReLU after every hidden layer, linear
/// output.
fn layer_specs(label: &str, layout: &MlpLayout, rows: u32) -> Result<Vec<DenseLayerSpec>, GpuError> {
    let dims: Vec<u32> = layout
        .dims
        .iter()
        .map(|&d| u32::try_from(d).map_err(|_| GpuError::invalid_argument(label, format!("width {d} exceeds u32"))))
        .collect::<Result<_, _>>()?;
    let layers = layout.layers.len();
    if layers == 0 || dims.len() != layers + 1 {
        return Err(GpuError::invalid_argument(
            label,
            format!("layout {layout:?} has no consistent layers"),
        ));
    }
    let specs: Vec<DenseLayerSpec> = (0..layers)
        .map(|k| DenseLayerSpec {
            label: format!("{label}.{k}"),
            rows,
            in_dim: dims[k],
            out_dim: dims[k + 1],
            relu: k + 1 < layers,
            weights: layout.layers[k].clone(),
        })
        .collect();
    Ok(specs)
}

/// How an MLP of `layout` over `rows` rows stores its hidden rows ([`MlpPass::hidden_rows`]),
/// known before it is built, for a caller that allocates rows the MLP writes or reads in the
/// same format (e.g. its output). `input_grad`: whether its backward computes the input's
/// gradient; `backward`: whether it has one.
pub fn mlp_row_format(
    ctx: &GpuContext,
    pipelines: &DenseKernels,
    layout: &MlpLayout,
    rows: u32,
    input_grad: bool,
    backward: bool,
) -> Result<RowFormat, GpuError> {
    let specs = layer_specs("mlp", layout, rows)?;
    let input_grads: Vec<bool> = (0..specs.len()).map(|k| backward && (k > 0 || input_grad)).collect();
    Ok(hidden_format(ctx, pipelines, &specs, &input_grads, backward))
}

/// How the hidden layers' outputs are stored: bf16 rows where every kernel that writes or reads
/// them is of the packed-weight family (every layer's forward, every input gradient the MLP
/// runs, every weight gradient through uniform windows) and `pipelines` does not ask for f32;
/// f32 otherwise (the tiled kernels read f32 alone).
fn hidden_format(
    ctx: &GpuContext,
    pipelines: &DenseKernels,
    specs: &[DenseLayerSpec],
    input_grads: &[bool],
    backward: bool,
) -> RowFormat {
    // The layers whose packed copies `MlpPacking` makes.
    let packed = |k: usize, kind| pipelines.packs(ctx, &specs[k], kind);
    let forward = (0..specs.len()).all(|k| packed(k, ProductKind::Forward));
    let backward_packed = !backward
        || (input_grads
            .iter()
            .enumerate()
            .all(|(k, &dx)| !dx || packed(k, ProductKind::BackwardInput))
            && specs.iter().all(|spec| uniform_weight_chunks(ctx, spec).is_some()));
    let uniform = pipelines.family == KernelFamily::UniformWeights;
    if uniform && forward && backward_packed {
        pipelines.hidden_rows()
    } else {
        RowFormat::F32
    }
}

/// One direction of an MLP as a stage of the training step (`MlpPass::forward_stage`,
/// `MlpPass::backward_stage`).
pub struct MlpStage<'a> {
    mlp: &'a MlpPass,
    name: &'static str,
    direction: Direction<'a>,
}

/// Which half of an MLP a stage records; a backward stage holds the pass's backward layers, so
/// a stage of a pass built without gradients cannot be made.
enum Direction<'a> {
    Forward,
    Backward(&'a [DenseBackward]),
}

impl MlpPass {
    /// The forward as a stage named `name`.
    pub fn forward_stage(&self, name: &'static str) -> MlpStage<'_> {
        MlpStage {
            mlp: self,
            name,
            direction: Direction::Forward,
        }
    }

    /// The backward as a stage named `name`; fails on a pass built without gradients.
    pub fn backward_stage(&self, name: &'static str) -> Result<MlpStage<'_>, GpuError> {
        let layers = self
            .backward
            .as_deref()
            .ok_or_else(|| GpuError::invalid_argument(name, "a backward stage of a pass built without gradients"))?;
        Ok(MlpStage {
            mlp: self,
            name,
            direction: Direction::Backward(layers),
        })
    }
}

impl Stage for MlpStage<'_> {
    fn name(&self) -> &'static str {
        self.name
    }

    fn record(&self, pass: &mut wgpu::ComputePass<'_>) {
        match self.direction {
            Direction::Forward => self.mlp.record_forward(pass),
            Direction::Backward(layers) => self.mlp.record_backward_layers(pass, layers),
        }
    }

    /// The packing of the weights and every layer's `DenseForward::global_bytes` (forward),
    /// or every layer's `DenseBackward::global_bytes` (backward), over N rows (the density
    /// MLP) or K (the heads).
    fn global_bytes(&self, step: &StepShape) -> u64 {
        let rows = if self.mlp.on_kept_rows {
            step.kept()
        } else {
            step.samples()
        };
        match self.direction {
            Direction::Forward => self.mlp.forward_bytes(rows),
            Direction::Backward(_) => self.mlp.backward_bytes(rows),
        }
    }
}
