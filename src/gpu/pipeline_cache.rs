//! Compiled compute pipelines and bind group layouts, kept with the device they belong to
//! ([`GpuContext`](super::GpuContext) holds one cache), so every pass built later on the same
//! context (a second trainer after a training restart in the page, the renderer, the bench)
//! reuses what an earlier one compiled instead of compiling the same WGSL again.
use std::collections::HashMap;
use std::sync::{Mutex, PoisonError};

/// What makes two pipelines the same: shader text, entry point, override constants and, for an
/// explicit layout, the entries of each bind group.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub(crate) struct PipelineKey {
    pub source: String,
    pub entry_point: String,
    /// Constant names with their values' bits (f64 is not `Hash`).
    pub constants: Vec<(String, u64)>,
    pub layout: Option<Vec<Vec<wgpu::BindGroupLayoutEntry>>>,
}

/// How often the cache was asked and how often it had to create something.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct PipelineCacheStats {
    /// Pipelines compiled (cache misses).
    pub compiled: u64,
    /// Pipelines handed out again (cache hits).
    pub reused: u64,
    /// Bind group layouts created for explicit pipeline layouts.
    pub layouts_created: u64,
}

#[derive(Default)]
struct Entries {
    pipelines: HashMap<PipelineKey, wgpu::ComputePipeline>,
    layouts: HashMap<Vec<wgpu::BindGroupLayoutEntry>, wgpu::BindGroupLayout>,
    stats: PipelineCacheStats,
}

/// The cache itself; one per device, shared by every clone of its context.
#[derive(Default)]
pub struct PipelineCache {
    entries: Mutex<Entries>,
}

impl std::fmt::Debug for PipelineCache {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("PipelineCache").field("stats", &self.stats()).finish()
    }
}

impl PipelineCache {
    /// A lock that survives a panic elsewhere: the maps stay consistent whatever was interrupted
    /// (each update is a single insert).
    fn lock(&self) -> std::sync::MutexGuard<'_, Entries> {
        self.entries.lock().unwrap_or_else(PoisonError::into_inner)
    }

    pub fn stats(&self) -> PipelineCacheStats {
        self.lock().stats
    }

    /// The pipeline compiled earlier for `key`, counting the hit.
    pub(crate) fn pipeline(&self, key: &PipelineKey) -> Option<wgpu::ComputePipeline> {
        let mut entries = self.lock();
        let pipeline = entries.pipelines.get(key).cloned();
        if pipeline.is_some() {
            entries.stats.reused += 1;
        }
        pipeline
    }

    /// Keeps a freshly compiled pipeline, counting the miss.
    pub(crate) fn insert_pipeline(&self, key: PipelineKey, pipeline: &wgpu::ComputePipeline) {
        let mut entries = self.lock();
        entries.stats.compiled += 1;
        entries.pipelines.insert(key, pipeline.clone());
    }

    /// The bind group layout with these entries, created on first use.
    pub(crate) fn bind_group_layout(
        &self,
        device: &wgpu::Device,
        label: &str,
        entries: &[wgpu::BindGroupLayoutEntry],
    ) -> wgpu::BindGroupLayout {
        let mut cache = self.lock();
        if let Some(layout) = cache.layouts.get(entries) {
            return layout.clone();
        }
        let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some(label),
            entries,
        });
        cache.stats.layouts_created += 1;
        cache.layouts.insert(entries.to_vec(), layout.clone());
        layout
    }
}
