//! What can be read out of a trainer and put back: its parameters, its gradient (tests), and the
//! whole resumable state of a run (checkpoints).
use super::Trainer;
use crate::gpu::GpuError;
use crate::gpu::buffers::{PendingRead, read_buffer_async, read_elements_async};

/// A trainer's resumable state (see [`Trainer::read_state`]); the vectors follow `ParamLayout`.
#[derive(Clone, Debug, PartialEq)]
pub struct TrainerState {
    pub step: u32,
    pub params: Vec<f32>,
    pub first_moment: Vec<f32>,
    pub second_moment: Vec<f32>,
}

impl Trainer {
    /// Reads the parameters back (tests, checkpoints).
    pub fn read_params(&self) -> PendingRead<f32> {
        read_elements_async::<f32>(&self.ctx, &self.optimizer.params, 0..self.layout.total as u64)
    }

    /// Reads back the gradient buffer as it is, as f32 (a fixed-point table decoded). Between
    /// steps it is all zeros: each step's Adam
    /// zeroes the gradient it consumed (tests check that; [`Trainer::step_gradient`] reads a
    /// step's gradient).
    pub async fn read_gradients(&self) -> Result<Vec<f32>, GpuError> {
        let exponents = self.hash_backward.read_exponents(&self.ctx);
        let mut values = read_buffer_async::<f32>(&self.ctx, &self.optimizer.grads).await?;
        self.hash_backward.decode_fixed_point(&mut values, exponents).await?;
        Ok(values)
    }

    /// Runs one training step up to, not including, its Adam update and reads back the gradient
    /// it produced (tests: compare with the reference). The step counts (its losses can be
    /// read), the parameters do not move, and the gradient buffer is cleared after the copy so
    /// the next step starts from zero as it would after Adam.
    pub async fn step_gradient(&mut self) -> Result<Vec<f32>, GpuError> {
        let mut encoder = self.begin_step();
        {
            let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: Some("training step without its update"),
                timestamp_writes: None,
            });
            self.visit_step_before_update(&mut |stage| stage.record(&mut pass));
        }
        self.ctx.queue.submit([encoder.finish()]);
        let read = read_buffer_async::<f32>(&self.ctx, &self.optimizer.grads);
        let exponents = self.hash_backward.read_exponents(&self.ctx);
        let mut encoder = self.ctx.device.create_command_encoder(&wgpu::CommandEncoderDescriptor {
            label: Some("clearing the gradient read back"),
        });
        encoder.clear_buffer(&self.optimizer.grads, 0, None);
        self.ctx.queue.submit([encoder.finish()]);
        let mut values = read.await?;
        self.hash_backward.decode_fixed_point(&mut values, exponents).await?;
        Ok(values)
    }

    /// Everything a training run depends on besides the scene, the config and the labels: the
    /// parameters, Adam's two moments and the step count (which seeds the ray batches and sets
    /// Adam's bias corrections). Restoring it continues the run where it stopped.
    pub async fn read_state(&self) -> Result<TrainerState, GpuError> {
        let range = 0..self.layout.total as u64;
        let params = read_elements_async::<f32>(&self.ctx, &self.optimizer.params, range.clone());
        let first = read_elements_async::<f32>(&self.ctx, &self.optimizer.first_moment, range.clone());
        let second = read_elements_async::<f32>(&self.ctx, &self.optimizer.second_moment, range);
        Ok(TrainerState {
            step: self.step,
            params: params.await?,
            first_moment: first.await?,
            second_moment: second.await?,
        })
    }

    /// Puts back a state from [`Trainer::read_state`] of a trainer with the same config.
    pub fn restore_state(&mut self, state: &TrainerState) -> Result<(), GpuError> {
        let total = self.layout.total;
        for (what, len) in [
            ("parameters", state.params.len()),
            ("Adam first moment", state.first_moment.len()),
            ("Adam second moment", state.second_moment.len()),
        ] {
            if len != total {
                return Err(GpuError::invalid_argument(
                    what,
                    format!("{len} values given, the layout has {total}"),
                ));
            }
        }
        let queue = &self.ctx.queue;
        queue.write_buffer(&self.optimizer.params, 0, bytemuck::cast_slice(&state.params));
        queue.write_buffer(
            &self.optimizer.first_moment,
            0,
            bytemuck::cast_slice(&state.first_moment),
        );
        queue.write_buffer(
            &self.optimizer.second_moment,
            0,
            bytemuck::cast_slice(&state.second_moment),
        );
        self.step = state.step;
        self.pending_losses = None;
        self.last_losses = None;
        Ok(())
    }

    /// Replaces the parameters (tests: start from the reference's values).
    pub fn write_params(&self, params: &[f32]) -> Result<(), GpuError> {
        if params.len() != self.layout.total {
            return Err(GpuError::invalid_argument(
                "parameters",
                format!("{} values given, the layout has {}", params.len(), self.layout.total),
            ));
        }
        self.ctx
            .queue
            .write_buffer(&self.optimizer.params, 0, bytemuck::cast_slice(params));
        Ok(())
    }
}
