//! The manifest of an exported mask set (`classes.json`: its format, size, classes and files),
//! in a file of its own so that the writer and the mask set's readers both import it.
use serde::{Deserialize, Serialize};

use crate::labels::ClassInfo;

pub const MASKS_FORMAT: &str = "scribblefield-masks";
pub const MASKS_VERSION: u32 = 1;

/// What `classes.json` holds.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct MasksManifest {
    pub format: String,
    pub version: u32,
    pub frames: u32,
    pub width: u32,
    pub height: u32,
    pub classes: Vec<ClassInfo>,
    /// File of frame i is `files[i]`; previews are under `preview/` with the same names.
    pub files: Vec<String>,
    /// The same masks named after the frames in their capture: frame i's is `by_name[i]`
    /// (under `by-name/`). Empty when the export was made without the scene.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub by_name: Vec<String>,
    /// The masks keep only this many largest regions of each class but the first.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub objects: Option<u32>,
}
