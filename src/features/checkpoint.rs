//! A weights file of either format the DINO extractors accept: safetensors, or a PyTorch
//! checkpoint as `torch.save` writes it (`.pth`), told apart by content.
use std::io::Read;
use std::path::Path;

use super::FeatureError;
use super::pth::Pth;
use crate::safetensors::SafeTensors;

pub enum Checkpoint {
    SafeTensors(SafeTensors),
    Pth(Pth),
}

impl Checkpoint {
    /// Opens `path`, by content: a zip archive (or a legacy pickle, which [`Pth`] explains it
    /// cannot read) is a PyTorch checkpoint and a JSON header after 8 bytes is safetensors, whatever
    /// the names. Anything else goes to the reader its extension suggests (`.pth`, `.pt`, `.tar`:
    /// PyTorch), whose checks say what is wrong.
    pub fn open(path: &Path) -> Result<Self, FeatureError> {
        let mut head = Vec::with_capacity(9);
        let f = std::fs::File::open(path).map_err(|e| FeatureError::io(path, e))?;
        f.take(9)
            .read_to_end(&mut head)
            .map_err(|e| FeatureError::io(path, e))?;
        let zip_or_pickle = head.starts_with(b"PK\x03\x04") || head.starts_with(&[0x80, 0x02]);
        let safetensors = head.get(8) == Some(&b'{');
        let pytorch_ext = path
            .extension()
            .and_then(|e| e.to_str())
            .is_some_and(|e| matches!(e.to_ascii_lowercase().as_str(), "pth" | "pt" | "tar"));
        if zip_or_pickle || (pytorch_ext && !safetensors) {
            Ok(Checkpoint::Pth(Pth::open(path)?))
        } else {
            Ok(Checkpoint::SafeTensors(SafeTensors::open(path)?))
        }
    }

    /// The file's name, and for a checkpoint where in it the state dict was, for messages.
    pub fn file(&self) -> String {
        match self {
            Checkpoint::SafeTensors(st) => st.file().to_string(),
            Checkpoint::Pth(p) => format!("{} (state dict {})", p.file(), p.location),
        }
    }

    pub fn shape(&self, name: &str) -> Option<&[usize]> {
        match self {
            Checkpoint::SafeTensors(st) => st.info(name).map(|i| &i.shape[..]),
            Checkpoint::Pth(p) => p.shape(name),
        }
    }

    /// The tensor `name` as `f32`, which must have shape `shape`.
    pub fn f32(&self, name: &str, shape: &[usize]) -> Result<Vec<f32>, FeatureError> {
        match self {
            Checkpoint::SafeTensors(st) => Ok(st.f32(name, shape)?),
            Checkpoint::Pth(p) => p.f32(name, shape),
        }
    }

    pub fn names(&self) -> Vec<String> {
        match self {
            Checkpoint::SafeTensors(st) => st.names().map(String::from).collect(),
            Checkpoint::Pth(p) => p.names().map(String::from).collect(),
        }
    }
}
