//! Checkpoints: everything a run carries from one step to the next, as bytes, so a run can
//! stop and a later one go on from it bit for bit as if it had not stopped. That is the
//! engine clock (the step index the nodes' random draws are keyed by), both buffers of
//! every state and every persistent node output (records, accumulators); everything else a
//! step reads is rebuilt from the inputs, params and seed, which the caller must give
//! again (the binary checks them: src/cli.rs).

use super::{ExecError, Program};
use crate::plan::BufferRole;

/// A program's carried values after `steps_done` steps, by name.
#[derive(Clone, Debug, PartialEq)]
pub struct Checkpoint {
    pub steps_done: u64,
    pub buffers: Vec<(String, Vec<u8>)>,
}

impl Program<'_> {
    /// The carried buffers, named, in a fixed order.
    fn carried(&self) -> Vec<(String, &wgpu::Buffer)> {
        let mut out = vec![("clock".to_string(), &self.clock)];
        for (s, pair) in self.plan.states.iter().zip(&self.state_buffers) {
            out.push((format!("state.{}.a", s.name), &pair[0]));
            out.push((format!("state.{}.b", s.name), &pair[1]));
        }
        for (i, (b, info)) in self.buffers.iter().zip(&self.plan.buffers).enumerate() {
            if info.role == BufferRole::Persistent {
                out.push((format!("persistent.{i}"), b));
            }
        }
        out
    }

    /// Reads the carried buffers back (after at least one step).
    pub fn checkpoint(&self) -> Result<Checkpoint, ExecError> {
        if self.steps_done == 0 {
            return Err(ExecError::Run(
                "a checkpoint needs at least one step run".into(),
            ));
        }
        let mut buffers = Vec::new();
        for (name, b) in self.carried() {
            buffers.push((name, self.gpu.read_buffer(b, b.size())?));
        }
        Ok(Checkpoint {
            steps_done: self.steps_done,
            buffers,
        })
    }

    /// Starts the program from a checkpoint of the same plan: the prologue as a first run
    /// does, then the carried buffers and the step count as they were; the next
    /// [`Program::run_on`] goes on from there. A checkpoint of another plan (other
    /// buffers or sizes) is refused, naming the first difference.
    pub fn restore(&mut self, cp: &Checkpoint) -> Result<(), ExecError> {
        let carried: Vec<(String, u64)> = self
            .carried()
            .into_iter()
            .map(|(n, b)| (n, b.size()))
            .collect();
        let given: Vec<(String, u64)> = cp
            .buffers
            .iter()
            .map(|(n, b)| (n.clone(), b.len() as u64))
            .collect();
        if carried != given {
            let what = carried
                .iter()
                .zip(&given)
                .find(|(a, b)| a != b)
                .map(|((n, s), (m, t))| format!("{n} of {s} bytes here, {m} of {t} there"))
                .unwrap_or_else(|| {
                    format!(
                        "{} carried buffers here, {} there",
                        carried.len(),
                        given.len()
                    )
                });
            return Err(ExecError::Run(format!(
                "the checkpoint was written by another plan ({what}): give the graph, params, inputs and outputs of the run that wrote it"
            )));
        }
        if cp.steps_done == 0 {
            return Err(ExecError::Run("the checkpoint has no step run".into()));
        }
        self.start()?;
        for ((_, b), (_, bytes)) in self.carried().into_iter().zip(&cp.buffers) {
            self.gpu.queue.write_buffer(b, 0, bytes);
        }
        let idx = self.gpu.queue.submit([]);
        self.gpu.wait(idx)?;
        self.steps_done = cp.steps_done;
        Ok(())
    }
}

/// The GSD schema of checkpoint files.
const SCHEMA: &str = "mesoflow-checkpoint";

impl Checkpoint {
    /// Writes the checkpoint as a GSD file of schema `mesoflow-checkpoint` 1.0, one frame:
    /// `checkpoint/steps_done`, `checkpoint/run` (the caller's description of the run, to
    /// be checked when resuming) and `buffer/NAME` for each carried buffer (bytes).
    /// Written to a temporary and renamed into place.
    pub fn write(&self, path: &std::path::Path, run: &str) -> std::io::Result<()> {
        use crate::gsd::{GsdFile, GsdType, version};
        let mut f = GsdFile::create_with_schema(path, SCHEMA, version(1, 0))?;
        f.chunk(
            "checkpoint/steps_done",
            GsdType::U64,
            1,
            1,
            &self.steps_done.to_le_bytes(),
        )?;
        f.chunk(
            "checkpoint/run",
            GsdType::U8,
            run.len().max(1) as u64,
            1,
            if run.is_empty() { b" " } else { run.as_bytes() },
        )?;
        for (name, bytes) in &self.buffers {
            f.chunk(
                &format!("buffer/{name}"),
                GsdType::U8,
                bytes.len() as u64,
                1,
                bytes,
            )?;
        }
        f.finish().map(|_| ())
    }

    /// Reads a checkpoint file: the checkpoint and the description of its run.
    pub fn read(path: &std::path::Path) -> Result<(Checkpoint, String), String> {
        let f = crate::gsd::GsdRead::open(path)?;
        let bad = |what: &str| format!("{}: not a mesoflow checkpoint ({what})", path.display());
        if f.schema != SCHEMA {
            return Err(bad(&format!("schema `{}`", f.schema)));
        }
        let steps_done = f
            .chunk(0, "checkpoint/steps_done")
            .and_then(|(_, _, b)| Some(u64::from_le_bytes(b.try_into().ok()?)))
            .ok_or_else(|| bad("no step count"))?;
        let run = f
            .chunk(0, "checkpoint/run")
            .map(|(_, _, b)| String::from_utf8_lossy(b).to_string())
            .ok_or_else(|| bad("no run description"))?;
        // The buffers in the order they were written (the index keeps name ids in order
        // of first use, which is the writer's order).
        let mut buffers = Vec::new();
        for name in f.names(0) {
            if let Some(buffer) = name.strip_prefix("buffer/") {
                let (_, _, bytes) = f.chunk(0, name).ok_or_else(|| bad(name))?;
                buffers.push((buffer.to_string(), bytes.to_vec()));
            }
        }
        Ok((
            Checkpoint {
                steps_done,
                buffers,
            },
            run,
        ))
    }
}
