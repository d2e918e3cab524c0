//! Rendering from any camera: the rays of a [`ViewCamera`] built on the CPU (the twin of
//! `write_ray` in `shaders/ray_batch.wgsl`, for poses and resolutions that are not a scene
//! frame's), and the decoding of rendered ray rows into a [`RenderedFrame`].
//!
//! Samples are placed around a depth guide exactly as in training; a view without measured depth
//! is rendered twice: first with every sample spread over the ray, which gives a rough depth, then
//! with that depth as the guide (NeRF's coarse-to-fine idea with the renderer's own estimate).
use crate::field::reference::sampling::{clip_to_bounds, ray_through_pixel};
use crate::gpu::{GpuContext, GpuError};
use crate::refine::{RefineOptions, argmax_and_confidence, refine_probabilities};
use crate::scene::Guide;

use crate::refine::gpu::RefinePass;
use crate::scene::resample::nearest_source;
use crate::scene::{Bounds, Intrinsics, Pca, Pose, Scene};

use super::rays::{RAY_HITS_BOX, RayGeometry};

/// A pinhole camera to render from (OpenCV axes, camera-to-world pose).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ViewCamera {
    pub intrinsics: Intrinsics,
    pub pose: Pose,
    pub width: u32,
    pub height: u32,
}

impl ViewCamera {
    /// Frame `frame` of `scene` seen at `width × height` (any resolution; intrinsics scaled).
    pub fn of_frame(scene: &Scene, frame: usize, width: u32, height: u32) -> Option<ViewCamera> {
        let pose = scene.frames.get(frame)?.pose;
        Some(ViewCamera {
            intrinsics: scene.intrinsics.scaled((scene.width, scene.height), (width, height)),
            pose,
            width,
            height,
        })
    }

    pub fn pixels(&self) -> usize {
        self.width as usize * self.height as usize
    }
}

/// Where the samples of a view's rays concentrate.
#[derive(Clone, Copy, Debug)]
pub enum DepthGuide<'a> {
    /// Measured z-depth in metres per pixel of the view (0: none), e.g. a frame's depth image.
    Measured(&'a [f32]),
    /// No measurement: estimate it with a first render whose samples spread over each ray.
    Estimate,
}

/// Frame `frame`'s measured depth resampled (nearest pixel centre, `scene::resample`) to `width × height`, in metres,
/// 0 where there is none: the guide for rendering a scene frame at another resolution.
pub fn frame_depth_at(scene: &Scene, frame: usize, width: u32, height: u32) -> Vec<f32> {
    let mut out = Vec::with_capacity(width as usize * height as usize);
    for y in 0..height {
        let sy = nearest_source(y, scene.height, height);
        for x in 0..width {
            let sx = nearest_source(x, scene.width, width);
            out.push(scene.depth_m(frame, sx, sy).unwrap_or(0.0) as f32);
        }
    }
    out
}

/// The ray records of pixels `first .. first + count` of `view` (row-major), the same records
/// `ray_batch.wgsl` writes for a scene frame. `depth`: the guide per view pixel (0: none).
/// `pixel` holds the view pixel index.
pub fn view_rays(
    view: &ViewCamera,
    bounds: &Bounds,
    depth: Option<&[f32]>,
    first: usize,
    count: usize,
) -> Vec<RayGeometry> {
    (first..first + count)
        .map(|p| {
            let (x, y) = ((p % view.width as usize) as f64, (p / view.width as usize) as f64);
            let ray = ray_through_pixel(&view.intrinsics, &view.pose, x, y);
            let clipped = clip_to_bounds(&ray, bounds);
            let (near, far) = clipped.unwrap_or((0.0, 0.0));
            RayGeometry {
                origin: ray.origin,
                z_per_t: ray.z_per_t,
                dir: ray.dir,
                near,
                far,
                depth: depth
                    .and_then(|d| d.get(p).copied())
                    .filter(|d| d.is_finite())
                    .unwrap_or(0.0),
                pixel: p as u32,
                flags: if clipped.is_some() { RAY_HITS_BOX } else { 0 },
            }
        })
        .collect()
}

/// What the field renders for one view, per pixel in row-major order.
#[derive(Clone, Debug, PartialEq)]
pub struct RenderedFrame {
    pub width: u32,
    pub height: u32,
    /// Argmax of the class probabilities.
    pub classes: Vec<u8>,
    /// The largest class probability.
    pub confidence: Vec<f32>,
    /// Softmax of the rendered semantic logits, `C` per pixel; refined in place by
    /// [`RenderedFrame::refine`].
    pub probabilities: Vec<f32>,
    /// Whether `refine` has been applied (classes and confidence then follow the refined
    /// probabilities).
    pub refined: bool,
    pub rgb: Vec<[f32; 3]>,
    /// Rendered z-depth in metres.
    pub depth: Vec<f32>,
    /// The rendered feature f through a 3-component PCA, as colours in [0,1]: the scene's PCA
    /// of its codes when it has one (so rendered and stored features look alike), else a PCA
    /// fitted to this view's own rendered features.
    pub features_pca: Vec<[f32; 3]>,
}

impl RenderedFrame {
    /// Snaps the class map to the edges of `guide` (the frame this was rendered for, at this
    /// resolution), on the CPU: see [`crate::refine`]. Errors name a guide of another size.
    pub fn refine(&mut self, guide: Guide<'_>, options: &RefineOptions) -> Result<(), String> {
        if options.is_off() {
            return Ok(());
        }
        self.check_guide(guide)?;
        let count = self.class_count();
        refine_probabilities(&mut self.probabilities, count, guide, options)?;
        self.take_refined();
        Ok(())
    }

    /// As [`RenderedFrame::refine`], on the GPU (`pass` from [`RefinePass::new`]); the page
    /// uses it so the filter does not hold up its thread.
    pub async fn refine_on_gpu(
        &mut self,
        ctx: &GpuContext,
        pass: &RefinePass,
        guide: Guide<'_>,
        options: &RefineOptions,
    ) -> Result<(), GpuError> {
        if options.is_off() {
            return Ok(());
        }
        self.check_guide(guide)
            .map_err(|e| GpuError::invalid_argument("refine", e))?;
        let count = self.class_count();
        pass.refine(ctx, &mut self.probabilities, count, guide, options).await?;
        self.take_refined();
        Ok(())
    }

    fn class_count(&self) -> usize {
        self.probabilities.len() / self.classes.len().max(1)
    }

    fn check_guide(&self, guide: Guide<'_>) -> Result<(), String> {
        if guide.rgb.dimensions() == (self.width, self.height) {
            return Ok(());
        }
        Err(format!(
            "refine: the guide is {} x {}, the rendered frame {} x {}",
            guide.rgb.width(),
            guide.rgb.height(),
            self.width,
            self.height
        ))
    }

    /// Classes and confidence from the (refined) probabilities.
    fn take_refined(&mut self) {
        (self.classes, self.confidence) = argmax_and_confidence(&self.probabilities, self.class_count());
        self.refined = true;
    }
}

/// Accumulates rendered ray rows (the rendered channels of `composite`'s output rows:
/// rgb, depth, C logits, D features) into a [`RenderedFrame`].
pub struct FrameAssembler {
    frame: RenderedFrame,
    classes: usize,
    feature_dim: usize,
    features: Vec<f32>,
}

impl FrameAssembler {
    pub fn new(width: u32, height: u32, classes: usize, feature_dim: usize) -> Self {
        let pixels = width as usize * height as usize;
        FrameAssembler {
            frame: RenderedFrame {
                width,
                height,
                classes: Vec::new(),
                confidence: Vec::new(),
                probabilities: Vec::with_capacity(pixels * classes),
                refined: false,
                rgb: Vec::with_capacity(pixels),
                depth: Vec::with_capacity(pixels),
                features_pca: Vec::new(),
            },
            classes,
            feature_dim,
            features: Vec::with_capacity(pixels * feature_dim),
        }
    }

    /// Adds one ray's rendered channels.
    pub fn push(&mut self, rendered: &[f32]) {
        let f = &mut self.frame;
        f.rgb.push([rendered[0], rendered[1], rendered[2]]);
        f.depth.push(rendered[3]);
        let logits = &rendered[4..4 + self.classes];
        let top = logits.iter().copied().fold(f32::NEG_INFINITY, f32::max);
        let sum: f32 = logits.iter().map(|&x| (x - top).exp()).sum();
        f.probabilities.extend(logits.iter().map(|&x| (x - top).exp() / sum));
        self.features
            .extend_from_slice(&rendered[4 + self.classes..4 + self.classes + self.feature_dim]);
    }

    pub fn depth(&self) -> &[f32] {
        &self.frame.depth
    }

    /// The class probabilities alone, `C` per pixel.
    pub fn into_probabilities(self) -> Vec<f32> {
        self.frame.probabilities
    }

    /// The finished frame (classes and confidence from the probabilities), its features shown
    /// through `pca` (or a PCA fitted to them).
    pub fn finish(mut self, pca: Option<&Pca>) -> RenderedFrame {
        (self.frame.classes, self.frame.confidence) = argmax_and_confidence(&self.frame.probabilities, self.classes);
        let fitted;
        let pca = match pca.filter(|p| p.mean.len() == self.feature_dim) {
            Some(p) => Some(p),
            None => {
                fitted = Pca::fit(&self.features, self.feature_dim);
                fitted.as_ref()
            }
        };
        self.frame.features_pca = match pca {
            Some(pca) => self
                .features
                .chunks_exact(self.feature_dim.max(1))
                .map(|code| pca.colour(code))
                .collect(),
            None => vec![[0.5; 3]; self.frame.depth.len()],
        };
        self.frame
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::demo::{DemoOptions, demo_scene};

    #[test]
    fn frame_view_at_full_resolution_has_the_frames_rays() {
        let scene = demo_scene(&DemoOptions {
            width: 32,
            height: 24,
            frames: 2,
            ..Default::default()
        })
        .unwrap();
        let view = ViewCamera::of_frame(&scene, 1, 32, 24).unwrap();
        assert_eq!(view.intrinsics, scene.intrinsics);
        let depth = frame_depth_at(&scene, 1, 32, 24);
        for (p, d) in depth.iter().enumerate() {
            let (x, y) = ((p % 32) as u32, (p / 32) as u32);
            assert_eq!(*d, scene.depth_m(1, x, y).unwrap_or(0.0) as f32);
        }
        let rays = view_rays(&view, &scene.bounds, Some(&depth), 5, 40);
        assert_eq!(rays.len(), 40);
        let r = &rays[0];
        let expected = ray_through_pixel(&scene.intrinsics, &scene.frames[1].pose, 5.0, 0.0);
        assert_eq!(r.origin, expected.origin);
        assert_eq!(r.dir, expected.dir);
        assert_eq!(r.pixel, 5);
        assert!(rays.iter().all(|r| r.flags & RAY_HITS_BOX != 0 && r.far > r.near));
    }

    #[test]
    fn half_resolution_guide_samples_the_frame() {
        let scene = demo_scene(&DemoOptions {
            width: 32,
            height: 24,
            frames: 1,
            ..Default::default()
        })
        .unwrap();
        let half = frame_depth_at(&scene, 0, 16, 12);
        assert_eq!(half.len(), 16 * 12);
        // Pixel (x, y) of the half view reads pixel (2x+1, 2y+1) of the frame.
        assert_eq!(half[3 * 16 + 4], scene.depth_m(0, 9, 7).unwrap_or(0.0) as f32);
    }

    #[test]
    fn assembler_decodes_rows() {
        let mut a = FrameAssembler::new(2, 1, 2, 3);
        a.push(&[0.1, 0.2, 0.3, 1.5, 0.0, 2.0, 1.0, 0.0, 0.0]);
        a.push(&[0.4, 0.5, 0.6, 2.5, 3.0, -1.0, 0.0, 1.0, 0.0]);
        let f = a.finish(None);
        assert_eq!(f.classes, vec![1, 0]);
        assert_eq!(f.depth, vec![1.5, 2.5]);
        assert!((f.confidence[0] - 1.0 / (1.0 + (-2.0f32).exp())).abs() < 1e-6);
        assert_eq!(f.features_pca.len(), 2);
        assert!(f.features_pca.iter().flatten().all(|v| (0.0..=1.0).contains(v)));
        assert_eq!(f.probabilities.len(), 4);
        assert!((f.probabilities[1] - f.confidence[0]).abs() < 1e-6);
        assert!((f.probabilities[0] + f.probabilities[1] - 1.0).abs() < 1e-6);
    }

    #[test]
    fn refining_follows_the_guide_and_names_a_guide_of_another_size() {
        // Two pixels, the first a confident class 1, the second a weak class 0 of the same
        // colour and depth right next to it: refining probabilities gives the second the first's
        // class (votes would keep each as it is).
        let mut a = FrameAssembler::new(2, 1, 2, 0);
        a.push(&[0.0, 0.0, 0.0, 1.0, 0.0, 3.0]);
        a.push(&[0.0, 0.0, 0.0, 1.0, 0.2, 0.0]);
        let mut f = a.finish(None);
        assert_eq!(f.classes, vec![1, 0]);
        let rgb = image::RgbImage::from_pixel(2, 1, image::Rgb([90, 90, 90]));
        let probabilities = RefineOptions {
            votes: false,
            ..RefineOptions::default()
        };
        f.refine(Guide::colour_only(&rgb), &probabilities).unwrap();
        assert_eq!(f.classes, vec![1, 1]);
        assert!(f.refined);
        let wrong = image::RgbImage::new(3, 1);
        let err = f
            .refine(Guide::colour_only(&wrong), &RefineOptions::default())
            .unwrap_err();
        assert!(err.contains("3 x 1") && err.contains("2 x 1"), "{err}");
    }
}
