//! The field's walks pause through [`crate::pause`]; it lives with the basics since the
//! importers and the feature baker (layers below and beside the field) pause the same way when
//! the page packs a capture. Re-exported here so the field's paths stay as they were.
pub use crate::pause::{CountPauses, NoPause, Pause, run_to_end};
