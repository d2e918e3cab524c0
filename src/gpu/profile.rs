//! What the kernels and the page's loop are chosen by on one device, decided once when the
//! device is opened ([`GpuContext::profile`](super::GpuContext::profile)) instead of asked of
//! the adapter wherever a choice is made. The page's `#kernels=` (and the tests' choice of a
//! kernel family) is applied here, once ([`DeviceProfile::with_kernels`]).
//!
//! Why each device gets what it gets is measured in docs/results/bench.md.

/// Which family of kernels runs the trainer's products and its compositing.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum KernelFamily {
    /// Workgroup-tiled products, a workgroup per ray in the composite, fixed-point atomics
    /// where floats have none: what GPUs run faster.
    Tiled,
    /// Row-per-invocation loops over weights in a uniform binding, an invocation per ray, a
    /// hash backward without atomics: what CPU devices (lavapipe, SwiftShader) run faster,
    /// whose atomics and workgroup barriers are slow.
    UniformWeights,
}

impl KernelFamily {
    /// The name reports and `#kernels=` use.
    pub fn name(self) -> &'static str {
        match self {
            KernelFamily::Tiled => "tiled",
            KernelFamily::UniformWeights => "uniform",
        }
    }
}

/// Training batches the page keeps in flight on a GPU: the device works on one while the next
/// is recorded.
pub const GPU_BATCHES_IN_FLIGHT: usize = 2;

/// Everything chosen by what the device is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct DeviceProfile {
    /// A software rasterizer (lavapipe, SwiftShader, WARP): what the adapter is, whatever
    /// kernels are asked for. The page trains its smallest model there.
    pub software: bool,
    /// The kernel family the trainer builds.
    pub kernels: KernelFamily,
    /// The uniform-weight MLPs run their input gradients as one chain: lavapipe (LLVM) does
    /// that faster, SwiftShader ran every backward slower with it.
    pub chains: bool,
    /// The uniform-weight kernels write their reductions out step by step (`UNROLL` in
    /// `shaders/_dense_uniform.wgsl`): lavapipe loads a uniform value once for all lanes only
    /// at an index made of constants; other CPU devices keep the loop they were measured with.
    pub unrolled_reductions: bool,
    /// The widest block of outputs one uniform-weight invocation computes: lavapipe keeps a whole
    /// 64-wide row's accumulators cheaper than reloading each input per block of 16; Subzero
    /// (SwiftShader, natively and in the page, where a CPU device has no name to tell which it
    /// is) ran 16 faster.
    pub widest_uniform_block: u32,
    /// How often the page repaints while it waits (loading, building): on a CPU device each
    /// repaint costs the work it waits for about a second.
    pub repaint_ms: u64,
    /// How often the training panel's figures are repainted while the field trains: rarer
    /// still on a CPU device, where every repaint delays training.
    pub training_repaint_ms: u64,
}

impl DeviceProfile {
    /// The profile of an adapter.
    pub fn of_adapter(info: &wgpu::AdapterInfo) -> DeviceProfile {
        let software = is_software_adapter(info);
        let name = info.name.to_ascii_lowercase();
        let lavapipe = name.contains("llvmpipe") || name.contains("lavapipe");
        DeviceProfile {
            software,
            kernels: if software {
                KernelFamily::UniformWeights
            } else {
                KernelFamily::Tiled
            },
            chains: lavapipe,
            unrolled_reductions: lavapipe,
            widest_uniform_block: if lavapipe { 64 } else { 16 },
            repaint_ms: if software { 1000 } else { 100 },
            training_repaint_ms: if software { 3000 } else { 250 },
        }
    }

    /// The same device running the `kernels` family whatever it is (`#kernels=`, and tests that
    /// compare the families on one device).
    pub fn with_kernels(self, kernels: KernelFamily) -> DeviceProfile {
        DeviceProfile { kernels, ..self }
    }

    /// Training batches the page keeps in flight, as the kernel family's devices get them: one
    /// on a CPU device, where the next batch's recording competes with the device for the same
    /// cores.
    pub fn batches_in_flight(&self) -> usize {
        match self.kernels {
            KernelFamily::UniformWeights => 1,
            KernelFamily::Tiled => GPU_BATCHES_IN_FLIGHT,
        }
    }
}

/// Whether an adapter is a software rasterizer (lavapipe/llvmpipe, SwiftShader, WARP): a CPU
/// device type, or one of their names in the adapter's name or driver (browsers often report
/// no device type).
pub fn is_software_adapter(info: &wgpu::AdapterInfo) -> bool {
    const NAMES: [&str; 5] = ["swiftshader", "llvmpipe", "lavapipe", "software", "warp"];
    let named = |s: &str| {
        let s = s.to_ascii_lowercase();
        NAMES.iter().any(|n| s.contains(n))
    };
    info.device_type == wgpu::DeviceType::Cpu || named(&info.name) || named(&info.driver)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn adapter(name: &str, device_type: wgpu::DeviceType) -> wgpu::AdapterInfo {
        wgpu::AdapterInfo {
            name: name.into(),
            device_type,
            ..wgpu::AdapterInfo::new(wgpu::DeviceType::Other, wgpu::Backend::Noop)
        }
    }

    #[test]
    fn each_kind_of_device_gets_its_own_kernels() {
        let lavapipe = DeviceProfile::of_adapter(&adapter("llvmpipe (LLVM 15.0.6, 256 bits)", wgpu::DeviceType::Cpu));
        assert_eq!(lavapipe.kernels, KernelFamily::UniformWeights);
        assert!(lavapipe.software && lavapipe.chains && lavapipe.unrolled_reductions);
        assert_eq!((lavapipe.widest_uniform_block, lavapipe.batches_in_flight()), (64, 1));

        let swiftshader = DeviceProfile::of_adapter(&adapter("SwiftShader Device (Subzero)", wgpu::DeviceType::Other));
        assert_eq!(swiftshader.kernels, KernelFamily::UniformWeights);
        assert!(swiftshader.software && !swiftshader.chains && !swiftshader.unrolled_reductions);
        assert_eq!(swiftshader.widest_uniform_block, 16);

        let gpu = DeviceProfile::of_adapter(&adapter("NVIDIA H100", wgpu::DeviceType::DiscreteGpu));
        assert_eq!(gpu.kernels, KernelFamily::Tiled);
        assert!(!gpu.software);
        assert_eq!(gpu.batches_in_flight(), GPU_BATCHES_IN_FLIGHT);
        assert!(gpu.repaint_ms < swiftshader.repaint_ms && gpu.training_repaint_ms < swiftshader.training_repaint_ms);
    }

    #[test]
    fn asking_for_a_family_changes_the_kernels_and_not_what_the_device_is() {
        let lavapipe = DeviceProfile::of_adapter(&adapter("llvmpipe", wgpu::DeviceType::Cpu));
        let tiled = lavapipe.with_kernels(KernelFamily::Tiled);
        assert_eq!(tiled.kernels, KernelFamily::Tiled);
        assert_eq!(tiled.batches_in_flight(), GPU_BATCHES_IN_FLIGHT);
        assert!(tiled.software && tiled.chains);
        assert_eq!(tiled.repaint_ms, lavapipe.repaint_ms);
        assert_eq!(tiled.with_kernels(KernelFamily::UniformWeights), lavapipe);
    }
}
