//! `mesoflow run --every K`: outputs written as frames while the run goes on (the run in
//! chunks of K steps, each output read back after each chunk): FILE.gsd a HOOMD-schema GSD
//! trajectory (several outputs may share one), FILE.npy one array of all the frames
//! (frames first). Each file is written to a hidden temporary and renamed into place when
//! the run ends well; a failed run leaves none.

use std::collections::BTreeMap;
use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

use mesoflow::expr::ParamValue;
use mesoflow::graph::Graph;
use mesoflow::gsd::{GsdFile, GsdType, f32_bytes};
use mesoflow::scene::SpeciesTable;
use mesoflow::value::{HostArray, HostData, ValueType};

/// What a trajectory frame takes from the graph: its box and time step, if it has them.
pub struct FrameContext {
    /// [Lx, Ly, Lz]; Lz 0 for a 2-D box (zmax - zmin where the graph has those).
    box_lengths: Option<[f64; 3]>,
    dt: Option<f64>,
    /// A scene's species: written in a GSD file's first frame (particles/types, typeid,
    /// diameter, mass, charge), which by GSD's rule stands for every later frame.
    species: Option<SpeciesTable>,
}

impl FrameContext {
    pub fn of(g: &Graph) -> FrameContext {
        let number = |name: &str| match g.param(name) {
            Some(ParamValue::Number(x)) => Some(*x),
            _ => None,
        };
        let box_lengths = match g.param("box") {
            Some(ParamValue::Numbers(b)) if b.len() == 3 => Some([b[0], b[1], b[2]]),
            Some(ParamValue::Numbers(b)) if b.len() == 2 => {
                let lz = match (number("zmin"), number("zmax")) {
                    (Some(lo), Some(hi)) => hi - lo,
                    _ => 0.0,
                };
                Some([b[0], b[1], lz])
            }
            _ => None,
        };
        FrameContext {
            box_lengths,
            dt: number("dt"),
            species: None,
        }
    }

    pub fn with_species(self, species: Option<SpeciesTable>) -> FrameContext {
        FrameContext { species, ..self }
    }

    /// A box known outside the graph's params (a scene's, bound inside its graph).
    pub fn with_box(self, box_lengths: Option<[f64; 3]>) -> FrameContext {
        FrameContext {
            box_lengths: box_lengths.or(self.box_lengths),
            ..self
        }
    }
}

/// A stream of frames of one or more outputs into one file.
enum Sink {
    Gsd(GsdFile),
    Npy(NpyFrames),
}

/// Every file of a streamed run, with the outputs each takes.
pub struct FrameSinks {
    sinks: Vec<(PathBuf, Vec<String>, Sink)>,
}

impl FrameSinks {
    /// Opens one sink per file (`files`: output name to file), for `frames` frames.
    pub fn open(files: &[(String, PathBuf)], frames: u64) -> Result<FrameSinks, String> {
        let mut sinks: Vec<(PathBuf, Vec<String>, Sink)> = Vec::new();
        for (name, path) in files {
            if let Some(s) = sinks.iter_mut().find(|s| &s.0 == path) {
                s.1.push(name.clone());
                continue;
            }
            let sink = if is_gsd(path) {
                Sink::Gsd(GsdFile::create(path).map_err(|e| io_error(name, path, e))?)
            } else {
                Sink::Npy(NpyFrames::new(path, frames))
            };
            sinks.push((path.clone(), vec![name.clone()], sink));
        }
        Ok(FrameSinks { sinks })
    }

    /// Appends a frame (after `step` steps) to every file.
    pub fn frame(
        &mut self,
        step: u64,
        outputs: &[(String, HostArray)],
        cx: &FrameContext,
    ) -> Result<(), String> {
        let by_name: BTreeMap<&str, &HostArray> =
            outputs.iter().map(|(n, a)| (n.as_str(), a)).collect();
        for (path, names, sink) in &mut self.sinks {
            let arrays: Vec<(&str, &HostArray)> = names
                .iter()
                .filter_map(|n| Some((n.as_str(), *by_name.get(n.as_str())?)))
                .collect();
            let result = match sink {
                Sink::Npy(npy) => match arrays.first() {
                    Some((_, a)) => npy.frame(a),
                    None => Err(std::io::Error::other("the output was not computed")),
                },
                Sink::Gsd(gsd) => gsd_frame(gsd, step, &arrays, cx),
            };
            result.map_err(|e| io_error(&names.join(", "), path, e))?;
        }
        Ok(())
    }

    /// Finishes every file (all frames written) and renames each into place.
    pub fn finish(self) -> Result<Written, String> {
        let mut done = Vec::new();
        for (path, names, sink) in self.sinks {
            let finished = match sink {
                Sink::Gsd(gsd) => gsd.finish().map(|_| ()),
                Sink::Npy(npy) => npy.finish(),
            };
            finished.map_err(|e| io_error(&names.join(", "), &path, e))?;
            done.push((names, path));
        }
        Ok(done)
    }
}

/// The files written, each with the outputs it holds.
pub type Written = Vec<(Vec<String>, PathBuf)>;

/// What the run sends the writer thread.
enum Message {
    Frame(u64, Vec<(String, HostArray)>),
    Finish,
}

/// [`FrameSinks`] on a thread of their own: frames are written while the next steps run.
/// One frame waits at most (a slow disk holds the run back rather than filling memory).
pub struct FrameWriter {
    to_writer: Option<std::sync::mpsc::SyncSender<Message>>,
    thread: Option<std::thread::JoinHandle<Result<Written, String>>>,
}

impl FrameWriter {
    pub fn start(mut sinks: FrameSinks, cx: FrameContext) -> FrameWriter {
        let (to_writer, from_run) = std::sync::mpsc::sync_channel(1);
        let thread = std::thread::spawn(move || {
            for message in from_run {
                match message {
                    Message::Frame(step, outputs) => sinks.frame(step, &outputs, &cx)?,
                    Message::Finish => return sinks.finish(),
                }
            }
            // The run stopped without finishing: the sinks are dropped, their
            // temporaries removed.
            Err("the run stopped before its last frame".into())
        });
        FrameWriter {
            to_writer: Some(to_writer),
            thread: Some(thread),
        }
    }

    /// Queues a frame; false when the writer has stopped on an error.
    pub fn frame(&self, step: u64, outputs: Vec<(String, HostArray)>) -> bool {
        self.to_writer
            .as_ref()
            .is_some_and(|w| w.send(Message::Frame(step, outputs)).is_ok())
    }

    /// Waits for every frame, finishes the files and renames them into place.
    pub fn finish(mut self) -> Result<Written, String> {
        if let Some(w) = self.to_writer.take() {
            let _ = w.send(Message::Finish);
        }
        self.thread
            .take()
            .map_or(Err("the frame writer is gone".into()), |t| {
                t.join()
                    .unwrap_or_else(|_| Err("the frame writer failed".into()))
            })
    }
}

impl Drop for FrameWriter {
    /// A run that failed: the writer stops and removes its temporaries before the
    /// process goes on (to its exit).
    fn drop(&mut self) {
        self.to_writer.take();
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

pub fn is_gsd(path: &Path) -> bool {
    path.extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("gsd"))
}

fn io_error(names: &str, path: &Path, e: std::io::Error) -> String {
    format!("--output {names}: cannot write {}: {e}", path.display())
}

/// Rows and columns of an array as a chunk: particles N x k, anything else 1 x words.
fn rows_cols(a: &HostArray) -> (u64, u32) {
    match a.ty {
        ValueType::Particles { n, k } => (n as u64, k),
        t => (1, t.words() as u32),
    }
}

fn bytes_of(a: &HostArray) -> (GsdType, Vec<u8>) {
    match &a.data {
        HostData::F32(v) => (GsdType::F32, f32_bytes(v)),
        HostData::U32(v) => (
            GsdType::U32,
            v.iter().flat_map(|x| x.to_le_bytes()).collect(),
        ),
    }
}

/// One HOOMD frame: the step, the box, N, `positions` as particles/position and
/// `velocities` as particles/velocity (2-D values with z = 0), every other output under
/// log/ (per-particle ones under log/particles/), and log/time where the graph has `dt`.
fn gsd_frame(
    gsd: &mut GsdFile,
    step: u64,
    arrays: &[(&str, &HostArray)],
    cx: &FrameContext,
) -> std::io::Result<()> {
    gsd.chunk(
        "configuration/step",
        GsdType::U64,
        1,
        1,
        &step.to_le_bytes(),
    )?;
    let planar = arrays
        .iter()
        .any(|(n, a)| *n == "positions" && matches!(a.ty, ValueType::Particles { k: 2, .. }));
    gsd.chunk(
        "configuration/dimensions",
        GsdType::U8,
        1,
        1,
        &[if planar { 2 } else { 3 }],
    )?;
    if let Some([lx, ly, lz]) = cx.box_lengths {
        let b = [
            lx as f32,
            ly as f32,
            if planar { 0.0 } else { lz as f32 },
            0.0,
            0.0,
            0.0,
        ];
        gsd.chunk("configuration/box", GsdType::F32, 6, 1, &f32_bytes(&b))?;
    }
    if let Some(dt) = cx.dt {
        gsd.chunk(
            "log/time",
            GsdType::F64,
            1,
            1,
            &(step as f64 * dt).to_le_bytes(),
        )?;
    }
    if let Some(sp) = cx.species.as_ref().filter(|_| gsd.frames_ended() == 0) {
        let width = sp.names.iter().map(|n| n.len() + 1).max().unwrap_or(1);
        let mut types = vec![0u8; width * sp.names.len()];
        for (i, name) in sp.names.iter().enumerate() {
            types[i * width..i * width + name.len()].copy_from_slice(name.as_bytes());
        }
        let n = sp.typeid.len() as u64;
        gsd.chunk(
            "particles/types",
            GsdType::I8,
            sp.names.len() as u64,
            width as u32,
            &types,
        )?;
        let words: Vec<u8> = sp.typeid.iter().flat_map(|t| t.to_le_bytes()).collect();
        gsd.chunk("particles/typeid", GsdType::U32, n, 1, &words)?;
        gsd.chunk(
            "particles/diameter",
            GsdType::F32,
            n,
            1,
            &f32_bytes(&sp.diameter),
        )?;
        gsd.chunk("particles/mass", GsdType::F32, n, 1, &f32_bytes(&sp.mass))?;
        gsd.chunk(
            "particles/charge",
            GsdType::F32,
            n,
            1,
            &f32_bytes(&sp.charge),
        )?;
    }
    let mut n_written = false;
    for (name, a) in arrays {
        let (rows, cols) = rows_cols(a);
        let particle_vector = matches!(a.ty, ValueType::Particles { k: 2 | 3, .. })
            && matches!(a.data, HostData::F32(_));
        match (*name, particle_vector) {
            ("positions" | "velocities", true) => {
                let HostData::F32(v) = &a.data else {
                    unreachable!("checked")
                };
                let xyz: Vec<f32> = v
                    .chunks_exact(cols as usize)
                    .flat_map(|r| [r[0], r[1], if cols == 3 { r[2] } else { 0.0 }])
                    .collect();
                let chunk = if *name == "positions" {
                    "particles/position"
                } else {
                    "particles/velocity"
                };
                if !n_written {
                    gsd.chunk(
                        "particles/N",
                        GsdType::U32,
                        1,
                        1,
                        &(rows as u32).to_le_bytes(),
                    )?;
                    n_written = true;
                }
                gsd.chunk(chunk, GsdType::F32, rows, 3, &f32_bytes(&xyz))?;
            }
            _ => {
                let (ty, bytes) = bytes_of(a);
                let chunk = if matches!(a.ty, ValueType::Particles { .. }) {
                    format!("log/particles/{name}")
                } else {
                    format!("log/{name}")
                };
                gsd.chunk(&chunk, ty, rows, cols, &bytes)?;
            }
        }
    }
    gsd.end_frame();
    Ok(())
}

/// Frames of one output into an NPY file of shape (frames, ...): the header once the
/// first frame gives the element type and shape, then each frame's values.
struct NpyFrames {
    path: PathBuf,
    frames: u64,
    file: Option<(PathBuf, BufWriter<File>, ValueType)>,
    written: u64,
}

impl NpyFrames {
    fn new(path: &Path, frames: u64) -> NpyFrames {
        NpyFrames {
            path: path.to_path_buf(),
            frames,
            file: None,
            written: 0,
        }
    }

    fn frame(&mut self, a: &HostArray) -> std::io::Result<()> {
        if self.file.is_none() {
            let (tmp, file) = mesoflow::npy::create_temporary(&self.path)?;
            let mut w = BufWriter::new(file);
            let dtype = match a.data {
                HostData::F32(_) => "<f4",
                HostData::U32(_) => "<u4",
            };
            let shape: Vec<String> = std::iter::once(self.frames)
                .chain(a.ty.npy_shape())
                .map(|d| d.to_string())
                .collect();
            let dict = format!(
                "{{'descr': '{dtype}', 'fortran_order': False, 'shape': ({},), }}",
                shape.join(", ")
            );
            // Magic, version 1.0, header length; the header padded with spaces to a
            // multiple of 64 bytes, ending in a newline.
            let unpadded = 10 + dict.len() + 1;
            let padded = unpadded.div_ceil(64) * 64;
            let mut header = dict.into_bytes();
            header.resize(padded - 10 - 1, b' ');
            header.push(b'\n');
            w.write_all(b"\x93NUMPY\x01\x00")?;
            w.write_all(&(header.len() as u16).to_le_bytes())?;
            w.write_all(&header)?;
            self.file = Some((tmp, w, a.ty));
        }
        let Some((_, w, ty)) = &mut self.file else {
            unreachable!("opened above")
        };
        if *ty != a.ty {
            return Err(std::io::Error::other(format!(
                "the output changed shape between frames ({} to {})",
                ty, a.ty
            )));
        }
        match &a.data {
            HostData::F32(v) => v.iter().try_for_each(|x| w.write_all(&x.to_le_bytes()))?,
            HostData::U32(v) => v.iter().try_for_each(|x| w.write_all(&x.to_le_bytes()))?,
        }
        self.written += 1;
        Ok(())
    }

    fn finish(mut self) -> std::io::Result<()> {
        let Some((tmp, mut w, _)) = self.file.take() else {
            return Err(std::io::Error::other("no frame was written"));
        };
        if self.written != self.frames {
            mesoflow::npy::abandon_temporary(&tmp);
            return Err(std::io::Error::other(format!(
                "{} frames written of {}",
                self.written, self.frames
            )));
        }
        w.flush()?;
        w.get_ref().sync_all()?;
        mesoflow::npy::finish_temporary(&tmp, &self.path)
    }
}

impl Drop for NpyFrames {
    /// Unfinished, nothing is left behind.
    fn drop(&mut self) {
        if let Some((tmp, _, _)) = &self.file {
            mesoflow::npy::abandon_temporary(tmp);
        }
    }
}
