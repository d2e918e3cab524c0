//! Errors of feature extraction. Each names the file (weights, .npy) or the frame it is about.
use std::path::PathBuf;

#[derive(Debug, thiserror::Error)]
pub enum FeatureError {
    /// A file exists but its content is wrong (a weights file, an imported `.npy`).
    #[error("{file}: {problem}")]
    Invalid { file: String, problem: String },
    /// Something that must exist does not; `hint` says where to get it.
    #[error("{what} not found at {path}: {hint}")]
    Missing { what: String, path: PathBuf, hint: String },
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// A frame the extractor cannot handle (e.g. too small), by index.
    #[error("frame {frame}: {problem}")]
    Frame { frame: usize, problem: String },
}

#[cfg(not(target_arch = "wasm32"))]
impl From<crate::safetensors::SafeTensorsError> for FeatureError {
    fn from(e: crate::safetensors::SafeTensorsError) -> Self {
        use crate::safetensors::SafeTensorsError;
        match e {
            SafeTensorsError::Invalid { file, problem } => FeatureError::Invalid { file, problem },
            SafeTensorsError::Io { path, source } => FeatureError::Io { path, source },
        }
    }
}

impl FeatureError {
    pub fn invalid(file: impl Into<String>, problem: impl Into<String>) -> Self {
        FeatureError::Invalid {
            file: file.into(),
            problem: problem.into(),
        }
    }
    /// The error with frame index `frame` filled in: extractors see one image and do not know
    /// which frame of the scene it is.
    pub fn at_frame(self, frame: usize) -> Self {
        match self {
            FeatureError::Frame { problem, .. } => FeatureError::Frame { frame, problem },
            e => e,
        }
    }
    pub fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        FeatureError::Io {
            path: path.into(),
            source,
        }
    }
}
