//! One recorded dispatch of a compute kernel ([`Dispatch`]: pipeline, bind group, workgroup
//! counts), and bind groups made from resources named as the WGSL names its variables
//! ([`bind_named`]), checked against the table `build.rs` generates from the shader
//! (`shaders::ShaderBinding`: which bindings each entry point uses, by name), so a pass never
//! lists bindings by position.
use super::context::GpuContext;
use super::error::GpuError;
use super::pipeline::{Dispatch1d, KernelSpec, count_dispatch, create_compute_pipeline};
use super::shaders::{ShaderBinding, bindings_of};

/// A compute pipeline with its bind group 0 and workgroup counts: what a pass records.
#[derive(Debug)]
pub struct Dispatch {
    pub pipeline: wgpu::ComputePipeline,
    pub bind_group: wgpu::BindGroup,
    /// The workgroup counts; with [`Dispatch::indirect`] the most it can launch.
    pub workgroups: [u32; 3],
    /// Where the counts are read from at run time instead (`dispatch_workgroups_indirect`:
    /// three u32 at a byte offset of a buffer with INDIRECT usage), for work whose size a
    /// kernel earlier in the step decides.
    pub indirect: Option<IndirectArgs>,
}

/// Three u32 workgroup counts in a buffer made with INDIRECT usage, at `offset` bytes.
#[derive(Debug, Clone)]
pub struct IndirectArgs {
    pub buffer: wgpu::Buffer,
    pub offset: u64,
}

impl Dispatch {
    pub fn new(pipeline: wgpu::ComputePipeline, bind_group: wgpu::BindGroup, workgroups: impl Into<[u32; 3]>) -> Self {
        Dispatch {
            pipeline,
            bind_group,
            workgroups: workgroups.into(),
            indirect: None,
        }
    }

    /// The same dispatch with its workgroup counts read from `args` when it runs.
    pub fn with_indirect(self, args: Option<IndirectArgs>) -> Self {
        Dispatch { indirect: args, ..self }
    }

    /// Compiles `spec`'s pipeline (or takes it from the device's cache) and binds its group 0
    /// by name ([`bind_named`]).
    pub async fn build(
        ctx: &GpuContext,
        spec: &KernelSpec<'_>,
        resources: &[(&str, wgpu::BindingResource<'_>)],
        workgroups: impl Into<[u32; 3]>,
    ) -> Result<Self, GpuError> {
        let pipeline = create_compute_pipeline(ctx, spec).await?;
        let bind_group = bind_named(ctx, spec, &pipeline.get_bind_group_layout(0), 0, resources)?;
        Ok(Dispatch::new(pipeline, bind_group, workgroups))
    }

    /// Whether it launches no workgroup (recording it would be a no-op).
    pub fn is_empty(&self) -> bool {
        self.workgroups.contains(&0)
    }

    pub fn record(&self, pass: &mut wgpu::ComputePass<'_>) {
        pass.set_pipeline(&self.pipeline);
        pass.set_bind_group(0, &self.bind_group, &[]);
        match &self.indirect {
            Some(args) => pass.dispatch_workgroups_indirect(&args.buffer, args.offset),
            None => {
                let [x, y, z] = self.workgroups;
                pass.dispatch_workgroups(x, y, z);
            }
        }
        count_dispatch();
    }
}

impl From<Dispatch1d> for [u32; 3] {
    fn from(d: Dispatch1d) -> [u32; 3] {
        [d.x, d.y, 1]
    }
}

/// The bindings of group `group` that `spec`'s entry point uses, from its shader's table.
pub fn bindings_used(spec: &KernelSpec<'_>, group: u32) -> Result<Vec<&'static ShaderBinding>, GpuError> {
    let table = bindings_of(spec.source).ok_or_else(|| {
        GpuError::invalid_argument(spec.label, "its shader source is none of shaders/ (no binding table)")
    })?;
    Ok(table
        .iter()
        .filter(|b| b.entry_point == spec.entry_point && b.group == group)
        .collect())
}

/// Bind group `group` of `spec`'s entry point from `(WGSL variable name, resource)` pairs: each
/// name must be a binding of that group the entry point uses, and every binding it uses must be
/// given, once. A mismatch is an error naming the kernel and the binding.
pub fn bind_named(
    ctx: &GpuContext,
    spec: &KernelSpec<'_>,
    layout: &wgpu::BindGroupLayout,
    group: u32,
    resources: &[(&str, wgpu::BindingResource<'_>)],
) -> Result<wgpu::BindGroup, GpuError> {
    let used = bindings_used(spec, group)?;
    let what = format!("bind group {group} of {} ({})", spec.label, spec.entry_point);
    let mut entries = Vec::with_capacity(resources.len());
    for (name, resource) in resources {
        let binding = used.iter().find(|b| b.name == *name).ok_or_else(|| {
            let names: Vec<&str> = used.iter().map(|b| b.name).collect();
            GpuError::invalid_argument(&what, format!("`{name}` is not a binding it uses (it uses {names:?})"))
        })?;
        if entries
            .iter()
            .any(|e: &wgpu::BindGroupEntry<'_>| e.binding == binding.binding)
        {
            return Err(GpuError::invalid_argument(&what, format!("`{name}` is given twice")));
        }
        entries.push(wgpu::BindGroupEntry {
            binding: binding.binding,
            resource: resource.clone(),
        });
    }
    if let Some(missing) = used.iter().find(|b| !resources.iter().any(|(name, _)| *name == b.name)) {
        return Err(GpuError::invalid_argument(
            &what,
            format!("`{}` (@binding({})) is not given", missing.name, missing.binding),
        ));
    }
    Ok(ctx.device.create_bind_group(&wgpu::BindGroupDescriptor {
        label: Some(spec.label),
        layout,
        entries: &entries,
    }))
}

/// `(name, whole buffer)` pairs as [`bind_named`] takes them.
pub fn whole<'a>(bindings: &[(&'a str, &'a wgpu::Buffer)]) -> Vec<(&'a str, wgpu::BindingResource<'a>)> {
    bindings
        .iter()
        .map(|&(name, buffer)| (name, buffer.as_entire_binding()))
        .collect()
}
