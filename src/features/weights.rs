//! Where a network's weights file is: the flag, else an environment variable, else a default
//! path; one rule for every extractor that needs weights.
use std::ffi::OsString;
use std::path::{Path, PathBuf};

use super::FeatureError;

/// `flag` if given, else `env` if set and not empty (named `env_name`), else `default`
/// (relative to the working directory). Absent: `FeatureError::Missing` naming `what`, where the
/// path came from, and `hint`.
pub(crate) fn resolve_weights_file(
    flag: Option<&Path>,
    env: Option<OsString>,
    env_name: &str,
    default: &str,
    what: &str,
    hint: impl FnOnce() -> String,
) -> Result<PathBuf, FeatureError> {
    let (path, from) = match (flag, env.filter(|v| !v.is_empty())) {
        (Some(p), _) => (p.to_path_buf(), "given".to_string()),
        (None, Some(v)) => (PathBuf::from(v), format!("from {env_name}")),
        (None, None) => (PathBuf::from(default), "the default".to_string()),
    };
    if path.is_file() {
        Ok(path)
    } else {
        Err(FeatureError::Missing {
            what: format!("{what} ({from})"),
            path,
            hint: hint(),
        })
    }
}
