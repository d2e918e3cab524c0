//! The import options that only some layouts use, their names on the command line, and the
//! check that refuses them for the others (an ignored option would pack something else than the
//! user asked for, silently).
use std::path::Path;

use super::{ImportOptions, Layout, shown};
use crate::scene::error::{Result, SceneError};

/// What transparent pixels of RGBA images are composited on.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Background {
    /// NeRF-synthetic training composites on white, so white is what models of those scenes see.
    #[default]
    White,
    Black,
}

impl Background {
    pub const ALL: [Background; 2] = [Background::White, Background::Black];

    pub fn name(self) -> &'static str {
        match self {
            Background::White => "white",
            Background::Black => "black",
        }
    }

    pub fn parse(name: &str) -> Option<Background> {
        Background::ALL.into_iter().find(|b| b.name() == name)
    }

    /// The channel value transparent pixels take.
    pub fn value(self) -> u8 {
        match self {
            Background::White => 255,
            Background::Black => 0,
        }
    }
}

/// One split of a NeRF-synthetic folder (`transforms_<split>.json`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub enum Split {
    Train,
    Val,
    Test,
}

impl Split {
    /// In the order they are packed when all are.
    pub const ALL: [Split; 3] = [Split::Train, Split::Val, Split::Test];

    pub fn name(self) -> &'static str {
        match self {
            Split::Train => "train",
            Split::Val => "val",
            Split::Test => "test",
        }
    }

    pub fn parse(name: &str) -> Option<Split> {
        Split::ALL.into_iter().find(|s| s.name() == name)
    }

    /// The split's file in the capture folder.
    pub fn file_name(self) -> String {
        format!("transforms_{}.json", self.name())
    }
}

/// Refuses options that `layout` would ignore.
pub(super) fn check_for_layout(opts: &ImportOptions, layout: Layout, input: &Path) -> Result<()> {
    let refuse = |at: String, option: &str, which: &str| {
        Err(SceneError::invalid(
            at,
            format!(
                "{option} is for {which} captures; {} is a {} capture",
                shown(input),
                layout.name()
            ),
        ))
    };
    if layout != Layout::Colmap
        && let Some(masks) = &opts.masks
    {
        return refuse(shown(masks), "--masks", "COLMAP");
    }
    if layout != Layout::NerfSplits && !opts.splits.is_empty() {
        return refuse(
            shown(input),
            "--split",
            "NeRF-synthetic split folder (transforms_train.json, ...)",
        );
    }
    if opts.alpha_gt && !matches!(layout, Layout::NerfSplits | Layout::Transforms) {
        return refuse(shown(input), "--alpha-gt", "NeRF (transforms.json or split folder)");
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_round_trip() {
        for s in Split::ALL {
            assert_eq!(Split::parse(s.name()), Some(s));
        }
        for b in Background::ALL {
            assert_eq!(Background::parse(b.name()), Some(b));
        }
        assert_eq!(Split::parse("training"), None);
        assert_eq!(Split::Val.file_name(), "transforms_val.json");
    }

    #[test]
    fn options_of_other_layouts_are_refused() {
        let opts = ImportOptions {
            splits: vec![Split::Train],
            ..Default::default()
        };
        let err = check_for_layout(&opts, Layout::Transforms, Path::new("cap")).unwrap_err();
        assert!(err.to_string().contains("--split is for NeRF-synthetic"), "{err}");
        assert!(check_for_layout(&opts, Layout::NerfSplits, Path::new("cap")).is_ok());
        let opts = ImportOptions {
            alpha_gt: true,
            ..Default::default()
        };
        let err = check_for_layout(&opts, Layout::ScanNet, Path::new("cap")).unwrap_err();
        assert!(err.to_string().contains("--alpha-gt") && err.to_string().contains("scannet"));
        assert!(check_for_layout(&opts, Layout::Transforms, Path::new("cap")).is_ok());
    }
}
