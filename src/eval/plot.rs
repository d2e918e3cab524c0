//! A plain line plot (mean IoU against clicks, one line per method) written as SVG by hand:
//! axes, ticks with labels, a legend. No plotting crate: the figures are simple and builds are
//! slow on the project's machines. SVG only: browsers and GitHub show it as an image, and the
//! text stays text (a PNG twin with its own pixel font was dropped).
use std::fmt::Write;

use crate::colors::distinct_color;

/// One line of the plot.
#[derive(Clone, Debug, PartialEq)]
pub struct Series {
    pub name: String,
    pub points: Vec<(f64, f64)>,
}

#[derive(Clone, Debug, PartialEq)]
pub struct LinePlot {
    pub title: String,
    pub x_label: String,
    pub y_label: String,
    /// The y axis spans this range (mean IoU: 0 to 1).
    pub y_range: (f64, f64),
    pub series: Vec<Series>,
}

const WIDTH: u32 = 800;
const HEIGHT: u32 = 480;
/// Plot area: left, top, right, bottom (pixels); the legend sits right of it.
const AREA: (f64, f64, f64, f64) = (70.0, 40.0, 560.0, 420.0);

/// "Nice" tick positions (steps of 1, 2 or 5 times a power of ten) covering [lo, hi] with at
/// most about `max_ticks` ticks; the first is ≤ lo and the last ≥ hi.
pub fn nice_ticks(lo: f64, hi: f64, max_ticks: usize) -> Vec<f64> {
    let (lo, hi) = if hi > lo { (lo, hi) } else { (lo, lo + 1.0) };
    let raw = (hi - lo) / max_ticks.max(1) as f64;
    let exponent = raw.log10().floor() as i32;
    let magnitude = 10f64.powi(exponent);
    let multiple = [1i64, 2, 5, 10]
        .into_iter()
        .find(|&m| m as f64 * magnitude >= raw)
        .unwrap_or(10);
    // Ticks as integers over a power of ten, so 3 x 0.2 prints and compares as 0.6.
    let value = |k: i64| {
        if exponent < 0 {
            (k * multiple) as f64 / 10f64.powi(-exponent)
        } else {
            (k * multiple) as f64 * magnitude
        }
    };
    let step = multiple as f64 * magnitude;
    let first = (lo / step).floor() as i64;
    let last = (hi / step - 1e-9).ceil() as i64;
    (first..=last).map(value).collect()
}

fn tick_label(v: f64) -> String {
    let s = format!("{v:.2}");
    let s = s.trim_end_matches('0').trim_end_matches('.');
    if s == "-0" { "0".into() } else { s.to_string() }
}

fn escape(s: &str) -> String {
    s.replace('&', "&amp;").replace('<', "&lt;").replace('>', "&gt;")
}

impl LinePlot {
    /// The x ticks: from 0 to the largest x of any series.
    pub fn x_ticks(&self) -> Vec<f64> {
        let max = self
            .series
            .iter()
            .flat_map(|s| s.points.iter().map(|p| p.0))
            .fold(0.0f64, f64::max);
        nice_ticks(0.0, max, 8)
    }

    pub fn y_ticks(&self) -> Vec<f64> {
        nice_ticks(self.y_range.0, self.y_range.1, 5)
    }

    /// Maps data coordinates to pixels of the plot area.
    fn mapper(&self) -> impl Fn(f64, f64) -> (f64, f64) + use<> {
        let xt = self.x_ticks();
        let yt = self.y_ticks();
        let (x0, x1) = (xt[0], *xt.last().expect("ticks are never empty"));
        let (y0, y1) = (yt[0], *yt.last().expect("ticks are never empty"));
        let (l, t, r, b) = AREA;
        move |x, y| (l + (x - x0) / (x1 - x0) * (r - l), b - (y - y0) / (y1 - y0) * (b - t))
    }

    /// The figure's width: the default, or wider so the longest legend entry fits.
    pub fn width(&self) -> u32 {
        let longest = self
            .series
            .iter()
            .map(|s| legend_text_width(&s.name))
            .max()
            .unwrap_or(0);
        WIDTH.max((AREA.2 as i64 + 46 + longest + 12) as u32)
    }

    pub fn to_svg(&self) -> String {
        let map = self.mapper();
        let (l, t, r, b) = AREA;
        let width = self.width();
        let mut s = String::new();
        let _ = writeln!(
            s,
            r#"<svg xmlns="http://www.w3.org/2000/svg" width="{width}" height="{HEIGHT}" viewBox="0 0 {width} {HEIGHT}" font-family="sans-serif" font-size="12">"#
        );
        let _ = writeln!(s, r#"<rect width="{width}" height="{HEIGHT}" fill="white"/>"#);
        let _ = writeln!(
            s,
            r#"<text x="{}" y="24" text-anchor="middle" font-size="15">{}</text>"#,
            (l + r) / 2.0,
            escape(&self.title)
        );
        for x in self.x_ticks() {
            let (px, _) = map(x, 0.0);
            let _ = writeln!(
                s,
                r##"<line x1="{px:.1}" y1="{t}" x2="{px:.1}" y2="{b}" stroke="#e0e0e0"/><text x="{px:.1}" y="{}" text-anchor="middle">{}</text>"##,
                b + 16.0,
                tick_label(x)
            );
        }
        for y in self.y_ticks() {
            let (_, py) = map(0.0, y);
            let _ = writeln!(
                s,
                r##"<line x1="{l}" y1="{py:.1}" x2="{r}" y2="{py:.1}" stroke="#e0e0e0"/><text x="{}" y="{:.1}" text-anchor="end">{}</text>"##,
                l - 6.0,
                py + 4.0,
                tick_label(y)
            );
        }
        let _ = writeln!(
            s,
            r#"<rect x="{l}" y="{t}" width="{}" height="{}" fill="none" stroke="black"/>"#,
            r - l,
            b - t
        );
        let _ = writeln!(
            s,
            r#"<text x="{}" y="{}" text-anchor="middle">{}</text>"#,
            (l + r) / 2.0,
            b + 40.0,
            escape(&self.x_label)
        );
        let _ = writeln!(
            s,
            r#"<text x="18" y="{0}" text-anchor="middle" transform="rotate(-90 18 {0})">{1}</text>"#,
            (t + b) / 2.0,
            escape(&self.y_label)
        );
        for (i, series) in self.series.iter().enumerate() {
            let [cr, cg, cb] = distinct_color(i);
            let colour = format!("rgb({cr},{cg},{cb})");
            let pts: Vec<String> = series
                .points
                .iter()
                .map(|&(x, y)| {
                    let (px, py) = map(x, y);
                    format!("{px:.1},{py:.1}")
                })
                .collect();
            let _ = writeln!(
                s,
                r#"<polyline points="{}" fill="none" stroke="{colour}" stroke-width="2"/>"#,
                pts.join(" ")
            );
            for p in &pts {
                let (cx, cy) = p.split_once(',').expect("formatted as x,y");
                let _ = writeln!(s, r#"<circle cx="{cx}" cy="{cy}" r="3" fill="{colour}"/>"#);
            }
            let ly = t + 10.0 + 20.0 * i as f64;
            let _ = writeln!(
                s,
                r#"<line x1="{}" y1="{ly}" x2="{}" y2="{ly}" stroke="{colour}" stroke-width="3"/><text x="{}" y="{}">{}</text>"#,
                r + 15.0,
                r + 40.0,
                r + 46.0,
                ly + 4.0,
                escape(&series.name)
            );
        }
        s.push_str("</svg>\n");
        s
    }
}

/// Room for `s` in the legend: 8 pixels a character, more than sans-serif at 12 px needs.
fn legend_text_width(s: &str) -> i64 {
    s.chars().count() as i64 * 8
}

#[cfg(test)]
mod tests {
    use super::*;

    fn plot() -> LinePlot {
        LinePlot {
            title: "demo".into(),
            x_label: "clicks".into(),
            y_label: "mean IoU".into(),
            y_range: (0.0, 1.0),
            series: vec![
                Series {
                    name: "hash+freq".into(),
                    points: vec![(0.0, 0.2), (5.0, 0.4), (10.0, 0.55)],
                },
                Series {
                    name: "a<b".into(),
                    points: vec![(0.0, 0.1), (10.0, 0.9)],
                },
            ],
        }
    }

    #[test]
    fn ticks_are_nice_and_cover_the_range() {
        assert_eq!(nice_ticks(0.0, 1.0, 5), vec![0.0, 0.2, 0.4, 0.6, 0.8, 1.0]);
        assert_eq!(nice_ticks(0.0, 100.0, 8), vec![0.0, 20.0, 40.0, 60.0, 80.0, 100.0]);
        assert_eq!(nice_ticks(0.0, 47.0, 8), vec![0.0, 10.0, 20.0, 30.0, 40.0, 50.0]);
        assert_eq!(nice_ticks(0.0, 0.0, 8), vec![0.0, 0.2, 0.4, 0.6, 0.8, 1.0]);
        assert_eq!(tick_label(0.2), "0.2");
        assert_eq!(tick_label(40.0), "40");
    }

    #[test]
    fn svg_has_a_line_per_series_a_legend_and_escapes_text() {
        let svg = plot().to_svg();
        assert_eq!(svg.matches("<polyline").count(), 2);
        assert!(svg.contains(">hash+freq</text>"));
        assert!(svg.contains("a&lt;b"));
        // The point (10, 0.55) lands at the right edge of the plot area (x ticks 0..10).
        assert!(svg.contains(&format!("{:.1},", AREA.2)), "{svg}");
        assert!(svg.trim_end().ends_with("</svg>"));
    }

    #[test]
    fn long_legend_names_widen_the_figure_to_fit() {
        let mut p = plot();
        assert_eq!(p.width(), WIDTH);
        p.series[1].name = "freq-only+features(efficientnet-lite0)".into();
        let w = p.width();
        // The legend's text starts 46 px right of the plot area, 8 px a character.
        assert_eq!(w, AREA.2 as u32 + 46 + 8 * p.series[1].name.len() as u32 + 12);
        assert!(p.to_svg().contains(&format!("width=\"{w}\"")));
    }
}
