//! A GSD file writer (HOOMD-blue's trajectory format, read by OVITO, freud, MDAnalysis and
//! the `gsd` Python package), enough to stream frames: chunks are appended as they come,
//! and the namelist, the index and the header are written when the file is finished. The
//! file is written to a hidden temporary next to it (`npy`'s, removed on an interrupt) and
//! renamed into place at [`GsdFile::finish`]: a run that fails leaves no half-written file.
//!
//! The layout (GSD 2.0, `gsd.c`): a 256-byte header (magic, the index's and the namelist's
//! locations and sizes, schema and file versions, application and schema names), chunks of
//! data anywhere, an index of 32-byte entries (frame, N, location, M, name id, type, flags)
//! sorted by frame then name id, and a namelist: the names packed, each ending in a NUL,
//! in blocks of 64 bytes (a name's id is its place).
//! Schema `hoomd` 1.4: `configuration/step`, `configuration/dimensions`,
//! `configuration/box`, `particles/N`, `particles/position`, `particles/velocity`, and
//! `log/...` for anything else (per-particle values under `log/particles/`).

use std::fs::File;
use std::io::{BufWriter, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};

const MAGIC: u64 = 0x65DF_65DF_65DF_65DF;
const HEADER_BYTES: u64 = 256;
const NAME_BYTES: usize = 64;

/// Element types of a chunk (gsd.h's numbering).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum GsdType {
    U8 = 1,
    U32 = 3,
    U64 = 4,
    /// Characters, as HOOMD's `particles/types` (one NUL-padded name per row).
    I8 = 5,
    F32 = 9,
    F64 = 10,
}

impl GsdType {
    fn size(self) -> u64 {
        element_size(self as u8).expect("a GSD type")
    }
}

/// Bytes per element of a type code in gsd.h's numbering (1 to 11: u8, u16, u32, u64,
/// i8, i16, i32, i64, float, double, character), None for another code.
fn element_size(code: u8) -> Option<u64> {
    match code {
        1 | 5 | 11 => Some(1),
        2 | 6 => Some(2),
        3 | 7 | 9 => Some(4),
        4 | 8 | 10 => Some(8),
        _ => None,
    }
}

pub fn version(major: u32, minor: u32) -> u32 {
    (major << 16) | minor
}

struct IndexEntry {
    frame: u64,
    n: u64,
    location: u64,
    m: u32,
    id: u16,
    ty: GsdType,
}

/// A GSD file being written, frame by frame.
pub struct GsdFile {
    path: PathBuf,
    temporary: PathBuf,
    out: BufWriter<File>,
    schema: String,
    schema_version: u32,
    at: u64,
    names: Vec<String>,
    index: Vec<IndexEntry>,
    frame: u64,
    frame_names: Vec<u16>,
}

impl GsdFile {
    /// Starts a HOOMD-schema file for `path` (written to a temporary until finished).
    pub fn create(path: &Path) -> std::io::Result<GsdFile> {
        GsdFile::create_with_schema(path, "hoomd", version(1, 4))
    }

    /// Starts a file of another schema (name at most 63 bytes, version major << 16 |
    /// minor).
    pub fn create_with_schema(
        path: &Path,
        schema: &str,
        schema_version: u32,
    ) -> std::io::Result<GsdFile> {
        if schema.is_empty() || schema.len() >= NAME_BYTES {
            return Err(std::io::Error::new(
                std::io::ErrorKind::InvalidInput,
                format!("GSD schema name `{schema}`: 1 to 63 bytes"),
            ));
        }
        let (temporary, file) = crate::npy::create_temporary(path)?;
        let mut out = BufWriter::new(file);
        // The header is written last; its place is kept.
        out.write_all(&[0u8; HEADER_BYTES as usize])?;
        Ok(GsdFile {
            path: path.to_path_buf(),
            temporary,
            out,
            schema: schema.to_string(),
            schema_version,
            at: HEADER_BYTES,
            names: Vec::new(),
            index: Vec::new(),
            frame: 0,
            frame_names: Vec::new(),
        })
    }

    /// Appends one chunk of the current frame: `n` rows of `m` elements of `ty`, `bytes`
    /// little-endian. A name at most once per frame.
    pub fn chunk(
        &mut self,
        name: &str,
        ty: GsdType,
        n: u64,
        m: u32,
        bytes: &[u8],
    ) -> std::io::Result<()> {
        let invalid = |what: String| std::io::Error::new(std::io::ErrorKind::InvalidInput, what);
        if name.is_empty() || name.len() >= NAME_BYTES {
            return Err(invalid(format!(
                "GSD chunk name `{name}`: 1 to {} bytes",
                NAME_BYTES - 1
            )));
        }
        if n * m as u64 * ty.size() != bytes.len() as u64 || m == 0 {
            return Err(invalid(format!(
                "GSD chunk `{name}`: {} bytes for {n} x {m} elements of {} bytes",
                bytes.len(),
                ty.size()
            )));
        }
        let id = match self.names.iter().position(|s| s == name) {
            Some(i) => i,
            None => {
                if self.names.len() >= u16::MAX as usize {
                    return Err(invalid("GSD: too many chunk names".into()));
                }
                self.names.push(name.to_string());
                self.names.len() - 1
            }
        } as u16;
        if self.frame_names.contains(&id) {
            return Err(invalid(format!(
                "GSD chunk `{name}` twice in frame {}",
                self.frame
            )));
        }
        self.frame_names.push(id);
        self.out.write_all(bytes)?;
        self.index.push(IndexEntry {
            frame: self.frame,
            n,
            location: self.at,
            m,
            id,
            ty,
        });
        self.at += bytes.len() as u64;
        Ok(())
    }

    /// How many frames are ended (the current frame's index).
    pub fn frames_ended(&self) -> u64 {
        self.frame
    }

    /// Ends the current frame (the next chunks belong to the next).
    pub fn end_frame(&mut self) {
        self.frame += 1;
        self.frame_names.clear();
    }

    /// Writes the namelist, the index and the header, syncs the file to disk and renames
    /// it into place.
    pub fn finish(mut self) -> std::io::Result<PathBuf> {
        if !self.frame_names.is_empty() {
            self.end_frame();
        }
        // Sorted by frame, then name id, as the readers' binary search needs.
        self.index.sort_by_key(|e| (e.frame, e.id));
        // GSD 2's namelist: the names packed, each ending in a NUL, then NULs to a whole
        // number of 64-byte entries (an empty name ends the list; the last byte is NUL).
        let namelist_location = self.at;
        let mut namelist: Vec<u8> = Vec::new();
        for name in &self.names {
            namelist.extend_from_slice(name.as_bytes());
            namelist.push(0);
        }
        let namelist_entries = (namelist.len() as u64 + 1).div_ceil(NAME_BYTES as u64);
        namelist.resize(namelist_entries as usize * NAME_BYTES, 0);
        self.out.write_all(&namelist)?;
        self.at += namelist.len() as u64;
        let index_location = self.at;
        let index_entries = (self.index.len() as u64).max(1);
        for e in &self.index {
            let mut entry = [0u8; 32];
            entry[0..8].copy_from_slice(&e.frame.to_le_bytes());
            entry[8..16].copy_from_slice(&e.n.to_le_bytes());
            entry[16..24].copy_from_slice(&(e.location as i64).to_le_bytes());
            entry[24..28].copy_from_slice(&e.m.to_le_bytes());
            entry[28..30].copy_from_slice(&e.id.to_le_bytes());
            entry[30] = e.ty as u8;
            self.out.write_all(&entry)?;
        }
        if self.index.is_empty() {
            self.out.write_all(&[0u8; 32])?;
        }
        let mut header = [0u8; HEADER_BYTES as usize];
        header[0..8].copy_from_slice(&MAGIC.to_le_bytes());
        header[8..16].copy_from_slice(&index_location.to_le_bytes());
        header[16..24].copy_from_slice(&index_entries.to_le_bytes());
        header[24..32].copy_from_slice(&namelist_location.to_le_bytes());
        header[32..40].copy_from_slice(&namelist_entries.to_le_bytes());
        header[40..44].copy_from_slice(&self.schema_version.to_le_bytes());
        header[44..48].copy_from_slice(&version(2, 0).to_le_bytes());
        let application = format!("mesoflow {}", env!("CARGO_PKG_VERSION"));
        header[48..48 + application.len()].copy_from_slice(application.as_bytes());
        header[112..112 + self.schema.len()].copy_from_slice(self.schema.as_bytes());
        self.out.seek(SeekFrom::Start(0))?;
        self.out.write_all(&header)?;
        self.out.flush()?;
        self.out.get_ref().sync_all()?;
        crate::npy::finish_temporary(&self.temporary, &self.path)?;
        Ok(self.path.clone())
    }
}

impl Drop for GsdFile {
    /// A file dropped unfinished (an error on the way) leaves nothing behind.
    fn drop(&mut self) {
        crate::npy::abandon_temporary(&self.temporary);
    }
}

/// A GSD file read back: its schema and every chunk's place, for [`GsdRead::chunk`].
pub struct GsdRead {
    bytes: Vec<u8>,
    pub schema: String,
    /// The index in its order (frame, then name id: the order of first use): (frame,
    /// name, type, N, M, location).
    chunks: Vec<(u64, String, u8, u64, u32, u64)>,
}

impl GsdRead {
    /// Reads and checks a GSD 2 file written by [`GsdFile`] (or by the `gsd` package).
    pub fn open(path: &Path) -> Result<GsdRead, String> {
        let bytes = std::fs::read(path).map_err(|e| format!("{}: {e}", path.display()))?;
        let corrupt = |what: &str| format!("{}: not a GSD file ({what})", path.display());
        let u64_at = |at: usize| -> Option<u64> {
            Some(u64::from_le_bytes(bytes.get(at..at + 8)?.try_into().ok()?))
        };
        if bytes.len() < HEADER_BYTES as usize || u64_at(0) != Some(MAGIC) {
            return Err(corrupt("no GSD header"));
        }
        let gsd_version = u32::from_le_bytes(bytes[44..48].try_into().expect("4 bytes"));
        if gsd_version >> 16 != 2 {
            return Err(corrupt(&format!("file version {}", gsd_version >> 16)));
        }
        let text = |b: &[u8]| {
            String::from_utf8_lossy(b.split(|&c| c == 0).next().unwrap_or(&[])).to_string()
        };
        let schema = text(&bytes[112..176]);
        let field = |at: usize| {
            u64_at(at)
                .map(|v| v as usize)
                .ok_or_else(|| corrupt("header"))
        };
        let (index, entries) = (field(8)?, field(16)?);
        let (namelist, name_entries) = (field(24)?, field(32)?);
        let names_end = name_entries
            .checked_mul(NAME_BYTES)
            .and_then(|n| n.checked_add(namelist))
            .filter(|&e| e <= bytes.len())
            .ok_or_else(|| corrupt("namelist"))?;
        let names: Vec<String> = bytes[namelist..names_end]
            .split(|&c| c == 0)
            .take_while(|n| !n.is_empty())
            .map(|n| String::from_utf8_lossy(n).to_string())
            .collect();
        let index_end = entries
            .checked_mul(32)
            .and_then(|n| n.checked_add(index))
            .filter(|&e| e <= bytes.len())
            .ok_or_else(|| corrupt("index"))?;
        let mut chunks = Vec::new();
        for e in bytes[index..index_end].chunks_exact(32) {
            let location = u64::from_le_bytes(e[16..24].try_into().expect("8 bytes"));
            if location == 0 {
                break;
            }
            let frame = u64::from_le_bytes(e[0..8].try_into().expect("8 bytes"));
            let n = u64::from_le_bytes(e[8..16].try_into().expect("8 bytes"));
            let m = u32::from_le_bytes(e[24..28].try_into().expect("4 bytes"));
            let id = u16::from_le_bytes([e[28], e[29]]) as usize;
            let name = names.get(id).ok_or_else(|| corrupt("a chunk's name"))?;
            chunks.push((frame, name.clone(), e[30], n, m, location));
        }
        Ok(GsdRead {
            bytes,
            schema,
            chunks,
        })
    }

    /// A chunk's bytes, with its N and M; None where the frame has no such chunk or it
    /// lies outside the file.
    pub fn chunk(&self, frame: u64, name: &str) -> Option<(u64, u32, &[u8])> {
        let &(_, _, ty, n, m, location) =
            self.chunks.iter().find(|c| c.0 == frame && c.1 == name)?;
        let len = n.checked_mul(m as u64)?.checked_mul(element_size(ty)?)?;
        let end = location.checked_add(len)?;
        let bytes = self.bytes.get(location as usize..end as usize)?;
        Some((n, m, bytes))
    }

    /// The names of a frame's chunks, in the order they were first used in the file.
    pub fn names(&self, frame: u64) -> Vec<&str> {
        self.chunks
            .iter()
            .filter(|c| c.0 == frame)
            .map(|c| c.1.as_str())
            .collect()
    }
}

/// Little-endian bytes of f32 values.
pub fn f32_bytes(v: &[f32]) -> Vec<u8> {
    v.iter().flat_map(|x| x.to_le_bytes()).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn u64_at(b: &[u8], at: usize) -> u64 {
        u64::from_le_bytes(b[at..at + 8].try_into().unwrap())
    }

    /// The file's structure, read back by hand: header, namelist, index sorted by frame
    /// and id, chunks where the index says. (tests/python's test_gsd.py reads it with the
    /// `gsd` package.)
    #[test]
    fn frames_round_trip_through_the_index() {
        let dir = std::env::temp_dir().join(format!("mesoflow-gsd-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("t.gsd");
        let mut f = GsdFile::create(&path).unwrap();
        for frame in 0..3u64 {
            f.chunk(
                "configuration/step",
                GsdType::U64,
                1,
                1,
                &(frame * 10).to_le_bytes(),
            )
            .unwrap();
            let x: Vec<f32> = (0..6).map(|i| (frame * 6 + i) as f32).collect();
            f.chunk("particles/position", GsdType::F32, 2, 3, &f32_bytes(&x))
                .unwrap();
            assert!(
                f.chunk("particles/position", GsdType::F32, 2, 3, &f32_bytes(&x))
                    .is_err()
            );
            f.end_frame();
        }
        assert!(f.chunk("bad", GsdType::F32, 2, 3, &[0u8; 5]).is_err());
        assert!(!path.exists(), "written to a temporary until finished");
        f.finish().unwrap();
        let b = std::fs::read(&path).unwrap();
        assert_eq!(u64_at(&b, 0), MAGIC);
        let (index, entries) = (u64_at(&b, 8) as usize, u64_at(&b, 16) as usize);
        let namelist = u64_at(&b, 24) as usize;
        assert_eq!(entries, 6);
        assert_eq!(
            &b[namelist..namelist + 38],
            b"configuration/step\0particles/position\0"
        );
        assert_eq!(b[namelist + 38], 0, "an empty name ends the list");
        assert_eq!(&b[112..117], b"hoomd");
        for k in 0..entries {
            let e = &b[index + 32 * k..index + 32 * (k + 1)];
            let (frame, id) = (u64_at(e, 0), u16::from_le_bytes([e[28], e[29]]));
            assert_eq!((frame, id), ((k / 2) as u64, (k % 2) as u16));
            let at = u64_at(e, 16) as usize;
            if id == 1 {
                assert_eq!(u64_at(e, 8), 2);
                let first = f32::from_le_bytes(b[at..at + 4].try_into().unwrap());
                assert_eq!(first, (frame * 6) as f32);
            } else {
                assert_eq!(u64_at(&b, at), frame * 10);
            }
        }
        let read = GsdRead::open(&path).unwrap();
        assert_eq!(read.schema, "hoomd");
        let (n, m, bytes) = read.chunk(2, "particles/position").unwrap();
        assert_eq!((n, m, bytes.len()), (2, 3, 24));
        assert_eq!(&bytes[..4], &12f32.to_le_bytes());
        assert!(read.chunk(3, "particles/position").is_none());
        assert_eq!(
            read.names(1),
            vec!["configuration/step", "particles/position"]
        );
        std::fs::write(dir.join("bad.gsd"), b"not a gsd file").unwrap();
        assert!(GsdRead::open(&dir.join("bad.gsd")).is_err());
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
