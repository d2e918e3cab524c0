//! Buffers from plain data, buffers full of garbage, and reading buffers back.
//!
//! Kernels under test write into buffers first filled with [`GARBAGE_WORDS`] (NaNs, infinities,
//! huge values), so a kernel that forgets to write an element is caught instead of passing on a
//! lucky zero.
//!
//! Readback is asynchronous ([`read_buffer_async`], [`PendingRead`]) because the browser forbids
//! blocking. On native, awaiting a read drives the device itself (blocking until the GPU is done),
//! so a read awaited under `pollster` cannot hang; [`read_buffer_blocking`] does exactly that.
use std::future::Future;
use std::marker::PhantomData;
use std::ops::Range;
use std::pin::Pin;
use std::task::{Context, Poll};

use bytemuck::Pod;
use futures_channel::oneshot;
use wgpu::util::DeviceExt as _;

use super::context::GpuContext;
use super::error::GpuError;

/// The repeating 32-bit pattern written by the garbage fills: a quiet NaN, f32::MAX, -infinity
/// and a word that is huge as u32 and as i32 magnitude (0xDEADBEEF). None of them is a value a
/// correct kernel leaves behind, whether the element is read as f32, u32 or i32.
pub const GARBAGE_WORDS: [u32; 4] = [0x7FC0_DEAD, 0x7F7F_FFFF, 0xFF80_0000, 0xDEAD_BEEF];

/// Usages of every storage buffer made here: bindable, and copyable both ways so it can be
/// filled, cleared and read back.
pub const STORAGE_USAGE: wgpu::BufferUsages = wgpu::BufferUsages::STORAGE
    .union(wgpu::BufferUsages::COPY_SRC)
    .union(wgpu::BufferUsages::COPY_DST);

/// `count` 32-bit words of the garbage pattern.
pub fn garbage_words(count: usize) -> Vec<u32> {
    GARBAGE_WORDS.iter().copied().cycle().take(count).collect()
}

/// Rounds a byte size up to what wgpu copies and maps in (4 bytes), at least 4 so the buffer can
/// be bound.
fn padded_size(bytes: u64) -> u64 {
    bytes.max(1).next_multiple_of(wgpu::COPY_BUFFER_ALIGNMENT)
}

fn checked_byte_size<T>(what: &str, count: usize) -> Result<u64, GpuError> {
    count
        .checked_mul(size_of::<T>())
        .map(|bytes| bytes as u64)
        .ok_or_else(|| GpuError::invalid_argument(what, format!("{count} elements overflow a byte size")))
}

/// A storage buffer holding `data` (padded to 4 bytes).
pub fn storage_buffer_from<T: Pod>(ctx: &GpuContext, label: &str, data: &[T]) -> Result<wgpu::Buffer, GpuError> {
    let bytes: &[u8] = bytemuck::cast_slice(data);
    ctx.ensure_storage_binding_fits(label, padded_size(bytes.len() as u64))?;
    if bytes.is_empty() {
        return storage_buffer_zeroed::<u32>(ctx, label, 1);
    }
    Ok(ctx.device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: Some(label),
        contents: bytes,
        usage: STORAGE_USAGE,
    }))
}

/// A storage buffer holding `data` followed by `tail_zeros` zero elements, with `extra` usages
/// (e.g. UNIFORM, for a buffer that some kernels read through uniform bindings of a fixed size
/// that may reach past the data).
pub fn storage_buffer_padded<T: Pod>(
    ctx: &GpuContext,
    label: &str,
    data: &[T],
    tail_zeros: usize,
    extra: wgpu::BufferUsages,
) -> Result<wgpu::Buffer, GpuError> {
    let mut bytes: Vec<u8> = bytemuck::cast_slice(data).to_vec();
    bytes.resize(checked_byte_size::<T>(label, data.len() + tail_zeros)? as usize, 0);
    bytes.resize(padded_size(bytes.len() as u64).max(4) as usize, 0);
    ctx.ensure_storage_binding_fits(label, bytes.len() as u64)?;
    Ok(ctx.device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: Some(label),
        contents: &bytes,
        usage: STORAGE_USAGE | extra,
    }))
}

/// A storage buffer of `count` elements of `T`, all zero bits.
pub fn storage_buffer_zeroed<T: Pod>(ctx: &GpuContext, label: &str, count: usize) -> Result<wgpu::Buffer, GpuError> {
    let size = padded_size(checked_byte_size::<T>(label, count)?);
    ctx.ensure_storage_binding_fits(label, size)?;
    // wgpu zero-initializes new buffers (a WebGPU guarantee).
    Ok(ctx.device.create_buffer(&wgpu::BufferDescriptor {
        label: Some(label),
        size,
        usage: STORAGE_USAGE,
        mapped_at_creation: false,
    }))
}

/// A storage buffer of `count` elements of `T` filled with the garbage pattern: for outputs of
/// kernels under test.
pub fn storage_buffer_garbage<T: Pod>(ctx: &GpuContext, label: &str, count: usize) -> Result<wgpu::Buffer, GpuError> {
    let size = padded_size(checked_byte_size::<T>(label, count)?);
    ctx.ensure_storage_binding_fits(label, size)?;
    let garbage = garbage_words((size / 4) as usize);
    Ok(ctx.device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: Some(label),
        contents: bytemuck::cast_slice(&garbage),
        usage: STORAGE_USAGE,
    }))
}

/// Overwrites a whole buffer (which needs COPY_DST) with the garbage pattern, e.g. before reusing
/// an output buffer in a test. Takes effect in queue order.
pub fn fill_with_garbage(ctx: &GpuContext, buffer: &wgpu::Buffer) {
    let garbage = garbage_words((buffer.size() / 4) as usize);
    ctx.queue.write_buffer(buffer, 0, bytemuck::cast_slice(&garbage));
}

/// A uniform buffer holding `value` (a `#[repr(C)]` Pod struct laid out like the WGSL struct;
/// WGSL rounds uniform structs up to 16 bytes, so pad the Rust struct to match).
pub fn uniform_buffer_from<T: Pod>(ctx: &GpuContext, label: &str, value: &T) -> wgpu::Buffer {
    ctx.device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: Some(label),
        contents: bytemuck::bytes_of(value),
        usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
    })
}

/// Reads a whole buffer (which needs COPY_SRC) back as elements of `T`. Trailing bytes that do
/// not fill a whole `T` (padding) are dropped.
pub fn read_buffer_async<T: Pod>(ctx: &GpuContext, buffer: &wgpu::Buffer) -> PendingRead<T> {
    let count = buffer.size() / size_of::<T>().max(1) as u64;
    read_elements_async(ctx, buffer, 0..count)
}

/// Reads elements `range` (in units of `T`) of a buffer back, e.g. the one loss value of a larger
/// buffer. Starts the copy immediately; the data arrives when the returned future resolves (or
/// [`PendingRead::try_take`] returns it).
pub fn read_elements_async<T: Pod>(ctx: &GpuContext, buffer: &wgpu::Buffer, range: Range<u64>) -> PendingRead<T> {
    let what = format!("{} elements {}..{}", buffer_name(buffer), range.start, range.end);
    let element = size_of::<T>() as u64;
    let (start, end) = (range.start.saturating_mul(element), range.end.saturating_mul(element));
    if range.start > range.end || end > buffer.size() {
        let problem = format!("range is outside the buffer of {} bytes", buffer.size());
        return PendingRead::without_gpu_work(ctx, what, ReadStage::Invalid(problem));
    }
    // Copies and maps work in 4-byte units; copy the enclosing aligned range and trim afterwards.
    let aligned_start = start - start % wgpu::COPY_BUFFER_ALIGNMENT;
    let aligned_end = end
        .next_multiple_of(wgpu::COPY_BUFFER_ALIGNMENT)
        .min(buffer.size())
        .max(aligned_start);
    let copy_size = aligned_end - aligned_start;
    if copy_size == 0 {
        return PendingRead::without_gpu_work(ctx, what, ReadStage::Empty);
    }
    let staging = ctx.device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("readback staging"),
        size: copy_size,
        usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    });
    let mut encoder = ctx.device.create_command_encoder(&wgpu::CommandEncoderDescriptor {
        label: Some("readback"),
    });
    encoder.copy_buffer_to_buffer(buffer, aligned_start, &staging, 0, copy_size);
    ctx.queue.submit([encoder.finish()]);

    let (mapped, map_result) = oneshot::channel();
    staging.map_async(wgpu::MapMode::Read, .., move |result| {
        // The read may have been dropped meanwhile; then nobody wants the result.
        let _ = mapped.send(result.map_err(|error| error.to_string()));
    });
    PendingRead {
        #[cfg(not(target_arch = "wasm32"))]
        device: ctx.device.clone(),
        what,
        stage: ReadStage::InFlight(staging, map_result),
        bytes: (start - aligned_start)..(end - aligned_start),
        _element: PhantomData,
    }
}

/// Native only: [`read_buffer_async`] run to completion on this thread.
#[cfg(not(target_arch = "wasm32"))]
pub fn read_buffer_blocking<T: Pod>(ctx: &GpuContext, buffer: &wgpu::Buffer) -> Result<Vec<T>, GpuError> {
    pollster::block_on(read_buffer_async(ctx, buffer))
}

fn buffer_name(buffer: &wgpu::Buffer) -> String {
    format!("buffer of {} bytes", buffer.size())
}

enum ReadStage {
    /// The request was invalid; nothing was submitted.
    Invalid(String),
    /// Nothing to read (an empty range).
    Empty,
    /// Copy submitted, mapping requested; the map callback sends its outcome.
    InFlight(wgpu::Buffer, oneshot::Receiver<Result<(), String>>),
    /// The data was handed out.
    Taken,
}

/// A readback in flight. Await it, or call [`PendingRead::try_take`] now and then (the trainer's
/// occasional loss read: it never waits).
pub struct PendingRead<T> {
    /// Native devices only make progress when polled; the browser drives its own.
    #[cfg(not(target_arch = "wasm32"))]
    device: wgpu::Device,
    what: String,
    stage: ReadStage,
    /// The requested bytes within the staging buffer.
    bytes: Range<u64>,
    // `fn() -> T`: the read produces Ts but holds none, so it is Unpin and Send whatever T is.
    _element: PhantomData<fn() -> T>,
}

impl<T: Pod> PendingRead<T> {
    // The browser needs no device handle to make progress, so `ctx` is native-only.
    #[cfg_attr(target_arch = "wasm32", allow(unused_variables))]
    fn without_gpu_work(ctx: &GpuContext, what: String, stage: ReadStage) -> Self {
        PendingRead {
            #[cfg(not(target_arch = "wasm32"))]
            device: ctx.device.clone(),
            what,
            stage,
            bytes: 0..0,
            _element: PhantomData,
        }
    }

    /// The data if the GPU has delivered it, without waiting. `None` means "not yet"; once it has
    /// returned `Some`, the read is finished and further calls return an error.
    pub fn try_take(&mut self) -> Option<Result<Vec<T>, GpuError>> {
        #[cfg(not(target_arch = "wasm32"))]
        {
            // Native callbacks only run inside a poll; this one does not block.
            let _ = self.device.poll(wgpu::PollType::Poll);
        }
        self.finish_if_ready(None)
    }

    /// The outcome if the map callback has run. With `cx`, a read still in flight wakes that
    /// task when the callback runs.
    fn finish_if_ready(&mut self, cx: Option<&mut Context<'_>>) -> Option<Result<Vec<T>, GpuError>> {
        let readback_error = |reason: String| GpuError::Readback {
            what: self.what.clone(),
            reason,
        };
        let outcome = match &mut self.stage {
            ReadStage::Invalid(reason) => Err(readback_error(reason.clone())),
            ReadStage::Empty => Ok(Vec::new()),
            ReadStage::Taken => Err(readback_error("the data was already taken".into())),
            ReadStage::InFlight(staging, map_result) => {
                let mapped = match cx {
                    Some(cx) => match Pin::new(map_result).poll(cx) {
                        Poll::Ready(mapped) => mapped,
                        Poll::Pending => return None,
                    },
                    None => map_result.try_recv().transpose()?,
                };
                let outcome = match mapped {
                    Ok(Ok(())) => copy_out(staging, &self.bytes).map_err(readback_error),
                    Ok(Err(reason)) => Err(readback_error(reason)),
                    Err(oneshot::Canceled) => {
                        Err(readback_error("the map callback was dropped without running".into()))
                    }
                };
                staging.unmap();
                outcome
            }
        };
        self.stage = ReadStage::Taken;
        Some(outcome)
    }
}

/// The requested `bytes` of a mapped staging buffer as elements of `T`.
fn copy_out<T: Pod>(staging: &wgpu::Buffer, bytes: &Range<u64>) -> Result<Vec<T>, String> {
    let view = staging.get_mapped_range(..).map_err(|error| error.to_string())?;
    let bytes = &view[bytes.start as usize..bytes.end as usize];
    let count = bytes.len() / size_of::<T>().max(1);
    let mut out = vec![T::zeroed(); count];
    bytemuck::cast_slice_mut::<T, u8>(&mut out).copy_from_slice(&bytes[..count * size_of::<T>()]);
    Ok(out)
}

impl<T: Pod> Future for PendingRead<T> {
    type Output = Result<Vec<T>, GpuError>;

    fn poll(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<Self::Output> {
        if let Some(done) = self.finish_if_ready(Some(cx)) {
            return Poll::Ready(done);
        }
        #[cfg(not(target_arch = "wasm32"))]
        {
            // Nothing else drives a native device: wait for the GPU here (the map callback runs
            // inside this poll), then look again.
            if let Err(error) = self.device.poll(wgpu::PollType::wait_indefinitely()) {
                let what = self.what.clone();
                return Poll::Ready(Err(GpuError::Readback {
                    what,
                    reason: error.to_string(),
                }));
            }
            if let Some(done) = self.finish_if_ready(None) {
                return Poll::Ready(done);
            }
        }
        Poll::Pending
    }
}
