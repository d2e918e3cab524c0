//! GPU time per compute pass, from timestamp queries written at the start and end of each pass.
//! Only where the device has `TIMESTAMP_QUERY`: [`PassTimer::new`] answers `None` otherwise, and
//! callers fall back to wall-clock time (see [`Stopwatch`]).
//!
//! Use: `timer.timestamp_writes("encode")` into each `ComputePassDescriptor`, `timer.resolve(&mut
//! encoder)` before `finish()`, submit, then `timer.read(ctx).await` for the named durations.
use super::buffers::{PendingRead, read_elements_async};
use super::context::GpuContext;
use super::error::GpuError;

/// The GPU time one named pass took.
#[derive(Debug, Clone, PartialEq)]
pub struct PassTime {
    pub name: String,
    pub seconds: f64,
}

/// Sums the times of passes that share a name (e.g. the same kernel over many steps), in the
/// order the names first appear.
pub fn total_by_name(times: &[PassTime]) -> Vec<PassTime> {
    let mut totals: Vec<PassTime> = Vec::new();
    for time in times {
        match totals.iter_mut().find(|total| total.name == time.name) {
            Some(total) => total.seconds += time.seconds,
            None => totals.push(time.clone()),
        }
    }
    totals
}

/// Timestamp queries for up to `capacity` passes per round.
pub struct PassTimer {
    query_set: wgpu::QuerySet,
    resolve_buffer: wgpu::Buffer,
    capacity: u32,
    names: Vec<String>,
    /// Passes asked for beyond capacity; they ran untimed.
    untimed: usize,
    /// Nanoseconds per timestamp tick.
    period_ns: f64,
}

impl PassTimer {
    /// `None` when the device cannot write timestamps in compute passes.
    pub fn new(ctx: &GpuContext, capacity: u32) -> Option<Self> {
        if !ctx.has_timestamps || capacity == 0 {
            return None;
        }
        // A query set holds at most 4096 queries (two per pass).
        let capacity = capacity.min(wgpu::QUERY_SET_MAX_QUERIES / 2);
        let query_set = ctx.device.create_query_set(&wgpu::QuerySetDescriptor {
            label: Some("pass timestamps"),
            ty: wgpu::QueryType::Timestamp,
            count: capacity * 2,
        });
        let resolve_buffer = ctx.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("pass timestamps resolved"),
            size: u64::from(capacity) * 2 * u64::from(wgpu::QUERY_SIZE),
            usage: wgpu::BufferUsages::QUERY_RESOLVE | wgpu::BufferUsages::COPY_SRC,
            mapped_at_creation: false,
        });
        Some(PassTimer {
            query_set,
            resolve_buffer,
            capacity,
            names: Vec::new(),
            untimed: 0,
            period_ns: f64::from(ctx.queue.get_timestamp_period()),
        })
    }

    /// Timestamp writes for the next pass, named `name`; `None` once the round is full (the pass
    /// then runs untimed and [`PassTimer::untimed_passes`] counts it).
    pub fn timestamp_writes(&mut self, name: &str) -> Option<wgpu::ComputePassTimestampWrites<'_>> {
        let index = self.names.len() as u32;
        if index >= self.capacity {
            self.untimed += 1;
            return None;
        }
        self.names.push(name.to_string());
        Some(wgpu::ComputePassTimestampWrites {
            query_set: &self.query_set,
            beginning_of_pass_write_index: Some(2 * index),
            end_of_pass_write_index: Some(2 * index + 1),
        })
    }

    /// Passes asked for this round beyond the capacity.
    pub fn untimed_passes(&self) -> usize {
        self.untimed
    }

    /// Records the copy of this round's timestamps into a readable buffer; call after the last
    /// timed pass, on the same or a later encoder.
    pub fn resolve(&self, encoder: &mut wgpu::CommandEncoder) {
        let used = self.names.len() as u32 * 2;
        if used > 0 {
            encoder.resolve_query_set(&self.query_set, 0..used, &self.resolve_buffer, 0);
        }
    }

    /// Reads this round's durations (after the resolving encoder was submitted) and starts a new
    /// round.
    pub fn read(&mut self, ctx: &GpuContext) -> PassTimesRead {
        let names = std::mem::take(&mut self.names);
        self.untimed = 0;
        let ticks = read_elements_async::<u64>(ctx, &self.resolve_buffer, 0..names.len() as u64 * 2);
        PassTimesRead {
            names,
            ticks,
            period_ns: self.period_ns,
        }
    }
}

/// Pass durations on their way back from the GPU.
pub struct PassTimesRead {
    names: Vec<String>,
    ticks: PendingRead<u64>,
    period_ns: f64,
}

impl PassTimesRead {
    pub async fn times(self) -> Result<Vec<PassTime>, GpuError> {
        let ticks = self.ticks.await?;
        Ok(self
            .names
            .into_iter()
            .zip(ticks.chunks_exact(2))
            .map(|(name, pair)| {
                // Some drivers reorder the two writes slightly; a negative span is zero time.
                let span = pair[1].saturating_sub(pair[0]);
                PassTime {
                    name,
                    seconds: span as f64 * self.period_ns * 1e-9,
                }
            })
            .collect())
    }
}

/// Wall-clock time that works natively and in the browser (`std::time::Instant` panics on
/// wasm32-unknown-unknown).
#[derive(Debug, Clone, Copy)]
pub struct Stopwatch {
    #[cfg(not(target_arch = "wasm32"))]
    start: std::time::Instant,
    #[cfg(target_arch = "wasm32")]
    start_ms: f64,
}

impl Stopwatch {
    pub fn start() -> Self {
        #[cfg(not(target_arch = "wasm32"))]
        {
            Stopwatch {
                start: std::time::Instant::now(),
            }
        }
        #[cfg(target_arch = "wasm32")]
        {
            Stopwatch {
                start_ms: js_sys::Date::now(),
            }
        }
    }

    pub fn elapsed_seconds(&self) -> f64 {
        #[cfg(not(target_arch = "wasm32"))]
        {
            self.start.elapsed().as_secs_f64()
        }
        #[cfg(target_arch = "wasm32")]
        {
            (js_sys::Date::now() - self.start_ms) / 1000.0
        }
    }
}
