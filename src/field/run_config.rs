//! The one way a run gets the config it trains: a `Preset` (chosen by name, or for the adapter
//! and where the run happens), the user's changes on top, then [`finish`] for the scene and its
//! classes. The command line, the page, the bench and the quality suite all finish their
//! configs here.
use super::config::FieldConfig;
use crate::scene::Scene;

/// A config finished for a scene, and what the user should know about how.
#[derive(Clone, Debug, PartialEq)]
pub struct Finished {
    pub config: FieldConfig,
    /// Changes made because of the scene (no codes to supervise with), for the user.
    pub notes: Vec<String>,
}

/// `cfg` (a preset's config with the user's changes) finished for `scene` and `classes`
/// classes: the class count, and the feature width of the scene's codes, which the rendered
/// feature is compared with. Without codes there is nothing to supervise: supervision goes off,
/// said in a note. Not validated: callers may change more fields first.
pub fn finish(mut cfg: FieldConfig, scene: &Scene, classes: usize) -> Finished {
    let mut notes = Vec::new();
    cfg.num_classes = classes.max(2) as u32;
    match &scene.features {
        Some(codes) => cfg.feature_dim = codes.dim,
        None if cfg.feature_supervision => {
            notes.push("no feature codes; training without feature supervision".to_string());
            cfg.feature_supervision = false;
        }
        None => {}
    }
    Finished { config: cfg, notes }
}

#[cfg(test)]
mod tests {
    use crate::field::{FieldConfig, LastSample};
    use crate::refine::RefineOptions;
    use crate::scene::Scene;
    use crate::scene::demo::{DemoOptions, demo_scene};

    #[test]
    fn photo_captures_get_more_rounds_and_an_opaque_last_sample() {
        let last_sample = |scene: &Scene| FieldConfig::default().for_scene(scene).last_sample;
        let mut scene = demo_scene(&DemoOptions {
            width: 24,
            height: 16,
            frames: 4,
            ..DemoOptions::default()
        })
        .unwrap();
        assert_eq!(RefineOptions::for_scene(&scene), RefineOptions::DEFAULT);
        assert_eq!(last_sample(&scene), LastSample::Clear);
        let forced = FieldConfig {
            last_sample: LastSample::Opaque,
            ..FieldConfig::default()
        };
        assert!(forced.for_scene(&scene).opaque_last_sample());
        // A reconstruction's points: a reading at one pixel in ten, on 3 frames of 4.
        for frame in &mut scene.frames[1..] {
            let depth = frame.depth.as_mut().unwrap();
            for (i, p) in depth.pixels_mut().enumerate() {
                if i % 10 != 0 {
                    p.0[0] = 0;
                }
            }
        }
        let sparse = RefineOptions::for_scene(&scene);
        assert_eq!(last_sample(&scene), LastSample::Opaque);
        assert_eq!(sparse.iterations, RefineOptions::ROUNDS_WITHOUT_DENSE_DEPTH);
        assert_eq!(
            RefineOptions {
                iterations: 3,
                ..sparse
            },
            RefineOptions::DEFAULT
        );
        for frame in &mut scene.frames {
            frame.depth = None;
        }
        assert_eq!(
            RefineOptions::for_scene(&scene).iterations,
            RefineOptions::ROUNDS_WITHOUT_DENSE_DEPTH
        );
        assert_eq!(last_sample(&scene), LastSample::Opaque);
    }
}
