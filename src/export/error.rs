//! What can stop an export. Each variant names the frame, class, file or option it is about.
use crate::scene::error::SceneError;

#[derive(Debug, thiserror::Error)]
pub enum ExportError {
    /// Writing a file (or reading one back).
    #[error(transparent)]
    Scene(#[from] SceneError),
    #[error("{file}: mask is {got_width} x {got_height}, the first was {width} x {height}")]
    MaskSize {
        file: String,
        got_width: u32,
        got_height: u32,
        width: u32,
        height: u32,
    },
    #[error("frame {frame}: class id {id} at pixel ({x}, {y}) is not one of the {classes} classes")]
    UnknownClass {
        frame: usize,
        id: u8,
        x: u32,
        y: u32,
        classes: usize,
    },
    #[error("{count} masks for a scene of {frames} frames")]
    FrameCount { count: usize, frames: usize },
    #[error("objects per class (--objects): {0} keeps no region of any class but the first; give at least 1")]
    NoObjects(u32),
    #[error("point cloud (.ply): no frame of the scene has depth")]
    NoDepth,
    #[error("point cloud (.ply): needs the scene the masks are of (its depth, poses and intrinsics)")]
    NoScene,
    #[error("animation (.apng): needs the scene the masks are of (its frames' colour)")]
    NoFrames,
    #[error(
        "CVAT / PASCAL VOC: classes {first:?} and {second:?} share the colour {color:?}, and the layout tells classes apart by colour; give one of them another colour"
    )]
    SharedColour {
        first: String,
        second: String,
        color: [u8; 3],
    },
    #[error("CVAT / PASCAL VOC: class name {name:?} cannot be written to labelmap.txt ({problem}); rename the class")]
    LabelmapName { name: String, problem: &'static str },
    #[error("{at}: compressed RLE: {problem}")]
    Rle { at: String, problem: String },
}
