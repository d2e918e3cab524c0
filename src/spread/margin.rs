//! A margin inside what the walk labels: a walk's errors lie along the edges where it stopped
//! (or failed to stop), so the pixels it labelled next to any pixel not of their class are left
//! for the field to decide.

use crate::labels::UNLABELLED;
use crate::spread::box_counts::BoxCounts;

/// Drops each label of `walked` (`width` x `height`, row-major) that the walk added (`seeds` has
/// no label there) and that has, within `radius` pixels (a square window, clipped to the frame),
/// a pixel not labelled with its class. Seeds are never dropped; `radius` 0 changes nothing.
pub fn erode_walked(walked: &mut [u16], seeds: &[u16], width: usize, height: usize, radius: usize) {
    if radius == 0 || walked.len() != width * height || seeds.len() != walked.len() {
        return;
    }
    let before = walked.to_vec();
    // Rows, then columns: a pixel keeps its label when every pixel of its window has it.
    let mut same_in_row = vec![false; before.len()];
    for y in 0..height {
        for x in 0..width {
            let i = y * width + x;
            let label = before[i];
            same_in_row[i] = label != UNLABELLED
                && (x.saturating_sub(radius)..(x + radius + 1).min(width)).all(|k| before[y * width + k] == label);
        }
    }
    for y in 0..height {
        for x in 0..width {
            let i = y * width + x;
            if seeds[i] != UNLABELLED || before[i] == UNLABELLED {
                continue;
            }
            let label = before[i];
            let whole = (y.saturating_sub(radius)..(y + radius + 1).min(height))
                .all(|k| same_in_row[k * width + x] && before[k * width + x] == label);
            if !whole {
                walked[i] = UNLABELLED;
            }
        }
    }
}

/// Drops each label of `map` within `margin` pixels of the edge of its class's footprint: the
/// pixels with a label of that class within `gap` pixels. Sparse labels (a reconstruction's
/// points in a photo) leave gaps that are not edges; `gap` bridges them.
pub fn erode_footprints(map: &mut [u16], width: usize, height: usize, gap: usize, margin: usize, kept: Option<u16>) {
    if margin == 0 || map.len() != width * height {
        return;
    }
    let before = map.to_vec();
    let mut classes: Vec<u16> = before.iter().copied().filter(|&c| c != UNLABELLED).collect();
    classes.sort_unstable();
    classes.dedup();
    for class in classes.into_iter().filter(|&c| Some(c) != kept) {
        let labelled: Vec<u32> = (0..before.len() as u32)
            .filter(|&i| before[i as usize] == class)
            .collect();
        let near = BoxCounts::new(&labelled, width, height);
        let outside: Vec<u32> = (0..before.len() as u32)
            .filter(|&i| {
                let i = i as usize;
                let other = before[i] != class && before[i] != UNLABELLED;
                other || near.around(i % width, i / width, gap) == 0
            })
            .collect();
        let outside = BoxCounts::new(&outside, width, height);
        for (i, m) in map.iter_mut().enumerate() {
            if before[i] == class && outside.around(i % width, i / width, margin) > 0 {
                *m = UNLABELLED;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const U: u16 = UNLABELLED;

    #[test]
    fn the_walk_loses_its_labels_next_to_other_classes_and_gaps_but_seeds_stay() {
        // One row: a seed of class 0 at column 0, the walk's labels up to class 1's at 3..6,
        // and an unlabelled pixel at column 7.
        let seeds = vec![0, U, U, U, U, 1, U, U];
        let mut walked = vec![0, 0, 0, 1, 1, 1, 1, U];
        erode_walked(&mut walked, &seeds, 8, 1, 1);
        assert_eq!(walked, vec![0, 0, U, U, 1, 1, U, U]);
    }

    #[test]
    fn the_window_is_square_and_clipped_to_the_frame() {
        // 3 x 3 of class 0 walked from the centre's seed, with one unlabelled corner.
        let seeds = vec![U, U, U, U, 0, U, U, U, U];
        let mut walked = vec![0, 0, 0, 0, 0, 0, 0, 0, U];
        erode_walked(&mut walked, &seeds, 3, 3, 1);
        assert_eq!(walked, vec![0, 0, 0, 0, 0, U, 0, U, U]);
    }

    #[test]
    fn radius_zero_changes_nothing() {
        let seeds = vec![U; 4];
        let mut walked = vec![0, 1, 0, 1];
        erode_walked(&mut walked, &seeds, 4, 1, 0);
        assert_eq!(walked, vec![0, 1, 0, 1]);
    }

    #[test]
    fn sparse_labels_lose_a_margin_inside_their_footprint_and_keep_the_frame_border() {
        // 10 x 1: class 1 at every other pixel of columns 0..6 (points with gaps of one pixel),
        // then nothing. The footprint (gap 1) covers columns 0..7; a margin of 2 drops the labels
        // within 2 pixels of what lies beyond it, none at the frame's border on the left.
        let mut map = vec![1, U, 1, U, 1, U, 1, U, U, U];
        erode_footprints(&mut map, 10, 1, 1, 2, None);
        assert_eq!(map, vec![1, U, 1, U, 1, U, U, U, U, U]);
    }

    #[test]
    fn a_footprint_edge_against_another_class_is_an_edge_for_both() {
        // 6 x 1: class 0 then class 1, dense; margin 1 drops the pair at the meeting.
        let mut map = vec![0, 0, 0, 1, 1, 1];
        erode_footprints(&mut map, 6, 1, 1, 1, None);
        assert_eq!(map, vec![0, 0, U, U, 1, 1]);
        // A lone label with no gap bridged lies on its footprint's edge.
        let mut map = vec![U; 16];
        map[5] = 2;
        erode_footprints(&mut map, 4, 4, 0, 1, None);
        assert_eq!(map, vec![U; 16]);
    }

    #[test]
    fn no_margin_keeps_every_label() {
        let mut map = vec![0, U, 1, 1];
        erode_footprints(&mut map, 4, 1, 1, 0, None);
        assert_eq!(map, vec![0, U, 1, 1]);
    }

    #[test]
    fn the_kept_class_keeps_every_label() {
        let mut map = vec![0, 0, 0, 1, 1, 1];
        erode_footprints(&mut map, 6, 1, 1, 1, Some(0));
        assert_eq!(map, vec![0, 0, 0, U, 1, 1]);
    }
}
