//! Undo and redo of annotation edits. Every change the annotator makes to a [`LabelSet`] goes
//! through [`History::apply`] as an [`Edit`]; undo applies the inverse of the latest one. Edits
//! are small (one stroke, one class change) so the history can be long without holding copies
//! of the whole label set; only whole-set replacements (import, restore) keep both sets.
use super::{ClassInfo, LabelSet, Stroke};

/// Edits kept for undo; the oldest are forgotten beyond this.
pub const MAX_UNDO: usize = 1000;

/// One undoable change to a label set.
#[derive(Clone, Debug, PartialEq)]
pub enum Edit {
    /// A stroke (brush or eraser) appended to a frame.
    AddStroke { frame: u32, stroke: Stroke },
    /// A class appended to the palette.
    AddClass(ClassInfo),
    /// A class renamed or recoloured.
    ChangeClass {
        index: usize,
        before: ClassInfo,
        after: ClassInfo,
    },
    /// Every stroke of a frame removed at once ("clear frame").
    ClearFrame { frame: u32, strokes: Vec<Stroke> },
    /// The whole set replaced (import of an annotations file).
    Replace {
        before: Box<LabelSet>,
        after: Box<LabelSet>,
    },
}

impl Edit {
    /// The frame whose labels the edit changes, when it is about one frame.
    pub fn frame(&self) -> Option<u32> {
        match self {
            Edit::AddStroke { frame, .. } | Edit::ClearFrame { frame, .. } => Some(*frame),
            _ => None,
        }
    }

    /// Whether undoing or redoing this edit changes which pixels carry which label (and so
    /// what the trainer must be told), as opposed to only names or colours.
    pub fn changes_pixels(&self) -> bool {
        !matches!(self, Edit::ChangeClass { .. } | Edit::AddClass(_))
    }
}

/// Why an edit could not be applied; the set is unchanged then.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum EditError {
    #[error("class {class} does not exist (there are {classes} classes)")]
    NoSuchClass { class: usize, classes: usize },
    #[error("the history does not match the labels (nothing to undo on frame {frame})")]
    OutOfStep { frame: u32 },
}

/// The undo and redo stacks.
#[derive(Clone, Debug, Default)]
pub struct History {
    done: Vec<Edit>,
    undone: Vec<Edit>,
}

impl History {
    pub fn new() -> History {
        History::default()
    }

    pub fn can_undo(&self) -> bool {
        !self.done.is_empty()
    }

    pub fn can_redo(&self) -> bool {
        !self.undone.is_empty()
    }

    /// Applies `edit` to `labels` and records it; a new edit forgets what was undone.
    pub fn apply(&mut self, labels: &mut LabelSet, edit: Edit) -> Result<(), EditError> {
        forward(labels, &edit)?;
        self.done.push(edit);
        if self.done.len() > MAX_UNDO {
            self.done.remove(0);
        }
        self.undone.clear();
        Ok(())
    }

    /// Like [`History::apply`], but a class change right after another change of the same class
    /// joins it, so dragging through a colour picker is one undo step, not hundreds.
    pub fn apply_merging(&mut self, labels: &mut LabelSet, edit: Edit) -> Result<(), EditError> {
        if let (
            Edit::ChangeClass { index, after, .. },
            Some(Edit::ChangeClass {
                index: last_index,
                after: last_after,
                ..
            }),
        ) = (&edit, self.done.last_mut())
            && index == last_index
            && self.undone.is_empty()
        {
            forward(labels, &edit)?;
            *last_after = after.clone();
            return Ok(());
        }
        self.apply(labels, edit)
    }

    /// Reverts the latest edit; returns it (the caller refreshes what it touched).
    pub fn undo(&mut self, labels: &mut LabelSet) -> Result<Option<&Edit>, EditError> {
        let Some(edit) = self.done.pop() else {
            return Ok(None);
        };
        if let Err(e) = backward(labels, &edit) {
            self.done.push(edit);
            return Err(e);
        }
        self.undone.push(edit);
        Ok(self.undone.last())
    }

    /// Re-applies the latest undone edit; returns it.
    pub fn redo(&mut self, labels: &mut LabelSet) -> Result<Option<&Edit>, EditError> {
        let Some(edit) = self.undone.pop() else {
            return Ok(None);
        };
        if let Err(e) = forward(labels, &edit) {
            self.undone.push(edit);
            return Err(e);
        }
        self.done.push(edit);
        Ok(self.done.last())
    }
}

fn forward(labels: &mut LabelSet, edit: &Edit) -> Result<(), EditError> {
    match edit {
        Edit::AddStroke { frame, stroke } => {
            if let Some(c) = stroke.class {
                check_class(labels, c as usize)?;
            }
            labels.push_stroke(*frame, stroke.clone());
        }
        Edit::AddClass(class) => labels.classes.push(class.clone()),
        Edit::ChangeClass { index, after, .. } => {
            check_class(labels, *index)?;
            labels.classes[*index] = after.clone();
        }
        Edit::ClearFrame { frame, .. } => labels.frames.retain(|f| f.frame != *frame),
        Edit::Replace { after, .. } => *labels = (**after).clone(),
    }
    Ok(())
}

fn backward(labels: &mut LabelSet, edit: &Edit) -> Result<(), EditError> {
    match edit {
        Edit::AddStroke { frame, .. } => {
            let out_of_step = EditError::OutOfStep { frame: *frame };
            let at = labels
                .frames
                .iter()
                .position(|f| f.frame == *frame)
                .ok_or(out_of_step.clone())?;
            labels.frames[at].strokes.pop().ok_or(out_of_step)?;
            if labels.frames[at].strokes.is_empty() {
                labels.frames.remove(at);
            }
        }
        Edit::AddClass(_) => {
            labels.classes.pop();
        }
        Edit::ChangeClass { index, before, .. } => {
            check_class(labels, *index)?;
            labels.classes[*index] = before.clone();
        }
        Edit::ClearFrame { frame, strokes } => {
            for s in strokes {
                labels.push_stroke(*frame, s.clone());
            }
        }
        Edit::Replace { before, .. } => *labels = (**before).clone(),
    }
    Ok(())
}

fn check_class(labels: &LabelSet, class: usize) -> Result<(), EditError> {
    if class < labels.classes.len() {
        Ok(())
    } else {
        Err(EditError::NoSuchClass {
            class,
            classes: labels.classes.len(),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn class(name: &str) -> ClassInfo {
        ClassInfo {
            name: name.into(),
            color: [1, 2, 3],
        }
    }

    fn stroke(class: Option<u16>, x: f32) -> Stroke {
        Stroke {
            class,
            radius: 2.0,
            points: vec![[x, 1.0], [x + 1.0, 2.0]],
        }
    }

    #[test]
    fn undo_and_redo_walk_back_and_forth() {
        let mut labels = LabelSet::new(vec![class("a"), class("b")]);
        let mut history = History::new();
        let empty = labels.clone();
        history
            .apply(
                &mut labels,
                Edit::AddStroke {
                    frame: 3,
                    stroke: stroke(Some(0), 1.0),
                },
            )
            .unwrap();
        history
            .apply(
                &mut labels,
                Edit::AddStroke {
                    frame: 1,
                    stroke: stroke(Some(1), 5.0),
                },
            )
            .unwrap();
        history
            .apply(
                &mut labels,
                Edit::AddStroke {
                    frame: 3,
                    stroke: stroke(None, 2.0),
                },
            )
            .unwrap();
        let full = labels.clone();
        assert_eq!(labels.frames.iter().map(|f| f.frame).collect::<Vec<_>>(), [1, 3]);

        assert_eq!(history.undo(&mut labels).unwrap().and_then(Edit::frame), Some(3));
        assert_eq!(labels.frame(3).unwrap().strokes.len(), 1);
        history.undo(&mut labels).unwrap();
        history.undo(&mut labels).unwrap();
        assert_eq!(labels, empty, "a frame whose last stroke is undone disappears");
        assert!(history.undo(&mut labels).unwrap().is_none());
        for _ in 0..3 {
            history.redo(&mut labels).unwrap();
        }
        assert_eq!(labels, full);
        assert!(!history.can_redo());
    }

    #[test]
    fn a_new_edit_forgets_the_undone_ones() {
        let mut labels = LabelSet::new(vec![class("a")]);
        let mut history = History::new();
        let add = |x| Edit::AddStroke {
            frame: 0,
            stroke: stroke(Some(0), x),
        };
        history.apply(&mut labels, add(1.0)).unwrap();
        history.undo(&mut labels).unwrap();
        assert!(history.can_redo());
        history.apply(&mut labels, add(2.0)).unwrap();
        assert!(!history.can_redo());
        assert_eq!(labels.frame(0).unwrap().strokes, vec![stroke(Some(0), 2.0)]);
    }

    #[test]
    fn class_edits_clear_and_replace_undo() {
        let mut labels = LabelSet::new(vec![class("a")]);
        let mut history = History::new();
        history.apply(&mut labels, Edit::AddClass(class("b"))).unwrap();
        history
            .apply(
                &mut labels,
                Edit::ChangeClass {
                    index: 1,
                    before: class("b"),
                    after: ClassInfo {
                        name: "mug".into(),
                        color: [9, 9, 9],
                    },
                },
            )
            .unwrap();
        history
            .apply(
                &mut labels,
                Edit::AddStroke {
                    frame: 2,
                    stroke: stroke(Some(1), 0.0),
                },
            )
            .unwrap();
        let before_clear = labels.clone();
        let strokes = labels.frame(2).unwrap().strokes.clone();
        history
            .apply(&mut labels, Edit::ClearFrame { frame: 2, strokes })
            .unwrap();
        assert!(labels.frames.is_empty());
        let imported = LabelSet::new(vec![class("x")]);
        let before = Box::new(labels.clone());
        history
            .apply(
                &mut labels,
                Edit::Replace {
                    before,
                    after: Box::new(imported.clone()),
                },
            )
            .unwrap();
        assert_eq!(labels, imported);
        history.undo(&mut labels).unwrap();
        history.undo(&mut labels).unwrap();
        assert_eq!(labels, before_clear);
        history.undo(&mut labels).unwrap();
        history.undo(&mut labels).unwrap();
        assert_eq!(labels.classes[1], class("b"));
        history.undo(&mut labels).unwrap();
        assert_eq!(labels.classes, vec![class("a")]);
    }

    #[test]
    fn repeated_class_changes_merge_into_one_undo_step() {
        let mut labels = LabelSet::new(vec![class("a"), class("b")]);
        let mut history = History::new();
        let colour = |index: usize, c: u8| ClassInfo {
            name: ["a", "b"][index].into(),
            color: [c, c, c],
        };
        let mut before = class("a");
        for c in 10..20 {
            let after = colour(0, c);
            history
                .apply_merging(
                    &mut labels,
                    Edit::ChangeClass {
                        index: 0,
                        before: before.clone(),
                        after: after.clone(),
                    },
                )
                .unwrap();
            before = after;
        }
        history
            .apply_merging(
                &mut labels,
                Edit::ChangeClass {
                    index: 1,
                    before: class("b"),
                    after: colour(1, 5),
                },
            )
            .unwrap();
        assert_eq!(labels.classes, vec![colour(0, 19), colour(1, 5)]);
        history.undo(&mut labels).unwrap();
        assert_eq!(labels.classes, vec![colour(0, 19), class("b")]);
        history.undo(&mut labels).unwrap();
        assert_eq!(labels.classes, vec![class("a"), class("b")]);
        assert!(!history.can_undo());
    }

    #[test]
    fn invalid_edits_change_nothing() {
        let mut labels = LabelSet::new(vec![class("a")]);
        let mut history = History::new();
        let err = history
            .apply(
                &mut labels,
                Edit::AddStroke {
                    frame: 0,
                    stroke: stroke(Some(4), 0.0),
                },
            )
            .unwrap_err();
        assert_eq!(err, EditError::NoSuchClass { class: 4, classes: 1 });
        assert!(labels.frames.is_empty() && !history.can_undo());
    }

    #[test]
    fn history_is_bounded() {
        let mut labels = LabelSet::new(vec![class("a")]);
        let mut history = History::new();
        for i in 0..MAX_UNDO + 5 {
            history
                .apply(
                    &mut labels,
                    Edit::AddStroke {
                        frame: 0,
                        stroke: stroke(Some(0), i as f32),
                    },
                )
                .unwrap();
        }
        let mut undone = 0;
        while history.undo(&mut labels).unwrap().is_some() {
            undone += 1;
        }
        assert_eq!(undone, MAX_UNDO);
        assert_eq!(labels.frame(0).unwrap().strokes.len(), 5);
    }
}
