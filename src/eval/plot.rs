//! A plain line plot (mean IoU against clicks, one line per method) written as SVG by hand and
//! rasterized to a PNG with `image`: axes, ticks with labels, a legend. No plotting crate: the
//! figures are simple and builds are slow on the project's machines.
use std::fmt::Write;

use image::{Rgb, RgbImage};

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
        let longest = self.series.iter().map(|s| text_width(&s.name)).max().unwrap_or(0);
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

    /// The same figure as a PNG-ready image (text in a built-in 3 x 5 pixel font, doubled).
    pub fn to_image(&self) -> RgbImage {
        let mut img = RgbImage::from_pixel(self.width(), HEIGHT, Rgb([255, 255, 255]));
        let map = self.mapper();
        let (l, t, r, b) = AREA;
        let black = Rgb([0, 0, 0]);
        let grid = Rgb([224, 224, 224]);
        for x in self.x_ticks() {
            let (px, _) = map(x, 0.0);
            line(&mut img, (px, t), (px, b), grid, 1);
            let label = tick_label(x);
            text(&mut img, px - text_width(&label) as f64 / 2.0, b + 8.0, &label, black);
        }
        for y in self.y_ticks() {
            let (_, py) = map(0.0, y);
            line(&mut img, (l, py), (r, py), grid, 1);
            let label = tick_label(y);
            text(&mut img, l - 8.0 - text_width(&label) as f64, py - 5.0, &label, black);
        }
        for (a, c) in [((l, t), (r, t)), ((r, t), (r, b)), ((r, b), (l, b)), ((l, b), (l, t))] {
            line(&mut img, a, c, black, 1);
        }
        let centred = |s: &str, y: f64, img: &mut RgbImage| {
            text(img, (l + r) / 2.0 - text_width(s) as f64 / 2.0, y, s, black);
        };
        centred(&self.title, 12.0, &mut img);
        centred(&self.x_label, b + 30.0, &mut img);
        text(&mut img, 4.0, t - 22.0, &self.y_label, black);
        for (i, series) in self.series.iter().enumerate() {
            let colour = Rgb(distinct_color(i));
            let pts: Vec<(f64, f64)> = series.points.iter().map(|&(x, y)| map(x, y)).collect();
            for w in pts.windows(2) {
                line(&mut img, w[0], w[1], colour, 2);
            }
            for &p in &pts {
                dot(&mut img, p, 3, colour);
            }
            let ly = t + 10.0 + 20.0 * i as f64;
            line(&mut img, (r + 15.0, ly), (r + 40.0, ly), colour, 3);
            text(&mut img, r + 46.0, ly - 5.0, &series.name, black);
        }
        img
    }
}

fn put(img: &mut RgbImage, x: i64, y: i64, c: Rgb<u8>) {
    if x >= 0 && y >= 0 && (x as u32) < img.width() && (y as u32) < img.height() {
        img.put_pixel(x as u32, y as u32, c);
    }
}

fn dot(img: &mut RgbImage, (cx, cy): (f64, f64), radius: i64, c: Rgb<u8>) {
    let (cx, cy) = (cx.round() as i64, cy.round() as i64);
    for dy in -radius..=radius {
        for dx in -radius..=radius {
            if dx * dx + dy * dy <= radius * radius {
                put(img, cx + dx, cy + dy, c);
            }
        }
    }
}

/// A line `width` pixels thick: square pens stepped along it, one per pixel of its length.
fn line(img: &mut RgbImage, a: (f64, f64), b: (f64, f64), c: Rgb<u8>, width: i64) {
    let steps = (b.0 - a.0).abs().max((b.1 - a.1).abs()).ceil().max(1.0) as i64;
    let lo = -(width - 1) / 2;
    let hi = width / 2;
    for i in 0..=steps {
        let f = i as f64 / steps as f64;
        let x = (a.0 + f * (b.0 - a.0)).round() as i64;
        let y = (a.1 + f * (b.1 - a.1)).round() as i64;
        for dy in lo..=hi {
            for dx in lo..=hi {
                put(img, x + dx, y + dy, c);
            }
        }
    }
}

/// Scale of the built-in font: each font pixel is a SCALE x SCALE square.
const SCALE: i64 = 2;

fn text_width(s: &str) -> i64 {
    s.chars().count() as i64 * 4 * SCALE
}

/// Draws `s` with its top-left corner at (x, y); characters without a glyph draw as a box.
fn text(img: &mut RgbImage, x: f64, y: f64, s: &str, c: Rgb<u8>) {
    let (x0, y0) = (x.round() as i64, y.round() as i64);
    for (i, ch) in s.chars().enumerate() {
        let rows = glyph(ch);
        for (row, bits) in rows.iter().enumerate() {
            for col in 0..3 {
                if bits & (0b100 >> col) != 0 {
                    for sy in 0..SCALE {
                        for sx in 0..SCALE {
                            put(
                                img,
                                x0 + (i as i64 * 4 + col) * SCALE + sx,
                                y0 + row as i64 * SCALE + sy,
                                c,
                            );
                        }
                    }
                }
            }
        }
    }
}

/// A 3 x 5 glyph: five rows of three bits (most significant bit left). Letters have one case.
fn glyph(ch: char) -> [u8; 5] {
    match ch.to_ascii_lowercase() {
        ' ' => [0, 0, 0, 0, 0],
        '0' => [0b111, 0b101, 0b101, 0b101, 0b111],
        '1' => [0b010, 0b110, 0b010, 0b010, 0b111],
        '2' => [0b111, 0b001, 0b111, 0b100, 0b111],
        '3' => [0b111, 0b001, 0b111, 0b001, 0b111],
        '4' => [0b101, 0b101, 0b111, 0b001, 0b001],
        '5' => [0b111, 0b100, 0b111, 0b001, 0b111],
        '6' => [0b111, 0b100, 0b111, 0b101, 0b111],
        '7' => [0b111, 0b001, 0b010, 0b010, 0b010],
        '8' => [0b111, 0b101, 0b111, 0b101, 0b111],
        '9' => [0b111, 0b101, 0b111, 0b001, 0b111],
        'a' => [0b010, 0b101, 0b111, 0b101, 0b101],
        'b' => [0b110, 0b101, 0b110, 0b101, 0b110],
        'c' => [0b011, 0b100, 0b100, 0b100, 0b011],
        'd' => [0b110, 0b101, 0b101, 0b101, 0b110],
        'e' => [0b111, 0b100, 0b110, 0b100, 0b111],
        'f' => [0b111, 0b100, 0b110, 0b100, 0b100],
        'g' => [0b011, 0b100, 0b101, 0b101, 0b011],
        'h' => [0b101, 0b101, 0b111, 0b101, 0b101],
        'i' => [0b111, 0b010, 0b010, 0b010, 0b111],
        'j' => [0b001, 0b001, 0b001, 0b101, 0b010],
        'k' => [0b101, 0b101, 0b110, 0b101, 0b101],
        'l' => [0b100, 0b100, 0b100, 0b100, 0b111],
        'm' => [0b101, 0b111, 0b111, 0b101, 0b101],
        'n' => [0b110, 0b101, 0b101, 0b101, 0b101],
        'o' => [0b010, 0b101, 0b101, 0b101, 0b010],
        'p' => [0b110, 0b101, 0b110, 0b100, 0b100],
        'q' => [0b010, 0b101, 0b101, 0b110, 0b011],
        'r' => [0b110, 0b101, 0b110, 0b101, 0b101],
        's' => [0b011, 0b100, 0b010, 0b001, 0b110],
        't' => [0b111, 0b010, 0b010, 0b010, 0b010],
        'u' => [0b101, 0b101, 0b101, 0b101, 0b111],
        'v' => [0b101, 0b101, 0b101, 0b101, 0b010],
        'w' => [0b101, 0b101, 0b111, 0b111, 0b101],
        'x' => [0b101, 0b101, 0b010, 0b101, 0b101],
        'y' => [0b101, 0b101, 0b010, 0b010, 0b010],
        'z' => [0b111, 0b001, 0b010, 0b100, 0b111],
        '.' => [0, 0, 0, 0, 0b010],
        ',' => [0, 0, 0, 0b010, 0b100],
        ':' => [0, 0b010, 0, 0b010, 0],
        '-' | '—' => [0, 0, 0b111, 0, 0],
        '+' => [0, 0b010, 0b111, 0b010, 0],
        '_' => [0, 0, 0, 0, 0b111],
        '/' => [0b001, 0b001, 0b010, 0b100, 0b100],
        '%' => [0b101, 0b001, 0b010, 0b100, 0b101],
        '(' => [0b001, 0b010, 0b010, 0b010, 0b001],
        ')' => [0b100, 0b010, 0b010, 0b010, 0b100],
        '=' => [0, 0b111, 0, 0b111, 0],
        '@' => [0b111, 0b101, 0b111, 0b100, 0b111],
        _ => [0b111, 0b101, 0b101, 0b101, 0b111],
    }
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
    fn png_draws_the_series_colours_where_the_data_is() {
        let p = plot();
        let img = p.to_image();
        assert_eq!(img.dimensions(), (WIDTH, HEIGHT));
        let map = p.mapper();
        // The second series ends at (10, 0.9): its colour is drawn there.
        let (x, y) = map(10.0, 0.9);
        assert_eq!(img.get_pixel(x.round() as u32, y.round() as u32).0, distinct_color(1));
        let (x, y) = map(5.0, 0.4);
        assert_eq!(img.get_pixel(x.round() as u32, y.round() as u32).0, distinct_color(0));
        // The axes' corner is black and the legend has both colours.
        assert_eq!(img.get_pixel(AREA.0 as u32, AREA.3 as u32).0, [0, 0, 0]);
        let legend_y = |i: f64| (AREA.1 + 10.0 + 20.0 * i) as u32;
        assert_eq!(img.get_pixel(AREA.2 as u32 + 20, legend_y(0.0)).0, distinct_color(0));
        assert_eq!(img.get_pixel(AREA.2 as u32 + 20, legend_y(1.0)).0, distinct_color(1));
    }

    #[test]
    fn long_legend_names_widen_the_figure_to_fit() {
        let mut p = plot();
        assert_eq!(p.width(), WIDTH);
        p.series[1].name = "freq-only+features(efficientnet-lite0)".into();
        let img = p.to_image();
        assert!(img.width() > WIDTH);
        // The legend's last glyph (")") has ink within the last 24 pixels of the image.
        let (w, h) = img.dimensions();
        let legend_row = (AREA.1 + 30.0) as u32;
        let inked = (w - 24..w)
            .flat_map(|x| (legend_row - 6..legend_row + 6).map(move |y| (x, y)))
            .any(|(x, y)| x < w && y < h && img.get_pixel(x, y).0 == [0, 0, 0]);
        assert!(inked, "legend text does not reach the right part of a {w} px image");
        assert!(p.to_svg().contains(&format!("width=\"{w}\"")));
    }
}
