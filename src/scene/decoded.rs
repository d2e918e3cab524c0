//! The decoded scene every other part of the crate works with.
use half::f16;
use image::{GrayImage, ImageBuffer, Luma, RgbImage};

use super::camera::{Bounds, Intrinsics, Pose};
use super::label_set::{ClassInfo, LabelSet};
use super::manifest::{Pca, Provenance};
use super::private_paths::scrub;

/// Depth in units of `Scene::depth_scale` metres; 0 = no reading.
pub type DepthImage = ImageBuffer<Luma<u16>, Vec<u16>>;

/// Ground-truth value meaning "no class" (ignored by evaluation).
pub const GT_VOID: u8 = 255;

#[derive(Clone, Debug, PartialEq)]
pub struct Frame {
    /// Camera-to-world, OpenCV camera axes.
    pub pose: Pose,
    pub rgb: RgbImage,
    pub depth: Option<DepthImage>,
    /// Dense class ids, `GT_VOID` = void.
    pub gt: Option<GrayImage>,
    /// Name of the frame in the capture it came from.
    pub source: Option<String>,
}

/// Per-frame feature codes on a `height x width` grid of `dim` values, frames back to back.
#[derive(Clone, Debug, PartialEq)]
pub struct FeatureCodes {
    pub height: u32,
    pub width: u32,
    pub dim: u32,
    pub extractor: String,
    pub data: Vec<f16>,
    pub pca: Pca,
}

impl FeatureCodes {
    pub fn values_per_frame(&self) -> usize {
        self.height as usize * self.width as usize * self.dim as usize
    }

    pub fn frame(&self, i: usize) -> &[f16] {
        let n = self.values_per_frame();
        &self.data[i * n..(i + 1) * n]
    }
}

#[derive(Clone, Debug, PartialEq)]
pub struct Scene {
    pub width: u32,
    pub height: u32,
    pub intrinsics: Intrinsics,
    /// Metres per depth unit.
    pub depth_scale: f64,
    pub bounds: Bounds,
    pub frames: Vec<Frame>,
    pub classes: Vec<ClassInfo>,
    pub features: Option<FeatureCodes>,
    pub labels: Option<LabelSet>,
    pub provenance: Provenance,
}

impl Scene {
    /// Whether most frames lack dense depth: no depth at all, or a reconstruction's sparse
    /// points ([`Scene::has_sparse_depth`]). Such a capture's field trains without surfaces to
    /// follow, which the refinement's rounds (`RefineOptions::for_scene`) and what rays render
    /// behind their last sample (`FieldConfig::for_scene`) both depend on.
    pub fn lacks_dense_depth(&self) -> bool {
        self.frames.iter().all(|f| f.depth.is_none()) || self.has_sparse_depth()
    }

    /// True when most frames with depth have readings at fewer than half their pixels: the
    /// depth of a reconstruction's points, not of a sensor.
    pub fn has_sparse_depth(&self) -> bool {
        let mut sparse = 0;
        let mut with_depth = 0;
        for depth in self.frames.iter().filter_map(|f| f.depth.as_ref()) {
            with_depth += 1;
            let readings = depth.pixels().filter(|p| p.0[0] > 0).count();
            if readings * 2 < depth.len() {
                sparse += 1;
            }
        }
        with_depth > 0 && sparse * 2 > with_depth
    }

    pub fn has_depth(&self) -> bool {
        self.frames.iter().any(|f| f.depth.is_some())
    }

    pub fn has_gt(&self) -> bool {
        self.frames.iter().any(|f| f.gt.is_some())
    }

    /// Depth in metres at pixel (x, y) of frame `i`, or None where there is no reading.
    pub fn depth_m(&self, i: usize, x: u32, y: u32) -> Option<f64> {
        let d = self.frames.get(i)?.depth.as_ref()?.get_pixel_checked(x, y)?.0[0];
        (d != 0).then_some(d as f64 * self.depth_scale)
    }

    /// A human-readable summary (what `scribblefield info` prints).
    pub fn summary(&self) -> String {
        use std::fmt::Write;
        let mut s = String::new();
        let k = &self.intrinsics;
        let b = &self.bounds;
        let yes = |v: bool| if v { "yes" } else { "no" };
        let _ = writeln!(s, "frames:      {}", self.frames.len());
        let _ = writeln!(s, "image size:  {} x {}", self.width, self.height);
        let _ = writeln!(
            s,
            "intrinsics:  fx {:.3} fy {:.3} cx {:.3} cy {:.3}",
            k.fx, k.fy, k.cx, k.cy
        );
        let _ = writeln!(
            s,
            "bounds (m):  [{:.3}, {:.3}, {:.3}] .. [{:.3}, {:.3}, {:.3}]",
            b.min[0], b.min[1], b.min[2], b.max[0], b.max[1], b.max[2]
        );
        let depth_frames = self.frames.iter().filter(|f| f.depth.is_some()).count();
        let _ = writeln!(
            s,
            "depth:       {} ({} of {} frames)",
            yes(depth_frames > 0),
            depth_frames,
            self.frames.len()
        );
        match &self.features {
            Some(f) => {
                let _ = writeln!(
                    s,
                    "features:    yes ({} x {} x {}, {})",
                    f.width,
                    f.height,
                    f.dim,
                    scrub(&f.extractor, None)
                );
            }
            None => {
                let _ = writeln!(s, "features:    no");
            }
        }
        let gt_frames = self.frames.iter().filter(|f| f.gt.is_some()).count();
        let _ = writeln!(s, "ground truth: {} ({} frames)", yes(gt_frames > 0), gt_frames);
        match &self.labels {
            Some(l) => {
                let strokes: usize = l.frames.iter().map(|f| f.strokes.len()).sum();
                let _ = writeln!(s, "labels:      yes ({} strokes on {} frames)", strokes, l.frames.len());
            }
            None => {
                let _ = writeln!(s, "labels:      no");
            }
        }
        if self.classes.is_empty() {
            let _ = writeln!(s, "classes:     unknown");
        } else {
            let names: Vec<String> = self
                .classes
                .iter()
                .enumerate()
                .map(|(i, c)| format!("{i}:{}", c.name))
                .collect();
            let _ = writeln!(s, "classes:     {}", names.join(", "));
        }
        if !self.provenance.source.is_empty() || !self.provenance.importer.is_empty() {
            // Archives packed before provenance was made relative may hold absolute paths.
            let _ = writeln!(
                s,
                "provenance:  {} ({})",
                scrub(&self.provenance.source, None),
                self.provenance.importer
            );
        }
        for n in &self.provenance.notes {
            let _ = writeln!(s, "note:        {}", scrub(n, None));
        }
        s
    }
}
