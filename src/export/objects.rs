//! The object-count cleanup of autolabel's `export.py --objects N`: of each class but the
//! first, only the N largest 8-connected regions of a mask are kept, and the pixels of the
//! others go to the first class. autolabel's first class is the background, so specks of a
//! class far from where it really is become background instead of a stray object.
use image::GrayImage;

/// Keeps the `keep` largest 8-connected regions of each class id above 0 in `mask` and sets
/// the rest of that class's pixels to 0. Regions of the same size are ranked by their first
/// pixel in reading order, so the result does not depend on anything but the mask.
pub fn keep_largest(mask: &mut GrayImage, keep: u32) {
    let (w, h) = (mask.width() as usize, mask.height() as usize);
    let ids = mask.as_raw().clone();
    let mut region = vec![u32::MAX; w * h];
    // (class, size, first pixel) of each region, in the order their first pixels come.
    let mut regions: Vec<(u8, u32, usize)> = Vec::new();
    let mut stack = Vec::new();
    for start in 0..w * h {
        if ids[start] == 0 || region[start] != u32::MAX {
            continue;
        }
        let r = regions.len() as u32;
        let class = ids[start];
        let mut size = 0u32;
        region[start] = r;
        stack.push(start);
        while let Some(p) = stack.pop() {
            size += 1;
            let (x, y) = (p % w, p / w);
            for dy in -1i64..=1 {
                for dx in -1i64..=1 {
                    let (nx, ny) = (x as i64 + dx, y as i64 + dy);
                    if nx < 0 || ny < 0 || nx >= w as i64 || ny >= h as i64 {
                        continue;
                    }
                    let q = ny as usize * w + nx as usize;
                    if ids[q] == class && region[q] == u32::MAX {
                        region[q] = r;
                        stack.push(q);
                    }
                }
            }
        }
        regions.push((class, size, start));
    }
    let mut order: Vec<usize> = (0..regions.len()).collect();
    order.sort_by_key(|&r| (regions[r].0, std::cmp::Reverse(regions[r].1), regions[r].2));
    let mut kept = vec![false; regions.len()];
    let mut per_class = [0u32; 256];
    for r in order {
        let class = regions[r].0 as usize;
        if per_class[class] < keep {
            per_class[class] += 1;
            kept[r] = true;
        }
    }
    for (p, id) in mask.iter_mut().enumerate() {
        if *id != 0 && !kept[region[p] as usize] {
            *id = 0;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn mask(rows: &[&str]) -> GrayImage {
        GrayImage::from_fn(rows[0].len() as u32, rows.len() as u32, |x, y| {
            image::Luma([rows[y as usize].as_bytes()[x as usize] - b'0'])
        })
    }

    #[test]
    fn keeps_the_largest_regions_of_each_class() {
        let mut m = mask(&[
            "1100022", //
            "1100020", // class 1: a 4-pixel square, a 1-pixel speck, a 2-pixel bar
            "0001000", // class 2: a 3-pixel corner, a diagonal pair (8-connected: one region)
            "0000200", //
            "1100020", //
        ]);
        keep_largest(&mut m, 1);
        assert_eq!(
            m,
            mask(&[
                "1100022", //
                "1100020", //
                "0000000", //
                "0000000", //
                "0000000", //
            ])
        );
        let mut m = mask(&[
            "1100022", //
            "1100020", //
            "0001000", //
            "0000200", //
            "1100020", //
        ]);
        keep_largest(&mut m, 2);
        assert_eq!(
            m,
            mask(&[
                "1100022", //
                "1100020", //
                "0000000", //
                "0000200", //
                "1100020", //
            ])
        );
    }

    #[test]
    fn ties_go_to_the_first_region_and_class_zero_is_left_alone() {
        let mut m = mask(&["1010", "0000", "0033"]);
        keep_largest(&mut m, 1);
        assert_eq!(m, mask(&["1000", "0000", "0033"]));
        let mut m = mask(&["0000", "0110", "0000"]);
        let before = m.clone();
        keep_largest(&mut m, 1);
        assert_eq!(m, before);
    }
}
