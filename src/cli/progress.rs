//! A progress bar for long CLI work; hidden when stderr is not a terminal (CI logs stay short).
use indicatif::{ProgressBar, ProgressStyle};

pub fn bar(what: &str) -> ProgressBar {
    let bar = ProgressBar::new(0);
    bar.set_style(
        ProgressStyle::with_template("{msg:>10} [{bar:40}] {pos}/{len} ({eta})")
            .expect("static template is valid")
            .progress_chars("=> "),
    );
    bar.set_message(what.to_string());
    bar
}
