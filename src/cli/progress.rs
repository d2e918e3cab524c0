//! Progress bars for long CLI work, with the time left; hidden when stderr is not a terminal
//! (CI logs stay short), where the commands print the time left in their log lines instead.
use std::time::Duration;

use indicatif::{ProgressBar, ProgressStyle};

pub fn bar(what: &str) -> ProgressBar {
    let bar = ProgressBar::new(0);
    bar.set_style(
        ProgressStyle::with_template("{msg:>10} [{bar:40}] {pos}/{len} ({elapsed} so far, ~{eta} left)")
            .expect("static template is valid")
            .progress_chars("=> "),
    );
    bar.set_message(what.to_string());
    bar
}

/// `, ~3 min 10 s left` from the bar's rate so far; empty before the first step or after the last.
pub fn left(bar: &ProgressBar) -> String {
    let (pos, len) = (bar.position(), bar.length().unwrap_or(0));
    if pos == 0 || pos >= len {
        return String::new();
    }
    // The bar's own estimate weighs recent steps; from a log line a plain average reads truer.
    let per_step = bar.elapsed().as_secs_f64() / pos as f64;
    format!(", ~{} left", duration((len - pos) as f64 * per_step))
}

/// The time left for `remaining` units of work at the rate `done` units took `elapsed`; None
/// before any work was done.
pub fn estimate(done: f64, remaining: f64, elapsed: Duration) -> Option<f64> {
    (done > 0.0).then(|| remaining.max(0.0) * elapsed.as_secs_f64() / done)
}

/// A duration as a person reads it: `42 s`, `3 min 10 s`, `2 h 05 min`.
pub fn duration(seconds: f64) -> String {
    let s = seconds.max(0.0).round() as u64;
    match s {
        0..60 => format!("{s} s"),
        60..3600 => format!("{} min {:02} s", s / 60, s % 60),
        _ => format!("{} h {:02} min", s / 3600, (s % 3600) / 60),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn durations_read_plainly() {
        assert_eq!(duration(0.4), "0 s");
        assert_eq!(duration(42.0), "42 s");
        assert_eq!(duration(190.0), "3 min 10 s");
        assert_eq!(duration(7500.0), "2 h 05 min");
    }

    #[test]
    fn time_left_follows_the_rate_so_far() {
        assert_eq!(estimate(0.0, 10.0, Duration::from_secs(5)), None);
        assert_eq!(estimate(10.0, 30.0, Duration::from_secs(20)), Some(60.0));
        let bar = ProgressBar::hidden();
        bar.set_length(10);
        assert_eq!(left(&bar), "");
        bar.set_position(10);
        assert_eq!(left(&bar), "");
        bar.set_position(4);
        assert!(
            left(&bar).starts_with(", ~") && left(&bar).ends_with(" left"),
            "{}",
            left(&bar)
        );
    }
}
