//! The scene on the GPU, uploaded once: every frame's colour, depth, pose and feature codes, the
//! camera and box, and the labelled pixels grouped by class (re-uploaded when labels change).
//!
//! Layouts (what `shaders/ray_batch.wgsl` reads):
//! - colour: one RGBA8 word per pixel (r in the low byte), frames back to back;
//! - depth: the archive's u16 values two to a word (even pixel in the low half), 0 = no reading
//!   (frames without depth are all 0). Half the memory of f32 metres; the kernel multiplies by
//!   `depth_scale`;
//! - poses: camera-to-world as three `vec4`s per frame, rows `[r0 r1 r2 t]`;
//! - features: the archive's f16 codes two to a word, `[frame][row][column][dim]`;
//! - labels: [`LabelIndex::to_words`].
//!
//! Pixels are named by one global index `frame · width · height + y · width + x` (u32: archives
//! hold at most 2^29 pixels). Each buffer must fit one storage binding of the device; a scene
//! that does not fails with [`GpuError::LimitExceeded`] naming the buffer and the scene's size.
use crate::field::config::FieldConfig;
use crate::gpu::buffers::{STORAGE_USAGE, storage_buffer_from};
use crate::gpu::{GpuContext, GpuError};
use crate::labels::{LabelSet, rasterize_frame};
use crate::scene::Scene;

/// Uniform block mirrored by `SceneUniforms` in `shaders/ray_batch.wgsl` (80 bytes).
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct SceneUniforms {
    pub width: u32,
    pub height: u32,
    pub frame_count: u32,
    pub pixels_per_frame: u32,
    pub total_pixels: u32,
    pub feature_height: u32,
    pub feature_width: u32,
    /// The config's D: the length of every ray's code row (zeros without features).
    pub feature_dim: u32,
    pub fx: f32,
    pub fy: f32,
    pub cx: f32,
    pub cy: f32,
    pub bounds_min: [f32; 3],
    /// Metres per depth unit.
    pub depth_scale: f32,
    pub bounds_max: [f32; 3],
    /// 1 when the scene carries feature codes.
    pub has_features: u32,
}

/// Labelled pixels grouped by class: the CPU side of the labels buffer, and what the CPU twin of
/// the ray picker draws from.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct LabelIndex {
    /// Global pixel indices per class id, ascending.
    pub pixels_by_class: Vec<Vec<u32>>,
}

impl LabelIndex {
    /// Rasterizes every labelled frame (`labels::rasterize_frame`; later strokes win, erasers
    /// clear) of a scene of `frame_count` frames of `width` x `height`. Class ids at or above
    /// `num_classes`, and frames beyond the scene, are left out: the model has no logit for them.
    pub fn from_labels(labels: Option<&LabelSet>, frame_count: u32, width: u32, height: u32, num_classes: u32) -> Self {
        let maps: Vec<(u32, Vec<u16>)> = labels
            .map(|labels| {
                labels
                    .frames
                    .iter()
                    .map(|f| (f.frame, rasterize_frame(labels.frame(f.frame), width, height)))
                    .collect()
            })
            .unwrap_or_default();
        Self::from_maps(&maps, frame_count, width, height, num_classes)
    }

    /// The index of per-frame label maps (`frame`, one class id per pixel of a `width x height`
    /// frame, `UNLABELLED` elsewhere), such as `spread::propagate` makes. Class ids at or above
    /// `num_classes`, and frames at or beyond `frame_count`, are left out.
    pub fn from_maps(maps: &[(u32, Vec<u16>)], frame_count: u32, width: u32, height: u32, num_classes: u32) -> Self {
        let mut pixels_by_class = vec![Vec::new(); num_classes as usize];
        let mut sorted: Vec<&(u32, Vec<u16>)> = maps.iter().filter(|(f, _)| *f < frame_count).collect();
        sorted.sort_by_key(|(f, _)| *f);
        sorted.dedup_by_key(|(f, _)| *f);
        let pixels_per_frame = width * height;
        for (frame, map) in sorted {
            for (index, class) in map.iter().take(pixels_per_frame as usize).enumerate() {
                if let Some(list) = pixels_by_class.get_mut(*class as usize) {
                    list.push(frame * pixels_per_frame + index as u32);
                }
            }
        }
        LabelIndex { pixels_by_class }
    }

    /// Repeats the pixels of `drawn` (the strokes themselves, a subset of this index) in their
    /// class's list until they make up at least `share` of it, so that a labelled ray drawn
    /// from a class lands on a stroke at least that often however far the strokes spread
    /// (`PropagationOptions::drawn_share`). `share` 0 leaves the index as it is.
    pub fn weight_drawn(&mut self, drawn: &LabelIndex, share: f32) {
        if share <= 0.0 {
            return;
        }
        let share = f64::from(share.min(0.9));
        for (list, strokes) in self.pixels_by_class.iter_mut().zip(&drawn.pixels_by_class) {
            let (d, total) = (strokes.len(), list.len());
            if d == 0 || total <= d {
                continue;
            }
            let spread = (total - d) as f64;
            let copies = (share * spread / ((1.0 - share) * d as f64)).ceil() as usize;
            for _ in 1..copies {
                list.extend_from_slice(strokes);
            }
            list.sort_unstable();
        }
    }

    /// Class ids with at least one labelled pixel, ascending: the classes a labelled ray draws
    /// from (uniformly).
    pub fn present_classes(&self) -> Vec<u32> {
        (0..self.pixels_by_class.len() as u32)
            .filter(|c| !self.pixels_by_class[*c as usize].is_empty())
            .collect()
    }

    pub fn labelled_pixel_count(&self) -> usize {
        self.pixels_by_class.iter().map(Vec::len).sum()
    }

    /// The buffer's words: `[K, (class, start, count) × K, pixels…]` with K present classes and
    /// `start` the word index of the class's first pixel.
    pub fn to_words(&self) -> Vec<u32> {
        let present = self.present_classes();
        let header = 1 + 3 * present.len();
        let mut words = Vec::with_capacity(header + self.labelled_pixel_count());
        words.push(present.len() as u32);
        let mut start = header as u32;
        for class in &present {
            let count = self.pixels_by_class[*class as usize].len() as u32;
            words.extend([*class, start, count]);
            start += count;
        }
        for class in &present {
            words.extend_from_slice(&self.pixels_by_class[*class as usize]);
        }
        words
    }
}

/// The uploaded scene. Bind the buffers whole; `labels` may be replaced by
/// [`SceneBuffers::upload_labels`] (watch [`SceneBuffers::labels_generation`]).
pub struct SceneBuffers {
    pub info: SceneUniforms,
    pub uniforms: wgpu::Buffer,
    pub rgb: wgpu::Buffer,
    pub depth: wgpu::Buffer,
    pub poses: wgpu::Buffer,
    pub features: wgpu::Buffer,
    pub labels: wgpu::Buffer,
    labels_generation: u64,
}

impl SceneBuffers {
    /// Uploads `scene` for a model with `cfg` (its feature_dim must match the scene's codes) and
    /// the scene's own labels, if any.
    pub fn upload(ctx: &GpuContext, scene: &Scene, cfg: &FieldConfig) -> Result<Self, GpuError> {
        let info = scene_uniforms(scene, cfg)?;
        let frames = scene.frames.len();
        let size = format!("{frames} frames of {} x {}", scene.width, scene.height);
        let pixels = info.total_pixels as usize;

        let mut rgb_words = Vec::with_capacity(pixels);
        for frame in &scene.frames {
            rgb_words.extend(
                frame
                    .rgb
                    .pixels()
                    .map(|p| u32::from_le_bytes([p.0[0], p.0[1], p.0[2], 255])),
            );
        }
        let mut depth_units = Vec::with_capacity(pixels + 1);
        for frame in &scene.frames {
            match &frame.depth {
                Some(depth) => depth_units.extend(depth.pixels().map(|p| p.0[0])),
                None => depth_units.resize(depth_units.len() + info.pixels_per_frame as usize, 0),
            }
        }
        let poses: Vec<f32> = scene
            .frames
            .iter()
            .flat_map(|frame| {
                let m = frame.pose.to_row_major();
                m[..12].iter().map(|v| *v as f32).collect::<Vec<_>>()
            })
            .collect();
        let feature_words = match &scene.features {
            Some(codes) => pack_u16_pairs(bytemuck::cast_slice(&codes.data)),
            None => vec![0],
        };

        let rgb = storage_buffer_from(ctx, &format!("scene colour ({size}, 4 bytes a pixel)"), &rgb_words)?;
        let depth = storage_buffer_from(
            ctx,
            &format!("scene depth ({size}, 2 bytes a pixel)"),
            &pack_u16_pairs(&depth_units),
        )?;
        let poses = storage_buffer_from(ctx, &format!("scene poses ({frames} frames)"), &poses)?;
        // Past the binding limit, what the user can change is how the archive was packed.
        let codes = scene.features.as_ref().map_or_else(String::new, |c| {
            format!(
                "{frames} frames of {} x {} cells x {} values; pack it with fewer feature cells (--feature-stride) or a smaller longest side (--max-size)",
                c.width, c.height, c.dim
            )
        });
        let features = storage_buffer_from(ctx, &format!("scene feature codes ({codes})"), &feature_words)?;
        let label_index = LabelIndex::from_labels(
            scene.labels.as_ref(),
            scene.frames.len() as u32,
            scene.width,
            scene.height,
            cfg.num_classes,
        );
        let labels = labels_buffer(ctx, &label_index.to_words())?;
        let uniforms = crate::gpu::buffers::uniform_buffer_from(ctx, "scene uniforms", &info);
        Ok(SceneBuffers {
            info,
            uniforms,
            rgb,
            depth,
            poses,
            features,
            labels,
            labels_generation: 0,
        })
    }

    /// Replaces the labelled pixels (after the user draws or erases). Writes in place when the
    /// new list fits the buffer; otherwise makes a larger buffer and bumps
    /// [`SceneBuffers::labels_generation`], so passes bound to the old one must rebind.
    pub fn upload_labels(&mut self, ctx: &GpuContext, index: &LabelIndex) -> Result<(), GpuError> {
        let words = index.to_words();
        let bytes = (words.len() * 4) as u64;
        if bytes <= self.labels.size() {
            ctx.queue.write_buffer(&self.labels, 0, bytemuck::cast_slice(&words));
            return Ok(());
        }
        self.labels = labels_buffer(ctx, &words)?;
        self.labels_generation += 1;
        Ok(())
    }

    /// Counts replacements of the labels buffer.
    pub fn labels_generation(&self) -> u64 {
        self.labels_generation
    }
}

/// A labels buffer with room to grow: twice what is needed, at least 64 Ki words, so a user
/// drawing stroke after stroke rarely forces a new buffer (and a rebind).
fn labels_buffer(ctx: &GpuContext, words: &[u32]) -> Result<wgpu::Buffer, GpuError> {
    let wanted = (words.len() * 2).max(1 << 16) as u64 * 4;
    let needed = words.len() as u64 * 4;
    let allowed = ctx
        .limits
        .max_storage_buffer_binding_size
        .min(ctx.limits.max_buffer_size);
    let size = wanted.min(allowed).max(needed);
    ctx.ensure_storage_binding_fits(&format!("labelled pixels ({} words)", words.len()), size)?;
    let buffer = ctx.device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("labelled pixels"),
        size,
        usage: STORAGE_USAGE,
        mapped_at_creation: false,
    });
    ctx.queue.write_buffer(&buffer, 0, bytemuck::cast_slice(words));
    Ok(buffer)
}

fn pack_u16_pairs(values: &[u16]) -> Vec<u32> {
    values
        .chunks(2)
        .map(|pair| u32::from(pair[0]) | (u32::from(pair.get(1).copied().unwrap_or(0)) << 16))
        .collect()
}

/// The scene's facts as the ray kernel sees them; fails on scenes it cannot index.
pub fn scene_uniforms(scene: &Scene, cfg: &FieldConfig) -> Result<SceneUniforms, GpuError> {
    let what = "scene upload";
    if scene.frames.is_empty() || scene.width == 0 || scene.height == 0 {
        return Err(GpuError::invalid_argument(
            what,
            format!(
                "{} frames of {} x {}: nothing to train on",
                scene.frames.len(),
                scene.width,
                scene.height
            ),
        ));
    }
    for (index, frame) in scene.frames.iter().enumerate() {
        let depth_size = frame.depth.as_ref().map(|d| d.dimensions());
        if frame.rgb.dimensions() != (scene.width, scene.height)
            || depth_size.is_some_and(|size| size != (scene.width, scene.height))
        {
            return Err(GpuError::invalid_argument(
                what,
                format!("frame {index} is not {} x {} like the scene", scene.width, scene.height),
            ));
        }
    }
    let pixels_per_frame = u64::from(scene.width) * u64::from(scene.height);
    let total = pixels_per_frame * scene.frames.len() as u64;
    if total > u64::from(u32::MAX) {
        return Err(GpuError::invalid_argument(
            what,
            format!("{total} pixels in all frames exceed the 2^32 a global pixel index can name"),
        ));
    }
    let (feature_height, feature_width, has_features) = match &scene.features {
        Some(codes) => {
            if codes.dim != cfg.feature_dim {
                return Err(GpuError::invalid_argument(
                    what,
                    format!(
                        "the scene's feature codes have {} dims but the model's feature_dim is {}",
                        codes.dim, cfg.feature_dim
                    ),
                ));
            }
            if codes.height == 0 || codes.width == 0 {
                return Err(GpuError::invalid_argument(what, "the feature grid is empty"));
            }
            (codes.height, codes.width, 1)
        }
        None => (1, 1, 0),
    };
    let k = &scene.intrinsics;
    let b = &scene.bounds;
    Ok(SceneUniforms {
        width: scene.width,
        height: scene.height,
        frame_count: scene.frames.len() as u32,
        pixels_per_frame: pixels_per_frame as u32,
        total_pixels: total as u32,
        feature_height,
        feature_width,
        feature_dim: cfg.feature_dim,
        fx: k.fx as f32,
        fy: k.fy as f32,
        cx: k.cx as f32,
        cy: k.cy as f32,
        bounds_min: b.min.map(|v| v as f32),
        depth_scale: scene.depth_scale as f32,
        bounds_max: b.max.map(|v| v as f32),
        has_features,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::labels::UNLABELLED;

    #[test]
    fn drawn_pixels_are_repeated_to_their_share_of_the_class() {
        let u = UNLABELLED;
        // Frame 0 of 8 pixels: class 0 drawn at 0, spread to 1..=6; class 1 drawn at 7 only.
        let maps = vec![(0, vec![0, 0, 0, 0, 0, 0, 0, 1])];
        let drawn_maps = vec![(0, vec![0, u, u, u, u, u, u, 1])];
        let mut index = LabelIndex::from_maps(&maps, 1, 8, 1, 2);
        let drawn = LabelIndex::from_maps(&drawn_maps, 1, 8, 1, 2);
        index.weight_drawn(&drawn, 0.5);
        // Six spread pixels: the stroke's pixel six times, in ascending order.
        assert_eq!(index.pixels_by_class[0], vec![0, 0, 0, 0, 0, 0, 1, 2, 3, 4, 5, 6]);
        assert_eq!(index.pixels_by_class[1], vec![7]);
        let unweighted = LabelIndex::from_maps(&maps, 1, 8, 1, 2);
        let mut same = unweighted.clone();
        same.weight_drawn(&drawn, 0.0);
        assert_eq!(same, unweighted);
    }
}
