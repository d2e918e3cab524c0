//! Label spreading: before the field trains, the user's strokes become labels over more of each
//! frame (a random walk on the frame's pixels, `pixel_walk`) and, on a capture whose depth is a
//! reconstruction's points, over the frames nobody drew on (`point_walk`, `view_seeds`).
//! `propagate` puts the pieces together per frame; `check` holds part of the strokes back to
//! see whether the spread can be trusted. Nothing here touches the model: the field trains on
//! the maps this layer writes (docs/quality.md has the rules and what each was measured to do).
pub mod box_counts;
pub mod check;
pub mod colour;
pub mod margin;
pub mod normals;
pub mod options;
pub mod pixel_walk;
pub mod point_walk;
pub mod propagate;
pub mod sparse_solve;
pub mod support_plane;
#[cfg(test)]
mod test_scenes;
pub mod view_seeds;

pub use options::{GuardedWalks, PropagationOptions, UndrawnFrames};
pub use propagate::PropagationCache;
