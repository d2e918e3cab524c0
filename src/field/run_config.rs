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
