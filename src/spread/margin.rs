//! A margin inside what the walk labels: a walk's errors lie along the edges where it stopped
//! (or failed to stop), so the pixels it labelled next to any pixel not of their class are left
//! for the field to decide.

use crate::labels::UNLABELLED;

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
}
