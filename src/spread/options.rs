//! What a user can set about label spreading (`scribble_propagation` in a field config), and the
//! check of each value.
use serde::{Deserialize, Serialize};

/// How strokes spread inside their frame before training. `enabled: false` trains on the
/// strokes alone.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct PropagationOptions {
    pub enabled: bool,
    /// CIE L*a*b* distance between neighbouring pixels at which the walk's step weight falls to
    /// e^-1/2 (a just-noticeable difference is about 2.3).
    pub colour_sigma: f32,
    /// Relative depth difference, |ln(d / d')|, between neighbours at which the step weight falls
    /// to e^-1/2; neighbours without a depth reading skip the term.
    pub depth_sigma: f32,
    /// Factor on the step weight between a pixel with a depth reading and one without, in a
    /// frame where most pixels have one: dense depth sensors lose depth at occlusion boundaries,
    /// so a hole in dense depth marks where one object ends. Sparse depth (a reconstruction's
    /// keypoints) has holes everywhere and skips this.
    pub depth_hole_factor: f32,
    /// How far a walk goes before it gives up, as a fraction of the image diagonal (through a
    /// uniform region; edges shorten it). Each step ends the walk with a small probability, so a
    /// pixel far from every stroke (the floor, when the only background strokes are on the wall)
    /// is reached by none and stays unlabelled, instead of taking the class of whichever stroke
    /// is least far.
    pub reach: f32,
    /// A pixel becomes a label only where the walk reaches its most likely class with at least
    /// this probability...
    pub min_probability: f32,
    /// ...and that class leads the next by this much.
    pub min_margin: f32,
    /// Turn of the surface normal between neighbours, as 1 - cos(angle), at which the step
    /// weight falls to e^-1 is this squared (0.15: about 12 degrees); 0 leaves normals out. Normals come from dense depth
    /// (`spread::normals`), so a crease where a box stands on a table stops the walk even where
    /// the two surfaces share a colour and a depth.
    pub normal_sigma: f32,
    /// The normal's turn counts only where the surface folds inward between the two pixels (a
    /// concave crease: where an object stands on its support, `spread::normals::folds_outward`);
    /// an outward fold (a box's own edge, a mug's rim) lies on one object, so the walk crosses
    /// it and labels the box's other faces too.
    pub inward_creases_only: bool,
    /// On a capture whose depth is a reconstruction's points (sparse), carry the strokes to
    /// every frame through the points first (`spread::point_walk`): each frame walks from the
    /// labels of the points that land in it and, where the strokes name the class of what the
    /// reconstruction missed, from its pixels far from every point (`spread::view_seeds`).
    /// Captures with dense depth are not affected.
    pub across_views: bool,
    /// What a frame nobody drew on trains on, when labels go across views: `points` (the labels
    /// of the points that land in it and its far pixels, as they are; the field decides the
    /// pixels between) or `walk` (its own walk from those). Its walk has no stroke of its own to
    /// stop it and carries a class wherever the colour lets it: onto what an object stands on,
    /// where the object's points meet it (docs/quality.md).
    pub undrawn_frames: UndrawnFrames,
    /// On a frame nobody drew on, the labels the points carry within this share of the image
    /// diagonal of the edge of their class's footprint (`spread::margin::erode_footprints`) are
    /// left to the field. Such a frame's object is labelled at every point up to its outline,
    /// while what surrounds it is labelled only far from every point: without a margin the field
    /// learns the object's edge on one side only and grows the object (docs/quality.md). 0 keeps
    /// every label.
    pub undrawn_margin: f32,
    /// On a frame with dense depth and strokes of two or more classes, find the largest plane
    /// in its depth (the floor or table the objects stand on, `spread::support_plane`); where
    /// the strokes on it agree on one class, the plane's pixels the walk leaves unlabelled take
    /// that class.
    pub support_plane: bool,
    /// Share of a class's labelled rays that training draws from the strokes themselves, at
    /// least, however far they spread (0: every labelled pixel alike): spread labels weigh less
    /// than drawn ones. At most 0.9.
    pub drawn_share: f32,
    /// Difference of the image feature codes between neighbours, in units of the frame's
    /// root-mean-square neighbour difference, at which the step weight falls to e^-1/2; 0 leaves
    /// features out. Features tell apart objects of one colour that colour alone cannot. Applies
    /// to the walks `guarded_walks` names, as `edge_margin` does.
    pub feature_sigma: f32,
    /// Pixels the walk labels within this share of the image diagonal of a pixel not of their
    /// class (another class's, or one left unlabelled) are dropped (`spread::margin`): where the
    /// walk stopped it may have stopped wrong. Strokes and carried labels are never dropped; 0
    /// keeps every label.
    pub edge_margin: f32,
    /// Which walks follow the feature codes and keep the margin (docs/quality.md, "Walks on
    /// colour alone").
    pub guarded_walks: GuardedWalks,
    /// Before training, hold back part of the strokes, spread from the rest and compare
    /// (`spread::check`); where the spread agrees with the held-back strokes on less than
    /// `min_agreement` of their pixels, train without that spread: without labels across views
    /// when the across-view folds fail, on the strokes alone when the within-frame fold fails.
    pub self_check: bool,
    pub min_agreement: f32,
}

/// Which walks inside a frame follow the feature codes and keep a margin along their edges
/// (`PropagationOptions::feature_sigma`, `edge_margin`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum GuardedWalks {
    /// Every walk.
    Every,
    /// Walks with colour as their only cue among several objects: on a frame without depth,
    /// from strokes of three or more classes. There objects meet other objects, and colour alone
    /// carries one object's class onto its neighbour; with two classes (an object on its
    /// backdrop) or with depth the walk's own labels up to the edges were measured to train
    /// better.
    ColourOnly,
}

impl GuardedWalks {
    /// Whether a walk on a frame (`has_depth`: any depth reading) from strokes of `classes`
    /// classes is guarded.
    pub fn guards(self, has_depth: bool, classes: usize) -> bool {
        match self {
            GuardedWalks::Every => true,
            GuardedWalks::ColourOnly => !has_depth && classes >= 3,
        }
    }
}

/// What labels across views give a frame with no strokes (`PropagationOptions::undrawn_frames`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum UndrawnFrames {
    /// Its points' labels and far pixels, then its own walk from them.
    Walk,
    /// Its points' labels and far pixels as they are.
    Points,
}

impl Default for PropagationOptions {
    fn default() -> Self {
        PropagationOptions {
            enabled: true,
            colour_sigma: 8.0,
            depth_sigma: 0.02,
            depth_hole_factor: 3e-4,
            reach: 0.5,
            min_probability: 0.5,
            min_margin: 0.5,
            normal_sigma: 0.15,
            inward_creases_only: true,
            across_views: true,
            undrawn_frames: UndrawnFrames::Points,
            undrawn_margin: 0.0,
            support_plane: true,
            drawn_share: 0.0,
            feature_sigma: 0.5,
            edge_margin: 0.02,
            guarded_walks: GuardedWalks::ColourOnly,
            self_check: true,
            min_agreement: 0.9,
        }
    }
}

impl PropagationOptions {
    /// A value that cannot work, named by its field.
    pub fn validate(&self) -> Result<(), String> {
        for (name, v) in [
            ("colour_sigma", self.colour_sigma),
            ("depth_sigma", self.depth_sigma),
            ("reach", self.reach),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return Err(format!(
                    "scribble_propagation: `{name}` = {v}: must be a positive number"
                ));
            }
        }
        if !(self.depth_hole_factor.is_finite() && self.depth_hole_factor > 0.0 && self.depth_hole_factor <= 1.0) {
            return Err(format!(
                "scribble_propagation: `depth_hole_factor` = {}: must be in (0, 1]",
                self.depth_hole_factor
            ));
        }
        if !(self.normal_sigma.is_finite() && self.normal_sigma >= 0.0) {
            return Err(format!(
                "scribble_propagation: `normal_sigma` = {}: must be 0 (off) or a positive number",
                self.normal_sigma
            ));
        }
        if !(self.min_agreement.is_finite() && (0.0..=1.0).contains(&self.min_agreement)) {
            return Err(format!(
                "scribble_propagation: `min_agreement` = {}: must be in [0, 1]",
                self.min_agreement
            ));
        }
        if !(self.drawn_share.is_finite() && (0.0..=0.9).contains(&self.drawn_share)) {
            return Err(format!(
                "scribble_propagation: `drawn_share` = {}: must be in [0, 0.9]",
                self.drawn_share
            ));
        }
        if !(self.feature_sigma.is_finite() && self.feature_sigma >= 0.0) {
            return Err(format!(
                "scribble_propagation: `feature_sigma` = {}: must be 0 (off) or a positive number",
                self.feature_sigma
            ));
        }
        for (name, v) in [
            ("edge_margin", self.edge_margin),
            ("undrawn_margin", self.undrawn_margin),
        ] {
            if !(v.is_finite() && (0.0..=0.1).contains(&v)) {
                return Err(format!("scribble_propagation: `{name}` = {v}: must be in [0, 0.1]"));
            }
        }
        for (name, v) in [
            ("min_probability", self.min_probability),
            ("min_margin", self.min_margin),
        ] {
            if !(v.is_finite() && (0.0..=1.0).contains(&v)) {
                return Err(format!("scribble_propagation: `{name}` = {v}: must be in [0, 1]"));
            }
        }
        Ok(())
    }
}
