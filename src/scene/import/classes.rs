//! Class lists for imported ground truth and labels, with distinct display colours.
use crate::colors::distinct_color;
use crate::scene::label_set::ClassInfo;

pub(super) fn class_infos(names: impl IntoIterator<Item = String>) -> Vec<ClassInfo> {
    names
        .into_iter()
        .enumerate()
        .map(|(i, name)| ClassInfo {
            name,
            color: distinct_color(i),
        })
        .collect()
}

/// Placeholder names for `count` classes known only by id.
pub(super) fn numbered(count: usize) -> Vec<String> {
    (0..count).map(|i| format!("class {i}")).collect()
}
