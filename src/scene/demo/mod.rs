//! The built-in demo scene: a table-top in a room with four kinds of textured objects,
//! rendered by a small CPU ray tracer into RGB-D frames on an orbit, with exact depth, poses
//! and dense ground-truth classes. Deterministic from a seed, so the app and the tests can use
//! it without any dataset.
mod geometry;
mod layout;
mod noise;
mod render;
mod textures;

pub use geometry::{Ray, Shape, SurfaceHit};
pub use layout::{DEMO_CLASS_COLOURS, DEMO_CLASSES, DemoWorld, Part, WorldHit};
pub use render::{HORIZONTAL_FOV_DEGREES, demo_intrinsics, look_at};

use super::archive::limits;
use super::decoded::{Frame, Scene};
use super::error::{Result, SceneError};
use super::manifest::Provenance;
use crate::rng::SplitMix64;
use crate::scene::GT_VOID;
use crate::scene::label_set::ClassInfo;
use glam::DVec3;
use render::{DEPTH_SCALE, Orbit, render_frame};

/// Frame counts accepted; 24 to 60 make a good orbit (enough overlap between neighbouring
/// views, few enough to label and train quickly).
pub const FRAME_RANGE: std::ops::RangeInclusive<u32> = 1..=720;
/// Image side lengths accepted, in pixels.
pub const SIDE_RANGE: std::ops::RangeInclusive<u32> = 16..=2048;

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct DemoOptions {
    /// Jitters object placement, sizes, colours and the orbit; the same seed gives the same
    /// scene, byte for byte, on a given platform (sines and cosines come from the platform's
    /// maths library, so native and wasm builds may differ in a last bit here and there).
    pub seed: u64,
    pub width: u32,
    pub height: u32,
    /// Views on one orbit around the table; 24 to 60 are the intended range.
    pub frames: u32,
}

impl Default for DemoOptions {
    fn default() -> Self {
        DemoOptions {
            seed: 0,
            width: 160,
            height: 120,
            frames: 36,
        }
    }
}

impl DemoOptions {
    /// Checks every option; the error names the option and its value.
    pub fn check(&self) -> Result<()> {
        let bad = |problem: String| Err(SceneError::invalid("demo scene options", problem));
        if !FRAME_RANGE.contains(&self.frames) {
            return bad(format!(
                "frames = {} is outside {}..={} (24 to 60 make a good orbit)",
                self.frames,
                FRAME_RANGE.start(),
                FRAME_RANGE.end()
            ));
        }
        for (name, value) in [("width", self.width), ("height", self.height)] {
            if !SIDE_RANGE.contains(&value) {
                return bad(format!(
                    "{name} = {value} is outside {}..={} pixels",
                    SIDE_RANGE.start(),
                    SIDE_RANGE.end()
                ));
            }
        }
        let pixels = self.width as u64 * self.height as u64 * self.frames as u64;
        if pixels > limits::MAX_TOTAL_PIXELS {
            return bad(format!(
                "{} frames of {} x {} make {pixels} pixels, more than a scene archive may hold ({}); \
                 use fewer frames or a smaller size",
                self.frames,
                self.width,
                self.height,
                limits::MAX_TOTAL_PIXELS
            ));
        }
        Ok(())
    }
}

/// The ground-truth classes of the demo scene, ids as in `DEMO_CLASSES`.
pub fn demo_classes() -> Vec<ClassInfo> {
    DEMO_CLASSES
        .iter()
        .zip(DEMO_CLASS_COLOURS)
        .map(|(name, color)| ClassInfo {
            name: (*name).into(),
            color,
        })
        .collect()
}

/// Renders the demo scene: `DemoWorld::generate(opts.seed)` seen from `opts.frames` cameras.
pub fn demo_scene(opts: &DemoOptions) -> Result<Scene> {
    render_demo(opts, DemoWorld::generate(opts.seed), DVec3::ZERO)
}

/// The demo's table and objects with no room, on a plain `backdrop` colour and without depth,
/// as a NeRF-synthetic capture is: two ground-truth classes, the backdrop (`background`) and
/// everything else (`object`). The cameras and the scene box are the demo's.
pub fn demo_scene_on_backdrop(opts: &DemoOptions, backdrop: [u8; 3]) -> Result<Scene> {
    let colour = DVec3::from_array(backdrop.map(|c| f64::from(c) / 255.0));
    let mut scene = render_demo(opts, DemoWorld::generate(opts.seed).without_room(), colour)?;
    for frame in &mut scene.frames {
        frame.depth = None;
        if let Some(gt) = &mut frame.gt {
            for p in gt.pixels_mut() {
                p.0[0] = u8::from(p.0[0] != GT_VOID);
            }
        }
    }
    scene.classes = vec![
        ClassInfo {
            name: "background".into(),
            color: DEMO_CLASS_COLOURS[0],
        },
        ClassInfo {
            name: "object".into(),
            color: DEMO_CLASS_COLOURS[2],
        },
    ];
    scene.provenance.source = format!(
        "demo scene seed {} on a plain backdrop {backdrop:?}, no depth",
        opts.seed
    );
    Ok(scene)
}

fn render_demo(opts: &DemoOptions, world: DemoWorld, backdrop: DVec3) -> Result<Scene> {
    opts.check()?;
    // The orbit draws from its own stream, so layout changes never move the cameras.
    let orbit = Orbit::new(
        world.look_target(),
        &mut SplitMix64::new(opts.seed ^ 0x0c0f_fee0_0b17_ca11),
    );
    let intrinsics = demo_intrinsics(opts.width, opts.height);
    let render_view = |i: u32| {
        let pose = orbit.pose(i, opts.frames);
        let r = render_frame(&world, &intrinsics, &pose, (opts.width, opts.height), backdrop);
        Frame {
            pose,
            rgb: r.rgb,
            depth: Some(r.depth),
            gt: Some(r.gt),
            source: Some(format!("demo-{i:03}")),
        }
    };
    let frames = render_views(opts.frames, &render_view);
    Ok(Scene {
        width: opts.width,
        height: opts.height,
        intrinsics,
        depth_scale: DEPTH_SCALE,
        bounds: world.bounds(),
        frames,
        classes: demo_classes(),
        features: None,
        labels: None,
        provenance: Provenance {
            source: format!("demo scene seed {}", opts.seed),
            importer: "demo-scene".into(),
            tool: format!("scribblefield {}", env!("CARGO_PKG_VERSION")),
            notes: vec![format!(
                "{} x {} pixels, {} views on an orbit around the table, {} degree horizontal field of view",
                opts.width, opts.height, opts.frames, HORIZONTAL_FOV_DEGREES
            )],
        },
    })
}

/// Renders views `0..count` in order. Views are independent, so natively they are spread over
/// the cores (the result does not depend on how); the browser has no threads to spare.
fn render_views(count: u32, render_view: &(dyn Fn(u32) -> Frame + Sync)) -> Vec<Frame> {
    #[cfg(not(target_arch = "wasm32"))]
    {
        let workers = std::thread::available_parallelism()
            .map_or(1, |n| n.get())
            .min(count as usize);
        if workers > 1 {
            let mut slots: Vec<Option<Frame>> = (0..count).map(|_| None).collect();
            let per_worker = (count as usize).div_ceil(workers);
            std::thread::scope(|scope| {
                for (w, chunk) in slots.chunks_mut(per_worker).enumerate() {
                    scope.spawn(move || {
                        for (j, slot) in chunk.iter_mut().enumerate() {
                            *slot = Some(render_view((w * per_worker + j) as u32));
                        }
                    });
                }
            });
            return slots
                .into_iter()
                .map(|f| f.expect("every worker fills its views"))
                .collect();
        }
    }
    (0..count).map(render_view).collect()
}
