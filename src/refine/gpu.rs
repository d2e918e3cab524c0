//! The edge-aware refinement of `refine` on the GPU (`shaders/refine.wgsl`): the same
//! rounds of 7 x 7 taps, one invocation per pixel, rounds ping-ponging between two buffers in one
//! submission, then one read-back. The page uses it so a 640 x 480 refinement (0.44 s on one CPU
//! core natively, more in wasm) does not hold up the page's thread; it awaits the read-back
//! without blocking.
use super::{HALF_TAPS, RefineOptions, TapScales, check_inputs, log_depth};
use crate::gpu::buffers::{read_elements_async, storage_buffer_from, storage_buffer_zeroed, uniform_buffer_from};
use crate::gpu::dispatch::{Dispatch, bind_named, whole};
use crate::gpu::pipeline::{Dispatch1d, KernelSpec, create_compute_pipeline};
use crate::gpu::{GpuContext, GpuError, shaders};
use crate::scene::Guide;

const WORKGROUP: u32 = 64;
const _: () = assert!(HALF_TAPS == 3, "shaders/refine.wgsl has HALF_TAPS = 3");

/// Mirrors `RefineUniforms` in `shaders/refine.wgsl`.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct RefineUniforms {
    pub width: u32,
    pub height: u32,
    pub classes: u32,
    pub step: u32,
    pub spatial_scale: f32,
    pub colour_scale: f32,
    pub depth_scale: f32,
    pub _pad: u32,
}

impl RefineUniforms {
    pub fn new(width: u32, height: u32, classes: u32, options: &RefineOptions) -> RefineUniforms {
        let s = TapScales::new(width, height, options);
        RefineUniforms {
            width,
            height,
            classes,
            step: s.step,
            spatial_scale: s.spatial,
            colour_scale: s.colour,
            depth_scale: s.depth,
            _pad: 0,
        }
    }
}

/// What a round reads besides the probabilities: the uniforms, and the guide as packed sRGB
/// words and log depth.
pub struct GuideBuffers {
    pub uniforms: wgpu::Buffer,
    pub colour: wgpu::Buffer,
    pub log_depth: wgpu::Buffer,
    pub pixels: u64,
}

impl GuideBuffers {
    pub fn new(
        ctx: &GpuContext,
        guide: Guide<'_>,
        classes: usize,
        options: &RefineOptions,
    ) -> Result<GuideBuffers, GpuError> {
        let (width, height) = guide.rgb.dimensions();
        let uniforms = RefineUniforms::new(width, height, classes as u32, options);
        let colour: Vec<u32> = guide
            .rgb
            .pixels()
            .map(|p| u32::from_le_bytes([p[0], p[1], p[2], 255]))
            .collect();
        Ok(GuideBuffers {
            uniforms: uniform_buffer_from(ctx, "refine uniforms", &uniforms),
            colour: storage_buffer_from(ctx, "refine colour", &colour)?,
            log_depth: storage_buffer_from(ctx, "refine log depth", &log_depth(guide))?,
            pixels: u64::from(width) * u64::from(height),
        })
    }
}

/// The compiled refinement kernel; build once, use for any frame.
pub struct RefinePass {
    pipeline: wgpu::ComputePipeline,
}

const REFINE_KERNEL: KernelSpec<'static> = KernelSpec {
    label: "refine",
    source: shaders::REFINE,
    entry_point: "refine",
    layout: None,
    constants: &[],
};

impl RefinePass {
    pub async fn new(ctx: &GpuContext) -> Result<RefinePass, GpuError> {
        Ok(RefinePass {
            pipeline: create_compute_pipeline(ctx, &REFINE_KERNEL).await?,
        })
    }

    /// Records one round reading `input` and writing every value of `output` (both
    /// `width · height · classes` f32).
    pub fn record(
        &self,
        ctx: &GpuContext,
        encoder: &mut wgpu::CommandEncoder,
        guide: &GuideBuffers,
        input: &wgpu::Buffer,
        output: &wgpu::Buffer,
    ) -> Result<(), GpuError> {
        let groups = Dispatch1d::for_device(ctx, guide.pixels, WORKGROUP)?;
        let bindings = whole(&[
            ("u", &guide.uniforms),
            ("colour", &guide.colour),
            ("log_depth", &guide.log_depth),
            ("probabilities_in", input),
            ("probabilities_out", output),
        ]);
        let bind_group = bind_named(
            ctx,
            &REFINE_KERNEL,
            &self.pipeline.get_bind_group_layout(0),
            0,
            &bindings,
        )?;
        let dispatch = Dispatch::new(self.pipeline.clone(), bind_group, groups);
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some("refine"),
            timestamp_writes: None,
        });
        dispatch.record(&mut pass);
        Ok(())
    }

    /// Refines `probabilities` (`classes` per pixel of `guide`) in place, as
    /// `refine::refine_probabilities` does on the CPU.
    pub async fn refine(
        &self,
        ctx: &GpuContext,
        probabilities: &mut Vec<f32>,
        classes: usize,
        guide: Guide<'_>,
        options: &RefineOptions,
    ) -> Result<(), GpuError> {
        check_inputs(probabilities.len(), classes, guide, options)
            .map_err(|e| GpuError::invalid_argument("refine", e))?;
        if options.is_off() || probabilities.is_empty() {
            return Ok(());
        }
        if options.votes {
            crate::refine::to_votes(probabilities, classes);
        }
        let guide = GuideBuffers::new(ctx, guide, classes, options)?;
        let buffers = [
            storage_buffer_from(ctx, "refine probabilities a", probabilities)?,
            storage_buffer_zeroed::<f32>(ctx, "refine probabilities b", probabilities.len())?,
        ];
        let mut encoder = ctx.device.create_command_encoder(&Default::default());
        for round in 0..options.iterations as usize {
            let (input, output) = (&buffers[round % 2], &buffers[(round + 1) % 2]);
            self.record(ctx, &mut encoder, &guide, input, output)?;
        }
        ctx.queue.submit([encoder.finish()]);
        let last = &buffers[options.iterations as usize % 2];
        *probabilities = read_elements_async::<f32>(ctx, last, 0..probabilities.len() as u64).await?;
        Ok(())
    }
}
