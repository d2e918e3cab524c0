//! A scene archive's content identity: a hash of `scene.json` and of every entry's name, CRC-32
//! and sizes, all read from the zip's central directory. The page keys saved annotations by it
//! rather than by the archive's URL, so a changed archive at the same URL does not get the old
//! labels and a changed query string does not lose them. No entry is decompressed for it: the
//! CRCs the zip already carries stand for the entries' bytes.
//!
//! FNV-1a over 128 bits: not cryptographic (it names a store entry, it signs nothing), but a
//! different archive hashing alike would need colliding CRCs *and* an identical manifest.
use std::io::{Read, Seek};

use zip::ZipArchive;

use super::super::error::{Result, SceneError};

const FNV_OFFSET: u128 = 0x6c62_272e_07bb_0142_62b8_2175_6295_c58d;
const FNV_PRIME: u128 = 0x0000_0000_0100_0000_0000_0000_0000_013b;

struct Fnv128(u128);

impl Fnv128 {
    fn new() -> Fnv128 {
        Fnv128(FNV_OFFSET)
    }

    fn bytes(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.0 ^= u128::from(b);
            self.0 = self.0.wrapping_mul(FNV_PRIME);
        }
    }

    /// A length first, so that ("ab", "c") and ("a", "bc") hash differently.
    fn field(&mut self, bytes: &[u8]) {
        self.bytes(&(bytes.len() as u64).to_le_bytes());
        self.bytes(bytes);
    }
}

/// The content id of an archive whose `scene.json` holds `manifest` (32 hex digits). Entries
/// are taken in name order, so re-zipping the same files in another order keeps the id.
pub fn content_id<R: Read + Seek>(zip: &mut ZipArchive<R>, archive: &str, manifest: &[u8]) -> Result<String> {
    let mut entries = Vec::with_capacity(zip.len());
    for i in 0..zip.len() {
        let entry = zip.by_index_raw(i).map_err(|source| SceneError::Zip {
            file: archive.into(),
            source,
        })?;
        let name = entry
            .name()
            .map_err(|source| SceneError::Zip {
                file: archive.into(),
                source,
            })?
            .to_string();
        entries.push((name, entry.crc32(), entry.size()));
    }
    entries.sort();
    let mut h = Fnv128::new();
    h.field(b"scribblefield-scene-content-1");
    h.field(manifest);
    for (name, crc, size) in &entries {
        h.field(name.as_bytes());
        h.bytes(&crc.to_le_bytes());
        h.bytes(&size.to_le_bytes());
    }
    Ok(format!("{:032x}", h.0))
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::io::{Cursor, Write};

    fn zip_of(files: &[(&str, &[u8])]) -> ZipArchive<Cursor<Vec<u8>>> {
        let mut w = zip::ZipWriter::new(Cursor::new(Vec::new()));
        for (name, data) in files {
            w.start_file(*name, zip::write::SimpleFileOptions::default()).unwrap();
            w.write_all(data).unwrap();
        }
        ZipArchive::new(Cursor::new(w.finish().unwrap().into_inner())).unwrap()
    }

    #[test]
    fn follows_content_not_order() {
        let a = content_id(&mut zip_of(&[("scene.json", b"{}"), ("a.png", b"xy")]), "a", b"{}").unwrap();
        let b = content_id(&mut zip_of(&[("a.png", b"xy"), ("scene.json", b"{}")]), "b", b"{}").unwrap();
        assert_eq!(a, b);
        assert_eq!(a.len(), 32);
        let changed = content_id(&mut zip_of(&[("scene.json", b"{}"), ("a.png", b"xz")]), "c", b"{}").unwrap();
        assert_ne!(a, changed);
        let renamed = content_id(&mut zip_of(&[("scene.json", b"{}"), ("b.png", b"xy")]), "d", b"{}").unwrap();
        assert_ne!(a, renamed);
        let manifest = content_id(&mut zip_of(&[("scene.json", b"{}"), ("a.png", b"xy")]), "e", b"{ }").unwrap();
        assert_ne!(a, manifest);
    }
}
