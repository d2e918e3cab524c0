//! Learning curves of the simulated user (mean IoU against labelled clicks): their CSV files,
//! the figures read off them (clicks needed to reach an IoU, IoU at a click count) and the
//! markdown tables of `ablate`. Plain data and maths, no GPU: unit-tested here.
use std::fmt::Write;

/// One evaluation of a simulated-user run.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct CurvePoint {
    /// Rounds of clicking done (0: after the warm-up, before any label).
    pub round: u32,
    /// Labelled clicks so far.
    pub clicks: u32,
    pub mean_iou: f64,
    pub pixel_acc: f64,
    /// Training steps done so far (warm-up included).
    pub steps: u32,
}

/// Header of a run's `curve.csv`.
pub const CURVE_HEADER: &str = "round,clicks,mean_iou,pixel_acc,steps";
/// Header of `ablate`'s `ablation.csv`: the curve columns after the scene and the method.
pub const ABLATION_HEADER: &str = "scene,method,round,clicks,mean_iou,pixel_acc,steps";

impl CurvePoint {
    fn csv_fields(&self) -> String {
        // Shortest round-trip formatting: the file parses back to exactly these values.
        format!(
            "{},{},{},{},{}",
            self.round, self.clicks, self.mean_iou, self.pixel_acc, self.steps
        )
    }

    fn parse_fields(fields: &[&str], line: usize) -> Result<CurvePoint, String> {
        let [round, clicks, miou, acc, steps] = fields else {
            return Err(format!("line {line}: expected 5 curve fields, found {}", fields.len()));
        };
        let int = |name: &str, v: &str| {
            v.trim()
                .parse::<u32>()
                .map_err(|e| format!("line {line}: {name} {v:?}: {e}"))
        };
        let float = |name: &str, v: &str| {
            v.trim()
                .parse::<f64>()
                .map_err(|e| format!("line {line}: {name} {v:?}: {e}"))
        };
        Ok(CurvePoint {
            round: int("round", round)?,
            clicks: int("clicks", clicks)?,
            mean_iou: float("mean_iou", miou)?,
            pixel_acc: float("pixel_acc", acc)?,
            steps: int("steps", steps)?,
        })
    }
}

/// A run's `curve.csv`.
pub fn curve_csv(points: &[CurvePoint]) -> String {
    let mut s = format!("{CURVE_HEADER}\n");
    for p in points {
        let _ = writeln!(s, "{}", p.csv_fields());
    }
    s
}

pub fn parse_curve_csv(text: &str) -> Result<Vec<CurvePoint>, String> {
    let mut lines = text.lines().enumerate();
    match lines.next() {
        Some((_, h)) if h.trim() == CURVE_HEADER => {}
        other => {
            return Err(format!(
                "line 1: expected the header {CURVE_HEADER:?}, found {:?}",
                other.map(|(_, h)| h).unwrap_or("")
            ));
        }
    }
    lines
        .filter(|(_, l)| !l.trim().is_empty())
        .map(|(i, l)| CurvePoint::parse_fields(&l.split(',').collect::<Vec<_>>(), i + 1))
        .collect()
}

/// The curve of one method on one scene.
#[derive(Clone, Debug, PartialEq)]
pub struct MethodCurve {
    pub scene: String,
    pub method: String,
    pub points: Vec<CurvePoint>,
}

/// `ablation.csv`: every curve, one row per evaluation. Names must not contain commas.
pub fn ablation_csv(curves: &[MethodCurve]) -> String {
    let mut s = format!("{ABLATION_HEADER}\n");
    for c in curves {
        for p in &c.points {
            let _ = writeln!(s, "{},{},{}", c.scene, c.method, p.csv_fields());
        }
    }
    s
}

/// Parses `ablation.csv` back into curves, in the order they first appear.
pub fn parse_ablation_csv(text: &str) -> Result<Vec<MethodCurve>, String> {
    let mut lines = text.lines().enumerate();
    match lines.next() {
        Some((_, h)) if h.trim() == ABLATION_HEADER => {}
        other => {
            return Err(format!(
                "line 1: expected the header {ABLATION_HEADER:?}, found {:?}",
                other.map(|(_, h)| h).unwrap_or("")
            ));
        }
    }
    let mut curves: Vec<MethodCurve> = Vec::new();
    for (i, line) in lines.filter(|(_, l)| !l.trim().is_empty()) {
        let fields: Vec<&str> = line.split(',').collect();
        if fields.len() != 7 {
            return Err(format!("line {}: expected 7 fields, found {}", i + 1, fields.len()));
        }
        let point = CurvePoint::parse_fields(&fields[2..], i + 1)?;
        let (scene, method) = (fields[0], fields[1]);
        match curves.iter_mut().find(|c| c.scene == scene && c.method == method) {
            Some(c) => c.points.push(point),
            None => curves.push(MethodCurve {
                scene: scene.to_string(),
                method: method.to_string(),
                points: vec![point],
            }),
        }
    }
    Ok(curves)
}

/// Clicks needed to reach `target` mean IoU: the first crossing of the curve, interpolated
/// linearly between the two evaluations around it; the first point's clicks if it already
/// reaches the target; `None` if the curve never does. Points must be in click order.
pub fn clicks_to_reach(points: &[CurvePoint], target: f64) -> Option<f64> {
    let first = points.first()?;
    if first.mean_iou >= target {
        return Some(f64::from(first.clicks));
    }
    points.windows(2).find_map(|w| {
        let (a, b) = (&w[0], &w[1]);
        (a.mean_iou < target && b.mean_iou >= target).then(|| {
            let t = (target - a.mean_iou) / (b.mean_iou - a.mean_iou);
            f64::from(a.clicks) + t * f64::from(b.clicks - a.clicks)
        })
    })
}

/// Mean IoU at `clicks`, interpolated linearly between the evaluations around it; `None`
/// outside the measured range (before the first evaluation or past the last).
pub fn iou_at(points: &[CurvePoint], clicks: u32) -> Option<f64> {
    let x = f64::from(clicks);
    if let Some(p) = points.iter().rev().find(|p| p.clicks == clicks) {
        return Some(p.mean_iou);
    }
    points.windows(2).find_map(|w| {
        let (a, b) = (&w[0], &w[1]);
        let (xa, xb) = (f64::from(a.clicks), f64::from(b.clicks));
        (xa < x && x < xb).then(|| a.mean_iou + (x - xa) / (xb - xa) * (b.mean_iou - a.mean_iou))
    })
}

/// Click counts of the table's "IoU at" columns.
pub const IOU_AT_CLICKS: [u32; 3] = [50, 100, 500];
/// Mean IoU targets of the table's "clicks to reach" columns.
pub const REACH_TARGETS: [f64; 2] = [0.8, 0.9];

fn dash_or(v: Option<f64>, f: impl Fn(f64) -> String) -> String {
    v.map(f).unwrap_or_else(|| "—".to_string())
}

/// The markdown tables of `ablate`: the final mean IoU in the shape of the paper's Table I
/// (a row per scene, a column per method), then per scene and method the clicks needed to reach
/// 80 % and 90 % mean IoU and the mean IoU at 50, 100 and 500 clicks ("—": not reached or
/// not measured that far).
pub fn markdown_tables(curves: &[MethodCurve]) -> String {
    let mut scenes: Vec<&str> = Vec::new();
    let mut methods: Vec<&str> = Vec::new();
    for c in curves {
        if !scenes.contains(&c.scene.as_str()) {
            scenes.push(&c.scene);
        }
        if !methods.contains(&c.method.as_str()) {
            methods.push(&c.method);
        }
    }
    let find = |s: &str, m: &str| curves.iter().find(|c| c.scene == s && c.method == m);
    let mut out = String::new();
    let _ = writeln!(
        out,
        "Mean IoU on the held-out frames at the end of the run (clicks used):\n"
    );
    let _ = writeln!(out, "| scene | {} |", methods.join(" | "));
    let _ = writeln!(out, "|---|{}", "---|".repeat(methods.len()));
    for s in &scenes {
        let cells: Vec<String> = methods
            .iter()
            .map(|m| match find(s, m).and_then(|c| c.points.last()) {
                Some(p) => format!("{:.3} ({})", p.mean_iou, p.clicks),
                None => "—".to_string(),
            })
            .collect();
        let _ = writeln!(out, "| {s} | {} |", cells.join(" | "));
    }
    let _ = writeln!(out);
    let reach: Vec<String> = REACH_TARGETS
        .iter()
        .map(|t| format!("clicks to {:.0} %", t * 100.0))
        .collect();
    let at: Vec<String> = IOU_AT_CLICKS.iter().map(|c| format!("IoU @ {c}")).collect();
    let _ = writeln!(out, "| scene | method | {} | {} |", reach.join(" | "), at.join(" | "));
    let _ = writeln!(out, "|---|---|{}", "---|".repeat(reach.len() + at.len()));
    for s in &scenes {
        for m in &methods {
            let Some(c) = find(s, m) else { continue };
            let mut cells: Vec<String> = REACH_TARGETS
                .iter()
                .map(|&t| dash_or(clicks_to_reach(&c.points, t), |v| format!("{v:.0}")))
                .collect();
            cells.extend(
                IOU_AT_CLICKS
                    .iter()
                    .map(|&k| dash_or(iou_at(&c.points, k), |v| format!("{v:.3}"))),
            );
            let _ = writeln!(out, "| {s} | {m} | {} |", cells.join(" | "));
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn curve(points: &[(u32, f64)]) -> Vec<CurvePoint> {
        points
            .iter()
            .enumerate()
            .map(|(i, &(clicks, mean_iou))| CurvePoint {
                round: i as u32,
                clicks,
                mean_iou,
                pixel_acc: mean_iou,
                steps: 100 + 250 * i as u32,
            })
            .collect()
    }

    #[test]
    fn clicks_to_reach_interpolates_the_first_crossing() {
        let c = curve(&[(0, 0.2), (10, 0.6), (20, 0.85), (30, 0.7), (40, 0.95)]);
        // 0.8 is crossed between 10 (0.6) and 20 (0.85): 10 + 0.2 / 0.25 * 10 = 18.
        assert!((clicks_to_reach(&c, 0.8).unwrap() - 18.0).abs() < 1e-9);
        // 0.9: not between 20 and 30 (it falls), first between 30 (0.7) and 40 (0.95): 38.
        assert!((clicks_to_reach(&c, 0.9).unwrap() - 38.0).abs() < 1e-9);
        assert_eq!(clicks_to_reach(&c, 0.2), Some(0.0));
        assert_eq!(clicks_to_reach(&c, 0.99), None);
        assert_eq!(clicks_to_reach(&[], 0.5), None);
        // Exactly reaching the target counts.
        assert_eq!(clicks_to_reach(&curve(&[(0, 0.1), (5, 0.8)]), 0.8), Some(5.0));
    }

    #[test]
    fn iou_at_interpolates_inside_the_measured_range_only() {
        let c = curve(&[(0, 0.2), (40, 0.6), (60, 0.7)]);
        assert!((iou_at(&c, 50).unwrap() - 0.65).abs() < 1e-12);
        assert!((iou_at(&c, 10).unwrap() - 0.3).abs() < 1e-12);
        assert_eq!(iou_at(&c, 40), Some(0.6));
        assert_eq!(iou_at(&c, 60), Some(0.7));
        assert_eq!(iou_at(&c, 100), None);
        assert_eq!(iou_at(&curve(&[(5, 0.5)]), 0), None);
    }

    #[test]
    fn csv_round_trips_and_errors_name_the_line() {
        let c = curve(&[(0, 0.25), (5, 0.5)]);
        assert_eq!(parse_curve_csv(&curve_csv(&c)).unwrap(), c);
        let curves = vec![
            MethodCurve {
                scene: "demo".into(),
                method: "hash+freq".into(),
                points: c.clone(),
            },
            MethodCurve {
                scene: "demo".into(),
                method: "freq-only".into(),
                points: c[..1].to_vec(),
            },
        ];
        assert_eq!(parse_ablation_csv(&ablation_csv(&curves)).unwrap(), curves);
        let e = parse_curve_csv(&format!("{CURVE_HEADER}\n1,2,x,0.5,3\n")).unwrap_err();
        assert!(e.contains("line 2") && e.contains("mean_iou"), "{e}");
        assert!(parse_curve_csv("a,b\n").unwrap_err().contains("header"));
    }

    #[test]
    fn tables_have_a_row_per_scene_and_dashes_where_not_reached() {
        let curves = vec![
            MethodCurve {
                scene: "demo".into(),
                method: "a".into(),
                points: curve(&[(0, 0.5), (100, 0.9)]),
            },
            MethodCurve {
                scene: "demo".into(),
                method: "b".into(),
                points: curve(&[(0, 0.3), (50, 0.4)]),
            },
            MethodCurve {
                scene: "ycb".into(),
                method: "a".into(),
                points: curve(&[(0, 0.1)]),
            },
        ];
        let md = markdown_tables(&curves);
        assert!(md.contains("| scene | a | b |"), "{md}");
        assert!(md.contains("| demo | 0.900 (100) | 0.400 (50) |"), "{md}");
        assert!(md.contains("| ycb | 0.100 (0) | — |"), "{md}");
        // a on demo: 80 % at 0 + 0.3/0.4 * 100 = 75 clicks, 90 % at 100; IoU 0.7 at 50, 0.9 at 100.
        assert!(md.contains("| demo | a | 75 | 100 | 0.700 | 0.900 | — |"), "{md}");
        assert!(md.contains("| demo | b | — | — | 0.400 | — | — |"), "{md}");
    }
}
