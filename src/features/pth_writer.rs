//! Test support: writes checkpoints the way `torch.save` does (PyTorch >= 1.6, pickle protocol
//! 2), opcode for opcode as CPython's `pickle.Pickler` emits them, so that the reader is tested on
//! PyTorch's layout without PyTorch.
use std::collections::HashMap;
use std::io::Write;

use zip::write::SimpleFileOptions;

/// One tensor to save: its storage (class, raw bytes, element count) and its view.
pub struct Entry {
    pub name: String,
    /// `FloatStorage`, `HalfStorage`, `DoubleStorage`, `LongStorage`, ...
    pub class: &'static str,
    pub bytes: Vec<u8>,
    pub numel: usize,
    pub offset: usize,
    pub shape: Vec<usize>,
    pub stride: Vec<usize>,
}

/// A contiguous float32 tensor.
pub fn f32_entry(name: &str, shape: &[usize], values: &[f32]) -> Entry {
    let mut stride = vec![1; shape.len()];
    for i in (0..shape.len().saturating_sub(1)).rev() {
        stride[i] = stride[i + 1] * shape[i + 1];
    }
    Entry {
        name: name.to_string(),
        class: "FloatStorage",
        bytes: values.iter().flat_map(|v| v.to_le_bytes()).collect(),
        numel: values.len(),
        offset: 0,
        shape: shape.to_vec(),
        stride,
    }
}

/// A protocol-2 pickler with CPython's memo behaviour (strings and globals memoised by value,
/// which is what interning gives `torch.save`).
#[derive(Default)]
pub struct Pickler {
    pub out: Vec<u8>,
    memo: HashMap<String, u32>,
    next: u32,
}

impl Pickler {
    fn put(&mut self) {
        if self.next < 256 {
            self.out.extend([b'q', self.next as u8]);
        } else {
            self.out.push(b'r');
            self.out.extend(self.next.to_le_bytes());
        }
        self.next += 1;
    }

    fn remembered(&mut self, key: &str) -> bool {
        match self.memo.get(key) {
            Some(&i) if i < 256 => self.out.extend([b'h', i as u8]),
            Some(&i) => {
                self.out.push(b'j');
                self.out.extend(i.to_le_bytes());
            }
            None => {
                self.memo.insert(key.to_string(), self.next);
                return false;
            }
        }
        true
    }

    pub fn str(&mut self, s: &str) {
        if !self.remembered(&format!("s:{s}")) {
            self.out.push(b'X');
            self.out.extend((s.len() as u32).to_le_bytes());
            self.out.extend(s.as_bytes());
            self.put();
        }
    }

    pub fn global(&mut self, module: &str, name: &str) {
        if !self.remembered(&format!("g:{module}.{name}")) {
            self.out.push(b'c');
            self.out.extend(format!("{module}\n{name}\n").as_bytes());
            self.put();
        }
    }

    pub fn int(&mut self, v: usize) {
        if v < 256 {
            self.out.extend([b'K', v as u8]);
        } else if v < 65536 {
            self.out.push(b'M');
            self.out.extend((v as u16).to_le_bytes());
        } else if v < 1 << 31 {
            self.out.push(b'J');
            self.out.extend((v as i32).to_le_bytes());
        } else {
            self.out.extend([0x8a, 8]);
            self.out.extend((v as u64).to_le_bytes());
        }
    }

    /// A tuple of ints (sizes and strides).
    pub fn int_tuple(&mut self, v: &[usize]) {
        if v.is_empty() {
            self.out.push(b')');
            return;
        }
        if v.len() > 3 {
            self.out.push(b'(');
        }
        v.iter().for_each(|&d| self.int(d));
        self.out.push(match v.len() {
            1 => 0x85,
            2 => 0x86,
            3 => 0x87,
            _ => b't',
        });
        self.put();
    }

    /// `collections.OrderedDict()` as `OrderedDict.__reduce__` pickles it (before its items).
    pub fn ordered_dict(&mut self) {
        self.global("collections", "OrderedDict");
        self.out.push(b')');
        self.out.push(b'R');
        self.put();
    }

    pub fn tensor(&mut self, e: &Entry, key: &str) {
        self.global("torch._utils", "_rebuild_tensor_v2");
        self.out.push(b'(');
        self.out.push(b'(');
        self.str("storage");
        self.global("torch", e.class);
        self.str(key);
        self.str("cpu");
        self.int(e.numel);
        self.out.push(b't');
        self.put();
        self.out.push(b'Q');
        self.int(e.offset);
        self.int_tuple(&e.shape);
        self.int_tuple(&e.stride);
        self.out.push(0x89);
        self.ordered_dict();
        self.out.push(b't');
        self.put();
        self.out.push(b'R');
        self.put();
    }

    /// A state dict (`OrderedDict` with `_metadata`), its storages keyed "0", "1", ...
    pub fn state_dict(&mut self, entries: &[Entry]) {
        self.ordered_dict();
        // CPython batches SETITEMS by 1000.
        for (b, batch) in entries.chunks(1000).enumerate() {
            self.out.push(b'(');
            for (i, e) in batch.iter().enumerate() {
                self.str(&e.name);
                self.tensor(e, &(b * 1000 + i).to_string());
            }
            self.out.push(b'u');
        }
        // state = {'_metadata': OrderedDict([('', {'version': 1})])}, then BUILD.
        self.out.push(b'}');
        self.put();
        self.str("_metadata");
        self.ordered_dict();
        self.str("");
        self.out.push(b'}');
        self.put();
        self.str("version");
        self.int(1);
        self.out.push(b's');
        self.out.push(b's');
        self.out.push(b's');
        self.out.push(b'b');
    }
}

/// The pickle of `entries` as a state dict, optionally nested as a DINO training checkpoint does:
/// `{wrap: state_dict, "epoch": 100, "args": Namespace(...)}` with names prefixed by `prefix`.
pub fn pickle_checkpoint(entries: &[Entry], wrap: Option<&str>) -> Vec<u8> {
    let mut p = Pickler::default();
    p.out.extend([0x80, 2]);
    match wrap {
        None => p.state_dict(entries),
        Some(key) => {
            p.out.push(b'}');
            p.put();
            p.out.push(b'(');
            p.str(key);
            p.state_dict(entries);
            p.str("epoch");
            p.int(100);
            p.str("args");
            // `argparse.Namespace(arch='vit_small')` as protocol 2 pickles an instance.
            p.global("argparse", "Namespace");
            p.out.push(b')');
            p.out.push(0x81);
            p.put();
            p.out.push(b'}');
            p.put();
            p.str("arch");
            p.str("vit_small");
            p.out.push(b's');
            p.out.push(b'b');
            p.out.push(b'u');
        }
    }
    p.out.push(b'.');
    p.out
}

/// A whole `.pth` in `torch.save`'s zip layout, with `pickle` as `data.pkl` and the entries'
/// storages as `data/0`, `data/1`, ... (stored, not compressed, as torch does).
pub fn zip_checkpoint(folder: &str, pickle: &[u8], entries: &[Entry]) -> Vec<u8> {
    let mut zip = zip::ZipWriter::new(std::io::Cursor::new(Vec::new()));
    let stored = SimpleFileOptions::default().compression_method(zip::CompressionMethod::Stored);
    let mut add = |name: String, bytes: &[u8]| {
        zip.start_file(name, stored).expect("zip entry");
        zip.write_all(bytes).expect("zip write");
    };
    add(format!("{folder}/data.pkl"), pickle);
    add(format!("{folder}/byteorder"), b"little");
    for (i, e) in entries.iter().enumerate() {
        add(format!("{folder}/data/{i}"), &e.bytes);
    }
    add(format!("{folder}/version"), b"3\n");
    add(format!("{folder}/.data/serialization_id"), b"1234567890");
    zip.finish().expect("zip finish").into_inner()
}

/// `torch.save(state_dict, ...)` of float32 tensors.
pub fn to_pth_bytes(tensors: &[(&str, &[usize], &[f32])]) -> Vec<u8> {
    let entries: Vec<Entry> = tensors.iter().map(|(n, s, v)| f32_entry(n, s, v)).collect();
    zip_checkpoint("archive", &pickle_checkpoint(&entries, None), &entries)
}
