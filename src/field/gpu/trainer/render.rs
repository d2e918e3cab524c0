//! Rendering with a trainer's field: whole frames and free views, in tiles of one batch of rays.
use super::*;
use crate::scene::camera::Intrinsics;

/// Most pixels [`Trainer::render_probabilities`] renders in one band of rows.
pub const BAND_PIXELS: usize = 1 << 18;

impl Trainer {
    /// Renders frame `frame` at its own resolution, in tiles of one batch of rays each, with the
    /// scene's depth guiding the samples as in training (rays made on the GPU). Each tile is read
    /// back before the next is recorded, so memory stays at one batch whatever the frame size.
    pub async fn render_frame(&mut self, frame: u32, width: u32, height: u32) -> Result<RenderedFrame, GpuError> {
        if frame >= self.frame_count || width * height != self.pixels_per_frame {
            return Err(GpuError::invalid_argument(
                "render",
                format!(
                    "frame {frame} of {width} x {height} is not in this scene ({} frames)",
                    self.frame_count
                ),
            ));
        }
        let first = frame * self.pixels_per_frame;
        let mut out = self.assembler(width, height);
        let mut done = 0u32;
        while done < self.pixels_per_frame {
            let count = (self.pixels_per_frame - done).min(self.cfg.batch_rays);
            self.frame_tile.set_tile(&self.ctx, first + done, count);
            self.render_tile(count, &mut out, true).await?;
            done += count;
        }
        Ok(out.finish(self.display_pca.as_ref()))
    }

    /// Renders any camera at any resolution (a new pose, or a scene frame at a lower resolution
    /// for a quick preview). With [`DepthGuide::Estimate`] the view is rendered twice, the
    /// second time with samples around the depth the first one found.
    pub async fn render_view(&mut self, view: &ViewCamera, guide: DepthGuide<'_>) -> Result<RenderedFrame, GpuError> {
        let pixels = view.pixels();
        if pixels == 0 || view.width > 16384 || view.height > 16384 {
            return Err(GpuError::invalid_argument(
                "render",
                format!("a view of {} x {} pixels cannot be rendered", view.width, view.height),
            ));
        }
        let estimated;
        let depth = match guide {
            DepthGuide::Measured(depth) => {
                if depth.len() != pixels {
                    return Err(GpuError::invalid_argument(
                        "render",
                        format!("depth guide has {} values for a view of {pixels} pixels", depth.len()),
                    ));
                }
                Some(depth)
            }
            DepthGuide::Estimate => {
                estimated = self.render_rays(view, None).await?.depth().to_vec();
                Some(estimated.as_slice())
            }
        };
        Ok(self.render_rays(view, depth).await?.finish(self.display_pca.as_ref()))
    }

    /// The class probabilities (`num_classes` per pixel, row-major) of any camera at any
    /// resolution, with `depth` (metres per pixel, 0: none) guiding the samples. Rendered in
    /// bands of rows of at most [`BAND_PIXELS`] pixels, each a view of its own (the principal
    /// point moved up by the band's first row), so that what is held besides the result stays
    /// one band whatever the size: a 1920 x 1440 frame is 2.8 M pixels.
    pub async fn render_probabilities(&mut self, view: &ViewCamera, depth: &[f32]) -> Result<Vec<f32>, GpuError> {
        let pixels = view.pixels();
        if pixels == 0 || view.width > 16384 || view.height > 16384 {
            return Err(GpuError::invalid_argument(
                "render",
                format!("a view of {} x {} pixels cannot be rendered", view.width, view.height),
            ));
        }
        if depth.len() != pixels {
            return Err(GpuError::invalid_argument(
                "render",
                format!("depth guide has {} values for a view of {pixels} pixels", depth.len()),
            ));
        }
        let width = view.width as usize;
        let rows = (BAND_PIXELS / width).max(1) as u32;
        let mut out = Vec::with_capacity(pixels * self.cfg.num_classes as usize);
        let mut top = 0u32;
        while top < view.height {
            let height = rows.min(view.height - top);
            let band = ViewCamera {
                intrinsics: Intrinsics {
                    cy: view.intrinsics.cy - f64::from(top),
                    ..view.intrinsics
                },
                height,
                ..*view
            };
            let first = top as usize * width;
            let guide = &depth[first..first + band.pixels()];
            out.extend(self.render_rays(&band, Some(guide)).await?.into_probabilities());
            top += height;
        }
        Ok(out)
    }

    async fn render_rays(&mut self, view: &ViewCamera, depth: Option<&[f32]>) -> Result<FrameAssembler, GpuError> {
        let batch = self.cfg.batch_rays as usize;
        let mut out = self.assembler(view.width, view.height);
        // Rendering computes no loss: target rows only carry the flags (the composite skips rays
        // that miss the box by them) and no label.
        let row_words = TARGET_HEADER_WORDS + self.cfg.feature_dim as usize;
        let mut targets = vec![0u32; batch * row_words];
        let miss = RayGeometry {
            origin: [0.0; 3],
            z_per_t: 1.0,
            dir: [0.0, 0.0, 1.0],
            near: 0.0,
            far: 0.0,
            depth: 0.0,
            pixel: 0,
            flags: 0,
        };
        let mut done = 0;
        while done < view.pixels() {
            let count = (view.pixels() - done).min(batch);
            let mut rays = view_rays(view, &self.bounds, depth, done, count);
            rays.resize(batch, miss);
            for (row, ray) in targets.chunks_exact_mut(row_words).zip(&rays) {
                row[TARGET_LABEL] = NO_LABEL;
                row[TARGET_FLAGS] = ray.flags;
                row[TARGET_PIXEL] = ray.pixel;
            }
            self.ctx
                .queue
                .write_buffer(&self.ray_batch.rays, 0, bytemuck::cast_slice(&rays));
            self.ctx
                .queue
                .write_buffer(&self.ray_batch.targets, 0, bytemuck::cast_slice(&targets));
            self.render_tile(count as u32, &mut out, false).await?;
            done += count;
        }
        Ok(out)
    }

    fn assembler(&self, width: u32, height: u32) -> FrameAssembler {
        FrameAssembler::new(
            width,
            height,
            self.cfg.num_classes as usize,
            self.cfg.feature_dim as usize,
        )
    }

    /// Renders the batch's rays (made by the frame-tile kernel when `frame_tile`, else already
    /// written) and adds the first `count` to `out`.
    async fn render_tile(&mut self, count: u32, out: &mut FrameAssembler, frame_tile: bool) -> Result<(), GpuError> {
        // A fixed step keeps the sample jitter of a pixel the same on every render.
        let uniforms = StepUniforms::for_step(&self.cfg, 1, self.seed ^ 0x5eed, 0.0);
        self.ctx
            .queue
            .write_buffer(&self.step_uniforms, 0, bytemuck::bytes_of(&uniforms));
        let mut encoder = self.ctx.device.create_command_encoder(&Default::default());
        {
            let mut pass = encoder.begin_compute_pass(&Default::default());
            if frame_tile {
                self.frame_tile.record(&mut pass);
            }
            self.visit_field_stages(&mut |stage| stage.record(&mut pass));
            // The forward alone: a render needs no loss and no gradient.
            self.composite.record_render(&mut pass);
        }
        self.ctx.queue.submit([encoder.finish()]);
        let layout = self.composite.layout;
        let words = layout.rendered(0..count as usize);
        let rows = read_elements_async::<f32>(
            &self.ctx,
            &self.composite.ray_outputs,
            words.start as u64..words.end as u64,
        )
        .await?;
        for row in rows.chunks_exact(layout.grad_stride()) {
            out.push(row);
        }
        Ok(())
    }
}
