//! The labels a trainer draws rays from: the user's strokes spread (`spread`) after the
//! self-check, uploaded as the label index, and what training reports about them.
use super::Trainer;
use crate::field::gpu::scene_buffers::LabelIndex;
use crate::gpu::GpuError;
use crate::labels::LabelSet;
use crate::pause::{NoPause, Pause, run_to_end};
use crate::scene::Scene;
use crate::spread::check::{SpreadCheck, check_spread};

impl Trainer {
    /// Replaces the labels training draws from (after the user draws, erases or undoes): each
    /// annotated frame of `scene` (the scene this trainer was made for) with its strokes spread
    /// as `FieldConfig::scribble_propagation` says (`spread::propagate`).
    pub fn set_labels(&mut self, labels: Option<&LabelSet>, scene: &Scene) -> Result<(), GpuError> {
        run_to_end(self.set_labels_pausing(labels, scene, &mut NoPause))
    }

    /// [`Trainer::set_labels`], pausing between iterations of the walks that spread the strokes
    /// (the page's thread also draws: `pause`).
    pub async fn set_labels_pausing(
        &mut self,
        labels: Option<&LabelSet>,
        scene: &Scene,
        pause: &mut impl Pause,
    ) -> Result<(), GpuError> {
        let classes = self.cfg.num_classes as usize;
        let asked = self.cfg.scribble_propagation;
        self.spread_check = None;
        let maps = match labels {
            Some(labels) => {
                let options = if asked.enabled && asked.self_check {
                    let check = check_spread(&mut self.propagation, scene, labels, classes, &asked, pause).await;
                    self.spread_check = Some(check);
                    check.apply(&asked)
                } else {
                    asked
                };
                self.propagation
                    .maps_pausing(scene, labels, classes, &options, pause)
                    .await
            }
            None => Vec::new(),
        };
        // What the strokes say lies beyond the scene box: labelled rays that end in an opaque
        // sample pass through the box with that class and stop in it with any other
        // (`LossWeights::opacity`).
        let far_class = match labels {
            Some(_) => self.propagation.far_class().map(u32::from),
            None => None,
        };
        let drawn = match labels {
            Some(labels) if self.cfg.scribble_propagation.drawn_share > 0.0 => Some(LabelIndex::from_labels(
                Some(labels),
                scene.frames.len() as u32,
                scene.width,
                scene.height,
                self.cfg.num_classes,
            )),
            _ => None,
        };
        self.use_label_maps(maps, far_class, drawn.as_ref(), scene)
    }

    /// Trains on `maps` (per frame, a class per pixel or `UNLABELLED`) exactly as given, with no
    /// spreading and no class beyond the scene box: for measurements that train on known
    /// labels (the quality suite's ceiling, the true masks of every frame).
    pub fn set_label_maps(&mut self, maps: Vec<(u32, Vec<u16>)>, scene: &Scene) -> Result<(), GpuError> {
        self.use_label_maps(maps, None, None, scene)
    }

    fn use_label_maps(
        &mut self,
        maps: Vec<(u32, Vec<u16>)>,
        far_class: Option<u32>,
        drawn: Option<&LabelIndex>,
        scene: &Scene,
    ) -> Result<(), GpuError> {
        let mut index = LabelIndex::from_maps(
            &maps,
            scene.frames.len() as u32,
            scene.width,
            scene.height,
            self.cfg.num_classes,
        );
        self.composite.set_far_class(&self.ctx, far_class);
        self.labelled_pixels = index.labelled_pixel_count();
        if let Some(drawn) = drawn {
            index.weight_drawn(drawn, self.cfg.scribble_propagation.drawn_share);
        }
        self.labelled_frames = maps
            .iter()
            .filter(|(_, map)| map.iter().any(|&c| c != crate::labels::UNLABELLED))
            .count();
        self.label_maps = maps;
        self.scene.upload_labels(&self.ctx, &index)?;
        self.ray_batch.follow_labels(&self.ctx, &self.scene);
        Ok(())
    }

    /// What the spread's self-check found for the current labels (`spread::check`);
    /// None without labels, with spreading off or with the check off.
    pub fn spread_check(&self) -> Option<SpreadCheck> {
        self.spread_check
    }

    /// Whether the current labels train with less spreading than the config asks, because the
    /// self-check failed.
    pub fn spread_withheld(&self) -> bool {
        self.spread_check
            .is_some_and(|c| c.apply(&self.cfg.scribble_propagation) != self.cfg.scribble_propagation)
    }

    /// The label maps training draws from, by frame: the strokes and what they spread to.
    pub fn label_maps(&self) -> &[(u32, Vec<u16>)] {
        &self.label_maps
    }

    /// The class whose labelled rays the opacity term pulls through the scene box (what lies
    /// beyond it), while rays of the other classes must stop inside it; `None` when the term
    /// does not apply: rays without an opaque last sample, a weight of 0, or labels that name no
    /// class for the pixels far from every point (`PropagationCache::far_class`).
    pub fn opacity_far_class(&self) -> Option<u32> {
        self.composite
            .far_class()
            .filter(|_| self.cfg.opaque_last_sample() && self.cfg.loss.opacity > 0.0)
    }

    /// Pixels training draws labels from: the current strokes, spread inside their frames (and,
    /// on a capture with sparse depth, to the other frames)
    /// (`FieldConfig::scribble_propagation`).
    pub fn labelled_pixels(&self) -> usize {
        self.labelled_pixels
    }

    /// Frames holding the pixels of [`Trainer::labelled_pixels`]: on a capture with sparse
    /// depth the strokes reach frames that were never drawn on.
    pub fn labelled_frames(&self) -> usize {
        self.labelled_frames
    }
}
