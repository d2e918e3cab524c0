//! The device everything GPU runs on: adapter choice, device creation with the adapter's own
//! limits, and the few facts kernels need to size themselves (limits, timestamp support).
//!
//! Creation is async because the browser forbids blocking; native code may use
//! [`GpuContext::new_blocking`]. The web app gets its device from eframe and wraps it with
//! [`GpuContext::from_device`].
use std::sync::Arc;

use super::error::GpuError;
use super::pipeline_cache::{PipelineCache, PipelineCacheStats};
use super::profile::{DeviceProfile, KernelFamily};

/// How to pick the adapter.
#[derive(Debug, Clone)]
pub struct GpuOptions {
    pub power_preference: wgpu::PowerPreference,
    /// Only accept a software adapter (lavapipe, SwiftShader, WARP).
    pub force_fallback_adapter: bool,
    /// Native only: pick the first adapter whose name contains this (case-insensitive), e.g.
    /// "llvmpipe" to test on lavapipe on a machine that also has a GPU.
    pub adapter_name: Option<String>,
}

impl Default for GpuOptions {
    fn default() -> Self {
        GpuOptions {
            power_preference: wgpu::PowerPreference::HighPerformance,
            force_fallback_adapter: false,
            adapter_name: None,
        }
    }
}

impl GpuOptions {
    /// Environment variable that sets [`GpuOptions::adapter_name`] in [`GpuOptions::from_env`].
    pub const ADAPTER_ENV: &'static str = "SCRIBBLEFIELD_ADAPTER";

    /// Defaults, with the adapter name taken from `SCRIBBLEFIELD_ADAPTER` when set.
    pub fn from_env() -> Self {
        let adapter_name = std::env::var(Self::ADAPTER_ENV)
            .ok()
            .filter(|name| !name.trim().is_empty());
        GpuOptions {
            adapter_name,
            ..GpuOptions::default()
        }
    }
}

/// A device and queue plus what kernels need to know about them.
#[derive(Debug, Clone)]
pub struct GpuContext {
    pub device: wgpu::Device,
    pub queue: wgpu::Queue,
    pub adapter_info: wgpu::AdapterInfo,
    /// The device's limits: the adapter's own when we created the device, not WebGPU's defaults.
    pub limits: wgpu::Limits,
    pub features: wgpu::Features,
    /// Compute passes can carry timestamp writes (see `gpu::timing`).
    pub has_timestamps: bool,
    /// What the kernels and the page's loop are chosen by on this device.
    profile: DeviceProfile,
    /// Pipelines and bind group layouts compiled on this device, shared by every clone.
    pipeline_cache: Arc<PipelineCache>,
}

impl GpuContext {
    /// Finds an adapter (a real GPU if there is one, else any, e.g. lavapipe) and opens a device
    /// with all of the adapter's limits and, when offered, timestamp queries and float atomics.
    pub async fn new(options: &GpuOptions) -> Result<Self, GpuError> {
        let adapter = find_adapter(options).await?;
        let adapter_info = adapter.get_info();
        // Float atomics let the hash grid's backward add with one atomic instead of a
        // compare-exchange loop (`field::gpu::encoding::AtomicAdd`).
        let wanted_features = wgpu::Features::TIMESTAMP_QUERY | wgpu::Features::SHADER_FLOAT32_ATOMIC;
        let descriptor = wgpu::DeviceDescriptor {
            label: Some("scribblefield"),
            required_features: adapter.features() & wanted_features,
            required_limits: adapter.limits(),
            ..Default::default()
        };
        let (device, queue) = adapter
            .request_device(&descriptor)
            .await
            .map_err(|source| GpuError::RequestDevice {
                adapter: describe_adapter(&adapter_info),
                source,
            })?;
        Ok(Self::from_device(device, queue))
    }

    /// Native only: [`GpuContext::new`] run to completion on this thread.
    #[cfg(not(target_arch = "wasm32"))]
    pub fn new_blocking(options: &GpuOptions) -> Result<Self, GpuError> {
        pollster::block_on(Self::new(options))
    }

    /// Wraps a device somebody else created (eframe's render state in the web app).
    pub fn from_device(device: wgpu::Device, queue: wgpu::Queue) -> Self {
        let features = device.features();
        let adapter_info = device.adapter_info();
        GpuContext {
            profile: DeviceProfile::of_adapter(&adapter_info),
            adapter_info,
            limits: device.limits(),
            has_timestamps: features.contains(wgpu::Features::TIMESTAMP_QUERY),
            features,
            device,
            queue,
            pipeline_cache: Arc::default(),
        }
    }

    /// The device's pipeline cache (see `gpu::pipeline::create_compute_pipeline`).
    pub(crate) fn pipeline_cache(&self) -> &PipelineCache {
        &self.pipeline_cache
    }

    /// How many pipelines this device compiled and how many it handed out again.
    pub fn pipeline_cache_stats(&self) -> PipelineCacheStats {
        self.pipeline_cache.stats()
    }

    /// The bind group layout with these entries, created once per device: what bind groups of a
    /// pipeline built with an explicit layout (`KernelSpec::layout`) are made with.
    pub fn bind_group_layout(&self, label: &str, entries: &[wgpu::BindGroupLayoutEntry]) -> wgpu::BindGroupLayout {
        self.pipeline_cache.bind_group_layout(&self.device, label, entries)
    }

    /// The same device running the `kernels` family whatever the adapter is (`#kernels=`, and
    /// tests that compare the families on one device).
    pub fn with_kernels(mut self, kernels: KernelFamily) -> Self {
        self.profile = self.profile.with_kernels(kernels);
        self
    }

    /// What the kernels and the page's loop are chosen by on this device.
    pub fn profile(&self) -> &DeviceProfile {
        &self.profile
    }

    /// One line naming the adapter, driver and backend, for logs and bench reports.
    pub fn describe(&self) -> String {
        describe_adapter(&self.adapter_info)
    }

    /// Native only: blocks until all submitted work is done and its callbacks have run.
    #[cfg(not(target_arch = "wasm32"))]
    pub fn wait_idle(&self) -> Result<(), GpuError> {
        self.device
            .poll(wgpu::PollType::wait_indefinitely())
            .map(|_| ())
            .map_err(|error| GpuError::Readback {
                what: "device idle wait".into(),
                reason: error.to_string(),
            })
    }

    /// Fails with a clear message when one buffer binding of `bytes` exceeds what the device
    /// allows, so callers can split the work (tiles, chunks) before wgpu rejects a binding.
    pub fn ensure_storage_binding_fits(&self, what: &str, bytes: u64) -> Result<(), GpuError> {
        let allowed = self
            .limits
            .max_storage_buffer_binding_size
            .min(self.limits.max_buffer_size);
        ensure_at_most(what, "max_storage_buffer_binding_size", bytes, allowed)
    }

    /// As [`GpuContext::ensure_storage_binding_fits`], for workgroup (shared) memory per workgroup.
    pub fn ensure_workgroup_storage_fits(&self, what: &str, bytes: u64) -> Result<(), GpuError> {
        let allowed = u64::from(self.limits.max_compute_workgroup_storage_size);
        ensure_at_most(what, "max_compute_workgroup_storage_size", bytes, allowed)
    }

    /// As [`GpuContext::ensure_storage_binding_fits`], for storage buffers bound in one stage.
    pub fn ensure_storage_buffer_count_fits(&self, what: &str, count: u32) -> Result<(), GpuError> {
        let allowed = u64::from(self.limits.max_storage_buffers_per_shader_stage);
        ensure_at_most(what, "max_storage_buffers_per_shader_stage", u64::from(count), allowed)
    }

    /// The compute limits this device has below WebGPU's defaults, as readable lines. Kernels are
    /// written for the defaults; a non-empty answer explains a later failure up front.
    pub fn compute_limit_shortfalls(&self) -> Vec<String> {
        let defaults = wgpu::Limits::default();
        let have = &self.limits;
        let checks: [(&str, u64, u64); 7] = [
            (
                "max_storage_buffer_binding_size",
                have.max_storage_buffer_binding_size,
                defaults.max_storage_buffer_binding_size,
            ),
            ("max_buffer_size", have.max_buffer_size, defaults.max_buffer_size),
            (
                "max_compute_workgroup_storage_size",
                have.max_compute_workgroup_storage_size.into(),
                defaults.max_compute_workgroup_storage_size.into(),
            ),
            (
                "max_storage_buffers_per_shader_stage",
                have.max_storage_buffers_per_shader_stage.into(),
                defaults.max_storage_buffers_per_shader_stage.into(),
            ),
            (
                "max_compute_invocations_per_workgroup",
                have.max_compute_invocations_per_workgroup.into(),
                defaults.max_compute_invocations_per_workgroup.into(),
            ),
            (
                "max_compute_workgroup_size_x",
                have.max_compute_workgroup_size_x.into(),
                defaults.max_compute_workgroup_size_x.into(),
            ),
            (
                "max_compute_workgroups_per_dimension",
                have.max_compute_workgroups_per_dimension.into(),
                defaults.max_compute_workgroups_per_dimension.into(),
            ),
        ];
        checks
            .iter()
            .filter(|(_, have, default)| have < default)
            .map(|(name, have, default)| format!("{name} is {have}, below the WebGPU default {default}"))
            .collect()
    }
}

fn ensure_at_most(what: &str, limit: &'static str, needed: u64, allowed: u64) -> Result<(), GpuError> {
    if needed <= allowed {
        Ok(())
    } else {
        Err(GpuError::LimitExceeded {
            what: what.to_string(),
            limit,
            needed,
            allowed,
        })
    }
}

fn describe_adapter(info: &wgpu::AdapterInfo) -> String {
    let driver = [info.driver.as_str(), info.driver_info.as_str()]
        .into_iter()
        .filter(|part| !part.is_empty())
        .collect::<Vec<_>>()
        .join(" ");
    if driver.is_empty() {
        format!("{} ({:?}, {:?})", info.name, info.backend, info.device_type)
    } else {
        format!("{} [{driver}] ({:?}, {:?})", info.name, info.backend, info.device_type)
    }
}

/// Native: list every adapter and take the most capable kind (discrete > integrated > virtual >
/// software > other), honouring the name filter and fallback flag.
#[cfg(not(target_arch = "wasm32"))]
async fn find_adapter(options: &GpuOptions) -> Result<wgpu::Adapter, GpuError> {
    let instance = wgpu::Instance::new(wgpu::InstanceDescriptor::new_without_display_handle_from_env());
    let adapters = instance.enumerate_adapters(wgpu::Backends::all()).await;
    let wanted_name = options.adapter_name.as_ref().map(|name| name.to_lowercase());
    let found: Vec<String> = adapters
        .iter()
        .map(|adapter| describe_adapter(&adapter.get_info()))
        .collect();
    let best = adapters
        .into_iter()
        .filter(|adapter| {
            let info = adapter.get_info();
            let name_ok = wanted_name
                .as_ref()
                .is_none_or(|wanted| info.name.to_lowercase().contains(wanted));
            let kind_ok = !options.force_fallback_adapter || info.device_type == wgpu::DeviceType::Cpu;
            name_ok && kind_ok
        })
        .max_by_key(|adapter| adapter_rank(adapter.get_info().device_type, options.power_preference));
    best.ok_or_else(|| {
        let mut tried = format!("{:?}", wgpu::Instance::enabled_backend_features());
        if !found.is_empty() {
            tried.push_str(&format!("; present but not matching the options: {}", found.join(", ")));
        }
        GpuError::NoAdapter {
            tried,
            hint: NO_ADAPTER_HINT,
        }
    })
}

#[cfg(not(target_arch = "wasm32"))]
const NO_ADAPTER_HINT: &str = if cfg!(target_os = "linux") {
    ". On Linux without a GPU, install a Vulkan CPU fallback: `apt-get install mesa-vulkan-drivers` (lavapipe)"
} else {
    ". Install or update the GPU driver"
};

#[cfg(not(target_arch = "wasm32"))]
fn adapter_rank(device_type: wgpu::DeviceType, preference: wgpu::PowerPreference) -> u8 {
    let prefer_integrated = preference == wgpu::PowerPreference::LowPower;
    match device_type {
        wgpu::DeviceType::DiscreteGpu if prefer_integrated => 4,
        wgpu::DeviceType::DiscreteGpu => 5,
        wgpu::DeviceType::IntegratedGpu if prefer_integrated => 5,
        wgpu::DeviceType::IntegratedGpu => 4,
        wgpu::DeviceType::VirtualGpu => 3,
        wgpu::DeviceType::Cpu => 2,
        wgpu::DeviceType::Other => 1,
    }
}

/// Browser: the browser picks; we pass the preference along.
#[cfg(target_arch = "wasm32")]
async fn find_adapter(options: &GpuOptions) -> Result<wgpu::Adapter, GpuError> {
    let mut descriptor = wgpu::InstanceDescriptor::new_without_display_handle();
    descriptor.backends = wgpu::Backends::BROWSER_WEBGPU;
    let instance = wgpu::Instance::new(descriptor);
    let request = wgpu::RequestAdapterOptions {
        power_preference: options.power_preference,
        force_fallback_adapter: options.force_fallback_adapter,
        compatible_surface: None,
        apply_limit_buckets: false,
    };
    instance
        .request_adapter(&request)
        .await
        .map_err(|error| GpuError::NoAdapter {
            tried: format!("WebGPU ({error})"),
            hint: ". This browser offers no WebGPU adapter; training needs WebGPU (recent Chrome, Edge or Firefox)",
        })
}
