//! Compute pipelines from the embedded shaders (compiled once per device: see
//! `gpu::pipeline_cache`) and 1D dispatches that stay within the per-dimension workgroup limit.
//! Bind groups are made by binding name (`gpu::dispatch`).
use std::cell::Cell;

use super::context::GpuContext;
use super::error::GpuError;
use super::pipeline_cache::PipelineKey;

thread_local! {
    static RECORDED: Cell<u64> = const { Cell::new(0) };
}

/// Dispatches recorded on this thread so far: every place that records one counts it. A
/// diagnostic (`bench` counts a training step's by recording one it never submits).
pub fn dispatches_recorded() -> u64 {
    RECORDED.with(Cell::get)
}

/// Counts one recorded dispatch (see [`dispatches_recorded`]).
pub(crate) fn count_dispatch() {
    RECORDED.with(|c| c.set(c.get() + 1));
}

/// What to build a compute pipeline from.
#[derive(Debug, Clone, Copy)]
pub struct KernelSpec<'a> {
    /// Names the pipeline in errors and GPU debuggers.
    pub label: &'a str,
    /// WGSL source, normally a constant of `gpu::shaders`.
    pub source: &'a str,
    pub entry_point: &'a str,
    /// `None`: derive the layout from the shader (then fetch it with
    /// `pipeline.get_bind_group_layout(i)`); `Some`: an explicit layout, the entries of each bind
    /// group in order (make bind groups with `GpuContext::bind_group_layout` of the same entries).
    pub layout: Option<&'a [&'a [wgpu::BindGroupLayoutEntry]]>,
    /// Values for the shader's `override` constants.
    pub constants: &'a [(&'a str, f64)],
}

impl<'a> KernelSpec<'a> {
    /// A spec with a derived layout and no override constants.
    pub fn new(label: &'a str, source: &'a str, entry_point: &'a str) -> Self {
        KernelSpec {
            label,
            source,
            entry_point,
            layout: None,
            constants: &[],
        }
    }
}

/// Compiles a compute pipeline, or hands out the one compiled earlier on this device for the same
/// source, entry point, constants and layout. wgpu's complaints (a shader that fails the
/// device's own checks, a bad layout) come back as [`GpuError::Validation`] instead of a panic;
/// a pipeline that failed is not kept.
pub async fn create_compute_pipeline(
    ctx: &GpuContext,
    spec: &KernelSpec<'_>,
) -> Result<wgpu::ComputePipeline, GpuError> {
    let key = PipelineKey {
        source: spec.source.to_string(),
        entry_point: spec.entry_point.to_string(),
        constants: spec
            .constants
            .iter()
            .map(|&(name, value)| (name.to_string(), value.to_bits()))
            .collect(),
        layout: spec
            .layout
            .map(|groups| groups.iter().map(|entries| entries.to_vec()).collect()),
    };
    if let Some(pipeline) = ctx.pipeline_cache().pipeline(&key) {
        return Ok(pipeline);
    }
    let validation = ctx.device.push_error_scope(wgpu::ErrorFilter::Validation);
    let module = ctx.device.create_shader_module(wgpu::ShaderModuleDescriptor {
        label: Some(spec.label),
        source: wgpu::ShaderSource::Wgsl(spec.source.into()),
    });
    let layout = spec.layout.map(|groups| {
        let groups: Vec<wgpu::BindGroupLayout> = groups
            .iter()
            .map(|entries| ctx.bind_group_layout(spec.label, entries))
            .collect();
        let groups: Vec<Option<&wgpu::BindGroupLayout>> = groups.iter().map(Some).collect();
        ctx.device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some(spec.label),
            bind_group_layouts: &groups,
            immediate_size: 0,
        })
    });
    let pipeline = ctx.device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
        label: Some(spec.label),
        layout: layout.as_ref(),
        module: &module,
        entry_point: Some(spec.entry_point),
        compilation_options: wgpu::PipelineCompilationOptions {
            constants: spec.constants,
            ..Default::default()
        },
        cache: None,
    });
    match validation.pop().await {
        None => {
            ctx.pipeline_cache().insert_pipeline(key, &pipeline);
            Ok(pipeline)
        }
        Some(error) => Err(GpuError::from_scope(
            format!("pipeline {} ({})", spec.label, spec.entry_point),
            error,
        )),
    }
}

/// Workgroup counts for `items` independent items in workgroups of `workgroup_size`, spread over
/// x and y when one dimension would exceed the device's limit (65535 by default). Kernels turn
/// the 2D workgroup id back into an item index with `linear_item_index` from
/// `shaders/_dispatch.wgsl` and return early past the end (the grid may overshoot by up to one
/// row of workgroups).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Dispatch1d {
    pub x: u32,
    pub y: u32,
}

impl Dispatch1d {
    pub fn new(items: u64, workgroup_size: u32, max_per_dimension: u32) -> Result<Self, GpuError> {
        if workgroup_size == 0 || max_per_dimension == 0 {
            return Err(GpuError::invalid_argument(
                "1D dispatch",
                format!("workgroup size {workgroup_size} and per-dimension limit {max_per_dimension} must be positive"),
            ));
        }
        let workgroups = items.div_ceil(u64::from(workgroup_size));
        let max = u64::from(max_per_dimension);
        if workgroups <= max {
            return Ok(Dispatch1d {
                x: workgroups as u32,
                y: 1,
            });
        }
        let y = workgroups.div_ceil(max);
        if y > max {
            return Err(GpuError::LimitExceeded {
                what: format!("a 1D dispatch of {items} items in workgroups of {workgroup_size}"),
                limit: "max_compute_workgroups_per_dimension squared",
                needed: workgroups,
                allowed: max * max,
            });
        }
        // Spread evenly so the overshoot is at most one row.
        let x = workgroups.div_ceil(y);
        Ok(Dispatch1d {
            x: x as u32,
            y: y as u32,
        })
    }

    /// As [`Dispatch1d::new`] with this device's per-dimension limit.
    pub fn for_device(ctx: &GpuContext, items: u64, workgroup_size: u32) -> Result<Self, GpuError> {
        Self::new(items, workgroup_size, ctx.limits.max_compute_workgroups_per_dimension)
    }

    /// Workgroups launched, including the overshoot.
    pub fn workgroups(&self) -> u64 {
        u64::from(self.x) * u64::from(self.y)
    }

    pub fn record(&self, pass: &mut wgpu::ComputePass<'_>) {
        pass.dispatch_workgroups(self.x, self.y, 1);
        count_dispatch();
    }
}

/// Encodes and submits one compute pass running `pipeline` with bind group 0 over `dispatch`:
/// the common case of tests and one-off kernels.
pub fn run_1d(
    ctx: &GpuContext,
    label: &str,
    pipeline: &wgpu::ComputePipeline,
    bind_group: &wgpu::BindGroup,
    dispatch: Dispatch1d,
) -> wgpu::SubmissionIndex {
    let mut encoder = ctx
        .device
        .create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some(label) });
    {
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some(label),
            timestamp_writes: None,
        });
        pass.set_pipeline(pipeline);
        pass.set_bind_group(0, bind_group, &[]);
        dispatch.record(&mut pass);
    }
    ctx.queue.submit([encoder.finish()])
}
