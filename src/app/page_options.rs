//! The page's options, from its address fragment (`#scene=...&model=tiny&res=4`), read once
//! when the page starts. Every key is listed in docs/web-app.md ("Page options"). A value that
//! cannot be used is reported ([`PageOptionError`], shown as a notice) and the default is used
//! instead, so a typo never keeps the page from opening. Plain logic: tested natively.
use crate::export::{ExportOptions, Format};
use crate::field::Preset;
use crate::gpu::KernelFamily;
use crate::labels::share::{parse_fragment, percent_decode};
use crate::scene::archive::limits;

/// Everything the address can ask for. `None` (or `false`) where it asks nothing: the page
/// then picks for itself.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PageOptions {
    /// `scene=`: the archive's URL, percent-decoded.
    pub scene: Option<String>,
    /// `labels=`: annotations from a share link (the raw share code).
    pub labels: Option<String>,
    /// `model=tiny|small|budget|full` (`field::Preset`).
    pub model: Option<Preset>,
    /// `res=N`: train and render at 1/N of the frames' resolution (1 to 16).
    pub res: Option<u32>,
    /// `rays=N`: rays per training batch and per render tile.
    pub rays: Option<u32>,
    /// `coarse=N`: the quick first render of a stale mask at 1/N (clamped to 1..=64), even
    /// where it is not quicker than the full one.
    pub coarse: Option<u32>,
    /// `refine=N`: rounds of edge-aware refinement (at most 16).
    pub refine: Option<u32>,
    /// `profile=1`: time a step before training.
    pub profile: bool,
    /// `split=1`: submit each stage of a step on its own.
    pub split: bool,
    /// `kernels=tiled|uniform`.
    pub kernels: Option<KernelFamily>,
    /// `pack-size=N`: a capture packed in the page is downscaled to this longest side
    /// (`pack --max-size`).
    pub pack_size: Option<u32>,
    /// `pack-every=N`: pack every N-th frame (`pack --every`).
    pub pack_every: Option<u32>,
    /// `pack-frames=N`: pack at most N frames (`pack --max-frames`).
    pub pack_frames: Option<u32>,
    /// `pack-stride=N`: baseline feature cells of N x N pixels (`pack --feature-stride`); 0
    /// packs no features.
    pub pack_stride: Option<u32>,
    /// `pack-steps=N`: training steps of the feature autoencoder (`pack --autoencoder-steps`).
    pub pack_steps: Option<u32>,
    /// `bench=PRESET`: no annotator; train this preset on the built-in demo scene as the page
    /// trains and report the figures of `scribblefield bench --json` (`app::bench`).
    pub bench: Option<Preset>,
    /// `bench-steps=N`: timed steps of the bench (after its warm-up).
    pub bench_steps: Option<u32>,
    /// `bench-inflight=N`: training batches the bench keeps in flight (1: wait for each batch
    /// before recording the next, as the page did before it kept two).
    pub bench_inflight: Option<u32>,
    /// `export=voc,coco,ply,apng`: the formats the masks download holds from the start (the
    /// "download also holds" boxes ticked), and `objects=N`: keep the N largest regions of each
    /// class but the first (`export::ExportOptions`).
    pub export: ExportOptions,
}

/// A value in the address the page cannot use; the option keeps its default.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[error("#{key}={value} in the address: expected {expected}; using the default")]
pub struct PageOptionError {
    pub key: &'static str,
    pub value: String,
    pub expected: &'static str,
}

/// Most `res=`: beyond it a frame is a few pixels.
pub const MAX_RES: u32 = 16;

impl PageOptions {
    /// Reads a fragment (the leading `#` optional). Unknown keys are left alone (other pages
    /// or later versions may add some); bad values come back as errors beside the options.
    pub fn parse(fragment: &str) -> (PageOptions, Vec<PageOptionError>) {
        let shared = parse_fragment(fragment);
        let mut options = PageOptions {
            scene: shared.scene,
            labels: shared.labels,
            ..PageOptions::default()
        };
        let mut errors = Vec::new();
        let fragment = fragment.strip_prefix('#').unwrap_or(fragment);
        let mut seen = Vec::new();
        for pair in fragment.split('&') {
            let Some((key, raw)) = pair.split_once('=') else {
                continue;
            };
            // The first occurrence of a key counts.
            if seen.contains(&key) {
                continue;
            }
            seen.push(key);
            let value = percent_decode(raw);
            let mut bad = |key: &'static str, expected: &'static str| {
                errors.push(PageOptionError {
                    key,
                    value: value.clone(),
                    expected,
                })
            };
            match key {
                "model" => match Preset::parse(&value) {
                    Some(m) => options.model = Some(m),
                    None => bad("model", "tiny, small, budget or full"),
                },
                "res" => match value.parse::<u32>() {
                    Ok(n) if (1..=MAX_RES).contains(&n) => options.res = Some(n),
                    _ => bad("res", "a whole number from 1 to 16"),
                },
                "rays" => match value.parse::<u32>() {
                    Ok(n) => options.rays = Some(n),
                    Err(_) => bad("rays", "a whole number of rays"),
                },
                "coarse" => match value.parse::<u32>() {
                    Ok(n) => options.coarse = Some(n.clamp(1, 64)),
                    Err(_) => bad("coarse", "a whole number (1: no quick render)"),
                },
                "refine" => match value.parse::<u32>() {
                    Ok(n) => options.refine = Some(n.min(16)),
                    Err(_) => bad("refine", "a whole number of rounds (0: none)"),
                },
                "profile" => options.profile = value != "0",
                "split" => options.split = value != "0",
                "kernels" => match value.as_str() {
                    "tiled" => options.kernels = Some(KernelFamily::Tiled),
                    "uniform" => options.kernels = Some(KernelFamily::UniformWeights),
                    _ => bad("kernels", "tiled or uniform"),
                },
                "pack-size" => match value.parse::<u32>() {
                    Ok(n) if (8..=limits::MAX_SIDE).contains(&n) => options.pack_size = Some(n),
                    _ => bad("pack-size", "a longest side in pixels, from 8 to 8192"),
                },
                "pack-every" => match value.parse::<u32>() {
                    Ok(n) if n >= 1 => options.pack_every = Some(n),
                    _ => bad("pack-every", "a whole number from 1"),
                },
                "pack-frames" => match value.parse::<u32>() {
                    Ok(n) if n >= 1 => options.pack_frames = Some(n),
                    _ => bad("pack-frames", "a whole number of frames from 1"),
                },
                "pack-stride" => match value.parse::<u32>() {
                    Ok(n) if n <= 64 => options.pack_stride = Some(n),
                    _ => bad("pack-stride", "pixels per feature cell, 1 to 64 (0: no features)"),
                },
                "pack-steps" => match value.parse::<u32>() {
                    Ok(n) if (1..=100_000).contains(&n) => options.pack_steps = Some(n),
                    _ => bad("pack-steps", "autoencoder steps, 1 to 100000"),
                },
                "bench" => match Preset::parse(&value) {
                    Some(p) => options.bench = Some(p),
                    None => bad("bench", "a preset: tiny, small, budget or full"),
                },
                "bench-steps" => match value.parse::<u32>() {
                    Ok(n) if (1..=10_000).contains(&n) => options.bench_steps = Some(n),
                    _ => bad("bench-steps", "timed steps, 1 to 10000"),
                },
                "bench-inflight" => match value.parse::<u32>() {
                    Ok(n) if (1..=2).contains(&n) => options.bench_inflight = Some(n),
                    _ => bad("bench-inflight", "1 or 2 batches in flight"),
                },
                "export" => {
                    let formats: Option<Vec<Format>> = value
                        .split(',')
                        .filter(|name| !name.is_empty())
                        .map(|name| Format::ALL.into_iter().find(|f| f.name() == name))
                        .collect();
                    match formats {
                        Some(formats) => {
                            for f in formats {
                                options.export.set(f, true);
                            }
                        }
                        None => bad("export", "formats among voc, coco and ply, separated by commas"),
                    }
                }
                "objects" => match value.parse::<u32>() {
                    Ok(n) if (1..=255).contains(&n) => options.export.objects = Some(n),
                    _ => bad("objects", "regions kept per class, 1 to 255"),
                },
                _ => {}
            }
        }
        (options, errors)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_empty_fragment_asks_nothing() {
        assert_eq!(PageOptions::parse(""), (PageOptions::default(), vec![]));
        assert_eq!(PageOptions::parse("#"), (PageOptions::default(), vec![]));
    }

    #[test]
    fn reads_every_option() {
        let (o, errors) = PageOptions::parse(
            "#scene=a%20b.zip&labels=xyz&model=tiny&res=4&rays=1200&coarse=4&refine=2&profile=1&split=1&kernels=uniform",
        );
        assert!(errors.is_empty(), "{errors:?}");
        assert_eq!(
            o,
            PageOptions {
                scene: Some("a b.zip".into()),
                labels: Some("xyz".into()),
                model: Some(Preset::Tiny),
                res: Some(4),
                rays: Some(1200),
                coarse: Some(4),
                refine: Some(2),
                profile: true,
                split: true,
                kernels: Some(KernelFamily::UniformWeights),
                ..PageOptions::default()
            }
        );
    }

    #[test]
    fn reads_the_packing_options() {
        let (o, errors) = PageOptions::parse("pack-size=120&pack-every=2&pack-frames=6&pack-stride=0&pack-steps=50");
        assert!(errors.is_empty(), "{errors:?}");
        assert_eq!(
            (o.pack_size, o.pack_every, o.pack_frames, o.pack_stride, o.pack_steps),
            (Some(120), Some(2), Some(6), Some(0), Some(50))
        );
        let (o, errors) = PageOptions::parse("pack-size=4&pack-every=0&pack-steps=x");
        assert_eq!((o.pack_size, o.pack_every, o.pack_steps), (None, None, None));
        let keys: Vec<_> = errors.iter().map(|e| e.key).collect();
        assert_eq!(keys, ["pack-size", "pack-every", "pack-steps"]);
    }

    #[test]
    fn reads_the_bench_options() {
        let (o, errors) = PageOptions::parse("bench=budget&bench-steps=20&bench-inflight=1");
        assert!(errors.is_empty(), "{errors:?}");
        assert_eq!(
            (o.bench, o.bench_steps, o.bench_inflight),
            (Some(Preset::Budget), Some(20), Some(1))
        );
        let (o, errors) = PageOptions::parse("bench=huge&bench-steps=0&bench-inflight=3");
        assert_eq!((o.bench, o.bench_steps, o.bench_inflight), (None, None, None));
        let keys: Vec<_> = errors.iter().map(|e| e.key).collect();
        assert_eq!(keys, ["bench", "bench-steps", "bench-inflight"]);
    }

    #[test]
    fn reads_what_the_download_holds() {
        let (o, errors) = PageOptions::parse("export=voc,coco&objects=2");
        assert!(errors.is_empty(), "{errors:?}");
        assert_eq!(o.export, ExportOptions::with(&[Format::Voc, Format::Coco], Some(2)));
        let (o, errors) = PageOptions::parse("export=voc,png&objects=0");
        assert_eq!(o.export, ExportOptions::default());
        let keys: Vec<_> = errors.iter().map(|e| e.key).collect();
        assert_eq!(keys, ["export", "objects"]);
    }

    #[test]
    fn clamps_as_before() {
        let (o, errors) = PageOptions::parse("coarse=0&refine=99&profile=0&split=0");
        assert!(errors.is_empty());
        assert_eq!(
            (o.coarse, o.refine, o.profile, o.split),
            (Some(1), Some(16), false, false)
        );
        assert_eq!(PageOptions::parse("coarse=1000").0.coarse, Some(64));
    }

    #[test]
    fn a_bad_value_is_named_and_keeps_the_default() {
        let (o, errors) = PageOptions::parse("model=huge&res=0&rays=many&kernels=fast&res=2");
        assert_eq!((o.model, o.res, o.rays, o.kernels), (None, None, None, None));
        let keys: Vec<_> = errors.iter().map(|e| e.key).collect();
        assert_eq!(keys, ["model", "res", "rays", "kernels"]);
        assert_eq!(
            errors[1].to_string(),
            "#res=0 in the address: expected a whole number from 1 to 16; using the default"
        );
        assert_eq!(PageOptions::parse("res=17").1.len(), 1);
    }

    #[test]
    fn unknown_keys_and_bare_words_are_ignored() {
        assert_eq!(
            PageOptions::parse("future=1&profile&model=full"),
            (
                PageOptions {
                    model: Some(Preset::Full),
                    ..PageOptions::default()
                },
                vec![]
            )
        );
    }
}
