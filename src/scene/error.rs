//! Errors for everything that reads or writes scenes. Every variant names the file (or archive
//! entry) it is about, so a user can find and fix the problem without reading code.
use std::path::PathBuf;

#[derive(Debug, thiserror::Error)]
pub enum SceneError {
    /// A file or archive entry exists but its content is wrong.
    #[error("{file}: {problem}")]
    Invalid { file: String, problem: String },
    /// A file or archive entry that must exist does not.
    #[error("{file}: missing ({what})")]
    Missing { file: String, what: String },
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("{file}: cannot decode image: {source}")]
    Image {
        file: String,
        #[source]
        source: image::ImageError,
    },
    #[error("{file}: not a readable zip archive: {source}")]
    Zip {
        file: String,
        #[source]
        source: zip::result::ZipError,
    },
    #[error("{file}: invalid JSON: {source}")]
    Json {
        file: String,
        #[source]
        source: serde_json::Error,
    },
}

impl SceneError {
    pub fn invalid(file: impl Into<String>, problem: impl Into<String>) -> Self {
        SceneError::Invalid {
            file: file.into(),
            problem: problem.into(),
        }
    }
    pub fn missing(file: impl Into<String>, what: impl Into<String>) -> Self {
        SceneError::Missing {
            file: file.into(),
            what: what.into(),
        }
    }
    pub fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        SceneError::Io {
            path: path.into(),
            source,
        }
    }
}

pub type Result<T, E = SceneError> = std::result::Result<T, E>;
