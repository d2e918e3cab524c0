//! Whole-model tests: finite differences through the full chain, and training on a tiny
//! synthetic scene with Adam.
use glam::{DMat4, DVec3};

use super::gradcheck::{assert_close, central_differences};
use super::loss::RayTarget;
use super::model::{FieldModel, SampledRay, TrainingRay};
use super::sampling::ray_through_pixel;
use super::{Adam, sh};
use crate::field::config::{Encoding, FieldConfig, LastSample, SemanticInput};
use crate::rng::SplitMix64;
use crate::scene::{Bounds, Intrinsics, Pose};

fn unit_box() -> Bounds {
    Bounds {
        min: [0.0; 3],
        max: [1.0; 3],
    }
}

/// The smallest config that still has every part: 2 hash levels (one dense, one hashed),
/// frequencies, hidden layers, geometry feature, 3 classes.
fn tiny_config() -> FieldConfig {
    FieldConfig {
        encoding: Encoding::HashFreq { frequencies: 2 },
        hash_levels: 2,
        log2_hash_table_size: 5,
        hash_base_resolution: 2,
        density_width: 6,
        density_layers: 1,
        geometry_dim: 3,
        color_width: 5,
        color_layers: 1,
        feature_width: 4,
        feature_layers: 1,
        feature_dim: 3,
        semantic_width: 4,
        num_classes: 3,
        samples_coarse: 3,
        samples_fine: 4,
        surface_band_fraction: 0.05,
        ..FieldConfig::default()
    }
}

/// The synthetic scene: an opaque wall at z = 0.6 filling the unit box, red (class 0) where
/// x < 0.5 and blue (class 1) elsewhere, seen by cameras at z = −0.5 looking along +z.
/// Returns a ray through a random pixel and its exact colour, depth, label and code.
fn wall_ray(cfg: &FieldConfig, rng: &mut SplitMix64, labelled: bool) -> TrainingRay {
    let k = Intrinsics {
        fx: 100.0,
        fy: 100.0,
        cx: 50.0,
        cy: 50.0,
    };
    loop {
        let camera = DVec3::new(rng.uniform(0.2, 0.8), rng.uniform(0.2, 0.8), -0.5);
        let pose = Pose(DMat4::from_translation(camera));
        let ray = ray_through_pixel(&k, &pose, rng.uniform(0.0, 100.0), rng.uniform(0.0, 100.0));
        let t_hit = (0.6 - ray.origin[2]) / ray.dir[2];
        let hit = ray.at(t_hit);
        if !(0.02..0.98).contains(&hit[0]) || !(0.02..0.98).contains(&hit[1]) {
            continue;
        }
        let class = usize::from(hit[0] >= 0.5);
        let rgb = [[0.9, 0.2, 0.1], [0.1, 0.3, 0.9]][class];
        let code = (0..cfg.feature_dim)
            .map(|d| {
                if (d as usize + class).is_multiple_of(2) {
                    0.8
                } else {
                    0.1
                }
            })
            .collect();
        let depth = t_hit * ray.z_per_t;
        let jitter: Vec<f32> = (0..cfg.samples_per_ray()).map(|_| rng.next_f32()).collect();
        let samples = SampledRay::new(cfg, &unit_box(), &ray, Some(depth), &jitter);
        let Some(samples) = samples else { continue };
        let target = RayTarget {
            rgb,
            depth: Some(depth),
            label: labelled.then_some(class as u32),
            code: Some(code),
        };
        return TrainingRay { samples, target };
    }
}

#[test]
fn whole_model_gradient_matches_finite_differences() {
    check_whole_model_gradient(tiny_config());
}

#[test]
fn whole_model_gradient_with_geometry_in_the_semantic_head() {
    check_whole_model_gradient(FieldConfig {
        semantic_input: SemanticInput::FeatureAndGeometry,
        ..tiny_config()
    });
}

#[test]
fn whole_model_gradient_with_an_opaque_last_sample_and_the_opacity_term() {
    check_whole_model_gradient_far(
        FieldConfig {
            last_sample: LastSample::Opaque,
            ..tiny_config()
        },
        Some(0),
    );
}

fn check_whole_model_gradient(config: FieldConfig) {
    check_whole_model_gradient_far(config, None);
}

fn check_whole_model_gradient_far(config: FieldConfig, far_class: Option<u32>) {
    let mut model = FieldModel::new(config).unwrap();
    model.far_class = far_class;
    let mut rng = SplitMix64::new(41);
    let mut batch: Vec<TrainingRay> = (0..3).map(|i| wall_ray(&model.config, &mut rng, i != 1)).collect();
    // One ray without depth (uniform samples, no depth term) and one labelled with class 2.
    batch[1].target.depth = None;
    batch[2].target.label = Some(2);
    let mut params: Vec<f64> = model.layout.init(7).into_iter().map(f64::from).collect();
    // Table values of ±1e-4 would make its gradient vanish next to the MLPs'; give it weight.
    for p in &mut params[model.layout.hash_table.clone()] {
        *p = rng.uniform(-0.5, 0.5);
    }

    let mut analytic = vec![0.0; model.layout.total];
    let terms = model.loss_and_gradient(&params, &batch, &mut analytic);
    assert!(
        terms.rgb > 0.0 && terms.depth > 0.0 && terms.semantic > 0.0 && terms.feature > 0.0,
        "{terms:?}"
    );
    assert!((model.loss(&params, &batch).total() - terms.total()).abs() < 1e-12);
    if far_class.is_some() {
        let without = FieldModel {
            far_class: None,
            ..model.clone()
        };
        let plain = without.loss(&params, &batch);
        assert!(terms.semantic > plain.semantic + 1e-9, "{terms:?} against {plain:?}");
    }
    let numeric = central_differences(|p| model.loss(p, &batch).total(), &params, 1e-6);
    for (name, range) in [
        ("model: hash table", model.layout.hash_table.clone()),
        ("model: density mlp", model.layout.density.range()),
        ("model: color mlp", model.layout.color.range()),
        ("model: feature mlp", model.layout.feature.range()),
        ("model: semantic mlp", model.layout.semantic.range()),
    ] {
        assert_close(name, &analytic[range.clone()], &numeric[range], 1e-5);
    }
}

#[test]
fn f32_and_f64_paths_agree() {
    // The GPU is compared with the f32 path; it must be the same computation as the proven one.
    let model = FieldModel::new(tiny_config()).unwrap();
    let mut rng = SplitMix64::new(43);
    let batch: Vec<TrainingRay> = (0..4).map(|_| wall_ray(&model.config, &mut rng, true)).collect();
    let params32 = model.layout.init(9);
    let params64: Vec<f64> = params32.iter().map(|p| f64::from(*p)).collect();
    let mut g32 = vec![0.0f32; model.layout.total];
    let mut g64 = vec![0.0f64; model.layout.total];
    let l32 = model.loss_and_gradient(&params32, &batch, &mut g32).total();
    let l64 = model.loss_and_gradient(&params64, &batch, &mut g64).total();
    assert!((l32 - l64).abs() < 1e-5 * l64.abs().max(1.0), "{l32} vs {l64}");
    let g32: Vec<f64> = g32.into_iter().map(f64::from).collect();
    assert_close("f32 vs f64 gradient", &g32, &g64, 1e-4);
}

#[test]
fn view_direction_encoding_is_fed_to_the_colour_mlp() {
    // Guards the [sh, geometry] input order: changing only the direction changes the colour
    // but not density, features or logits.
    let model = FieldModel::new(tiny_config()).unwrap();
    let params = model.layout.init(3);
    let (mut a, mut b) = ([0.0f32; 16], [0.0f32; 16]);
    sh::encode([0.0, 0.0, 1.0], &mut a);
    sh::encode([0.6, 0.0, 0.8], &mut b);
    let sa = model.forward_sample(&params, [0.3, 0.4, 0.5], &a, 1.0);
    let sb = model.forward_sample(&params, [0.3, 0.4, 0.5], &b, 1.0);
    assert_eq!(sa.sigma, sb.sigma);
    assert_eq!(sa.value[3..], sb.value[3..]);
    assert_ne!(sa.rgb, sb.rgb);
}

#[test]
fn adam_training_fits_the_synthetic_wall() {
    let cfg = FieldConfig {
        hash_levels: 4,
        log2_hash_table_size: 10,
        hash_base_resolution: 4,
        density_width: 16,
        density_layers: 1,
        geometry_dim: 7,
        color_width: 16,
        color_layers: 1,
        feature_width: 16,
        feature_layers: 1,
        feature_dim: 8,
        semantic_width: 16,
        num_classes: 2,
        samples_coarse: 4,
        samples_fine: 8,
        ..FieldConfig::default()
    };
    let model = FieldModel::new(cfg).unwrap();
    let mut rng = SplitMix64::new(51);
    let eval: Vec<TrainingRay> = (0..64).map(|_| wall_ray(&model.config, &mut rng, true)).collect();
    let mut params = model.layout.init(1);
    let mut adam = Adam::new(model.config.adam, model.layout.total);
    let mut grad = vec![0.0f32; model.layout.total];
    let before = model.loss(&params, &eval);
    for _ in 0..200 {
        let batch: Vec<TrainingRay> = (0..24).map(|_| wall_ray(&model.config, &mut rng, true)).collect();
        model.loss_and_gradient(&params, &batch, &mut grad);
        adam.update(&mut params, &grad, 1e-2);
    }
    let after = model.loss(&params, &eval);
    eprintln!(
        "synthetic wall: loss {:.4} -> {:.4} ({before:?} -> {after:?})",
        before.total(),
        after.total()
    );
    assert!(
        after.total() < before.total() / 10.0,
        "loss only went from {before:?} to {after:?}"
    );
    assert!(
        after.semantic < before.semantic / 10.0,
        "semantic loss did not fall: {before:?} -> {after:?}"
    );
}
