use super::super::pth_writer::{Entry, f32_entry, pickle_checkpoint, to_pth_bytes, zip_checkpoint};
use super::*;

fn message(r: Result<impl Sized, FeatureError>) -> String {
    match r {
        Ok(_) => panic!("expected an error"),
        Err(e) => e.to_string(),
    }
}

fn sample() -> Vec<Entry> {
    vec![
        f32_entry("cls_token", &[1, 1, 3], &[0.5, -1.0, 2.0]),
        f32_entry("blocks.0.attn.qkv.weight", &[2, 3], &[1.0, 2.0, 3.0, 4.0, 5.0, -6.5]),
        f32_entry("norm.bias", &[2], &[7.0, 8.0]),
    ]
}

#[test]
fn a_state_dict_as_torch_saves_it_reads_back() {
    let entries = sample();
    let bytes = zip_checkpoint("archive", &pickle_checkpoint(&entries, None), &entries);
    let p = Pth::from_bytes("w.pth", bytes).unwrap();
    assert_eq!(
        p.names().collect::<Vec<_>>(),
        ["blocks.0.attn.qkv.weight", "cls_token", "norm.bias"]
    );
    assert_eq!(p.location, "at the top");
    assert_eq!(p.shape("cls_token"), Some(&[1, 1, 3][..]));
    assert_eq!(p.f32("cls_token", &[1, 1, 3]).unwrap(), [0.5, -1.0, 2.0]);
    assert_eq!(
        p.f32("blocks.0.attn.qkv.weight", &[2, 3]).unwrap(),
        [1.0, 2.0, 3.0, 4.0, 5.0, -6.5]
    );
    let m = message(p.f32("norm.bias", &[3]));
    assert!(
        m.contains("w.pth") && m.contains("`norm.bias` has shape [2], expected [3]"),
        "{m}"
    );
    let m = message(p.f32("norm.weight", &[2]));
    assert!(m.contains("`norm.weight` missing"), "{m}");
    // torch names the folder after the file since PyTorch 1.6.x; any one folder is accepted.
    let bytes = zip_checkpoint("dino_deitsmall8_pretrain", &pickle_checkpoint(&entries, None), &entries);
    assert_eq!(Pth::from_bytes("w.pth", bytes).unwrap().names().count(), 3);
    // More than 256 memo entries (LONG_BINPUT/LONG_BINGET) and a SETITEMS batch per 1000.
    let many: Vec<Entry> = (0..1100)
        .map(|i| f32_entry(&format!("t{i}"), &[1], &[i as f32]))
        .collect();
    let bytes = zip_checkpoint("archive", &pickle_checkpoint(&many, None), &many);
    let p = Pth::from_bytes("many.pth", bytes).unwrap();
    assert_eq!(p.names().count(), 1100);
    assert_eq!(p.f32("t1099", &[1]).unwrap(), [1099.0]);
}

#[test]
fn a_training_checkpoint_is_unwrapped_and_its_prefixes_dropped() {
    let mut entries = sample();
    for e in &mut entries {
        e.name = format!("module.backbone.{}", e.name);
    }
    entries.push(f32_entry("module.head.last_layer.weight", &[1], &[3.0]));
    for key in ["teacher", "student", "model"] {
        let bytes = zip_checkpoint("archive", &pickle_checkpoint(&entries, Some(key)), &entries);
        let p = Pth::from_bytes("checkpoint.pth", bytes).unwrap();
        assert_eq!(p.location, format!("under `{key}`"));
        assert_eq!(p.f32("cls_token", &[1, 1, 3]).unwrap(), [0.5, -1.0, 2.0]);
        assert_eq!(p.f32("head.last_layer.weight", &[1]).unwrap(), [3.0]);
    }
    let bytes = zip_checkpoint("archive", &pickle_checkpoint(&entries, Some("weights")), &entries);
    let m = message(Pth::from_bytes("checkpoint.pth", bytes));
    assert!(
        m.contains("no state dict") && m.contains("keys: weights, epoch, args"),
        "{m}"
    );
}

#[test]
fn half_double_offsets_and_strides() {
    let mut half = f32_entry("h", &[2], &[0.0, 0.0]);
    half.class = "HalfStorage";
    half.bytes = [1.5f32, -0.25]
        .iter()
        .flat_map(|&v| f16::from_f32(v).to_le_bytes())
        .collect();
    let mut double = f32_entry("d", &[3], &[0.0; 3]);
    double.class = "DoubleStorage";
    double.bytes = [1.0f64, 2.0, 1e-3].iter().flat_map(|v| v.to_le_bytes()).collect();
    // A view of elements 2..4 of a 5-element storage, and a transposed (non-contiguous) view.
    let mut view = f32_entry("v", &[5], &[0.0, 1.0, 2.0, 3.0, 4.0]);
    (view.offset, view.shape, view.stride) = (2, vec![2, 1], vec![1, 7]);
    let mut transposed = f32_entry("t", &[2, 2], &[1.0, 2.0, 3.0, 4.0]);
    transposed.stride = vec![1, 2];
    let mut past = f32_entry("p", &[2], &[1.0, 2.0]);
    past.offset = 1;
    let mut long = f32_entry("l", &[1], &[0.0; 2]);
    (long.class, long.numel) = ("LongStorage", 1);
    let entries = vec![half, double, view, transposed, past, long];
    let p = Pth::from_bytes(
        "w.pth",
        zip_checkpoint("archive", &pickle_checkpoint(&entries, None), &entries),
    )
    .unwrap();
    assert_eq!(p.f32("h", &[2]).unwrap(), [1.5, -0.25]);
    assert_eq!(p.f32("d", &[3]).unwrap(), [1.0, 2.0, 1e-3]);
    assert_eq!(p.f32("v", &[2, 1]).unwrap(), [2.0, 3.0]);
    let m = message(p.f32("t", &[2, 2]));
    assert!(
        m.contains("`t` is not contiguous") && m.contains("stride [1, 2]"),
        "{m}"
    );
    let m = message(p.f32("p", &[2]));
    assert!(m.contains("`p` runs past its storage"), "{m}");
    let m = message(p.f32("l", &[1]));
    assert!(
        m.contains("w.pth") && m.contains("`l` is LongStorage, not a floating-point tensor"),
        "{m}"
    );
}

#[test]
fn bad_files_are_refused_with_the_file_and_the_reason() {
    let m = message(Pth::from_bytes("w.pth", b"not a zip at all".to_vec()));
    assert!(m.contains("w.pth") && m.contains("not a PyTorch checkpoint"), "{m}");
    let m = message(Pth::from_bytes("old.pth", vec![0x80, 0x02, 0x8a, 0x0a, 0x6c, 0xfc]));
    assert!(m.contains("old.pth") && m.contains("legacy format"), "{m}");
    // A zip without data.pkl.
    let m = message(Pth::from_bytes("x.pth", zip_checkpoint("a/b", b".", &[])));
    assert!(m.contains("without `<folder>/data.pkl`"), "{m}");

    // An opcode outside the subset: INST ('i') in place of the first GLOBAL, at byte 2.
    let entries = sample();
    let mut pkl = pickle_checkpoint(&entries, None);
    assert_eq!(pkl[2], b'c');
    pkl[2] = b'i';
    let m = message(Pth::from_bytes("w.pth", zip_checkpoint("archive", &pkl, &entries)));
    assert!(
        m.contains("w.pth") && m.contains("archive/data.pkl byte 2") && m.contains("opcode 0x69 (INST)"),
        "{m}"
    );
    // A pickle cut short.
    let pkl = pickle_checkpoint(&entries, None);
    let m = message(Pth::from_bytes(
        "w.pth",
        zip_checkpoint("archive", &pkl[..pkl.len() / 2], &entries),
    ));
    assert!(m.contains("archive/data.pkl byte") && m.contains("truncated"), "{m}");

    // A storage entry shorter than the pickle says.
    let mut short = sample();
    let pkl = pickle_checkpoint(&short, None);
    short[1].bytes.truncate(20);
    let m = message(Pth::from_bytes("w.pth", zip_checkpoint("archive", &pkl, &short)));
    assert!(
        m.contains("storage `archive/data/1` has 20 bytes") && m.contains("6 float32 values (24 bytes)"),
        "{m}"
    );
    // A storage entry missing altogether.
    let m = message(Pth::from_bytes("w.pth", zip_checkpoint("archive", &pkl, &short[..1])));
    assert!(m.contains("storage entry `archive/data/1` missing"), "{m}");

    // A big-endian checkpoint.
    let mut zip = zip::ZipWriter::new(std::io::Cursor::new(Vec::new()));
    let opts = zip::write::SimpleFileOptions::default();
    for (name, bytes) in [("archive/data.pkl", &pkl[..]), ("archive/byteorder", b"big")] {
        zip.start_file(name, opts).unwrap();
        std::io::Write::write_all(&mut zip, bytes).unwrap();
    }
    let m = message(Pth::from_bytes("be.pth", zip.finish().unwrap().into_inner()));
    assert!(m.contains("byte order `big`"), "{m}");
}

#[test]
fn the_checkpoint_reader_tells_the_formats_apart_by_content() {
    use super::super::checkpoint::Checkpoint;
    let dir = tempfile::tempdir().unwrap();
    let tensors: [(&str, &[usize], &[f32]); 1] = [("a", &[2], &[1.0, 2.0])];
    // A .pth named .safetensors and safetensors files named .bin or .pth all open.
    let pth = dir.path().join("weights.safetensors");
    std::fs::write(&pth, to_pth_bytes(&tensors)).unwrap();
    let st = dir.path().join("weights.bin");
    std::fs::write(&st, crate::safetensors::to_bytes(&tensors)).unwrap();
    let st_pth = dir.path().join("converted.pth");
    std::fs::write(&st_pth, crate::safetensors::to_bytes(&tensors)).unwrap();
    assert!(matches!(Checkpoint::open(&st_pth).unwrap(), Checkpoint::SafeTensors(_)));
    for path in [&pth, &st, &st_pth] {
        let ck = Checkpoint::open(path).unwrap();
        assert_eq!(ck.f32("a", &[2]).unwrap(), [1.0, 2.0]);
    }
    assert!(matches!(Checkpoint::open(&pth).unwrap(), Checkpoint::Pth(_)));
    // A file named .pth that is neither gets the checkpoint reader's explanation.
    let bad = dir.path().join("bad.pth");
    std::fs::write(&bad, b"hello").unwrap();
    let m = message(Checkpoint::open(&bad));
    assert!(m.contains("bad.pth") && m.contains("not a PyTorch checkpoint"), "{m}");
}
