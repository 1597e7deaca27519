//! The node contract: what every node kind declares and implements, and the registry
//! that maps kind names to node factories.
//!
//! A [`NodeKind`] is the factory: a name, a one-line doc, ports and typed params. Given
//! checked params it builds a [`Node`], which infers its output types from its input
//! types at plan time, says how it lowers to GPU work ([`Lowering`]), and carries an f64
//! CPU reference that its tests compare the GPU against.

use std::collections::BTreeMap;
use std::sync::Arc;

use crate::expr::{HostFunction, HostFunctions, ParamValue};
use crate::gpu::{CompileCtx, CompileError, DeviceCaps, Dispatch, NodeIo};
pub use crate::gpu::{NodeDecision, NodePlan};
use crate::transform::{SpectralBody, Transform};
use crate::value::{HostArray, PortType, RefArray, ValueType};

/// One input or output port of a node kind.
#[derive(Clone, Debug)]
pub struct PortSpec {
    pub name: &'static str,
    pub ty: PortType,
    pub doc: &'static str,
    /// Inputs only: the node runs without it (an absent value).
    pub optional: bool,
    /// Outputs only: the value persists across time steps and the node updates it in
    /// place (it starts at zero). Trajectory recorders and running averages use this.
    pub persistent: bool,
    /// The port belongs to an iteration the node drives (see [`GpuIterative`]). An output
    /// so marked takes a new value every iteration: the nodes that depend on it form the
    /// node's loop body. An input so marked closes the loop: the body's result, read
    /// after every iteration. Edges into such an input are not cycles.
    pub iterate: bool,
    /// Outputs only: the node can write this output into the buffer of the named input
    /// (`edge_flip_round`'s `mesh`, which it otherwise copies from its input before
    /// flipping in place). The planner gives the output that buffer where no one reads
    /// the input after the node (`plan/memory.rs` says when), else a buffer of its own.
    /// The node tells which by comparing the two buffers ([`NodeIo::in_place`]) and,
    /// when they are one, skips the copy and binds the buffer once (wgpu refuses a
    /// buffer bound read-only and read-write in one dispatch). Only for nodes that record
    /// their own kernels (`Lowering::Kernels`), and the two ports' types must agree.
    pub in_place_of: Option<&'static str>,
    /// Iterate outputs only: the node's own kernels set this output from the named
    /// iterate input after every run of the body and read it otherwise only after the
    /// last iteration (`repeat`'s `current`, refilled from `next`), and no body runs
    /// past the loop's stop (`IterativeKernels::gpu_stop` gates them off), so the body
    /// may overwrite it: an in-place output in the body may take its buffer. When the
    /// named input is that output (the body's last node writes `next` in place of
    /// `current`), the two share a buffer and the node skips the refill, binding the
    /// buffer once ([`NodeIo::in_place`]).
    pub refilled_from: Option<&'static str>,
    /// Iterate outputs only: the node's `start` kernels set this output from the named
    /// plain input, which the node reads nowhere else (`repeat`'s `current`, from
    /// `initial`). The planner gives the output the input's buffer where that input is
    /// a pooled value nothing reads after the loop starts (not the body, not a later
    /// launch: `plan/memory.rs`); the node, seeing the two buffers equal
    /// ([`NodeIo::in_place`]), skips the copy and binds the buffer once.
    pub started_from: Option<&'static str>,
    /// Plain outputs only: the node's `finish` kernels set this output from the named
    /// iterate output, its value after the last iteration, and nothing else writes it
    /// (`repeat`'s `out`, from `current`). The planner gives the two one buffer where
    /// nothing reads the iterate output after the loop (the output's own where it has
    /// one: a state's next buffer, a requested output's); the node, seeing the buffers
    /// equal ([`NodeIo::same_output`]), skips the copy.
    pub final_of: Option<&'static str>,
}

impl PortSpec {
    pub const fn new(name: &'static str, ty: PortType, doc: &'static str) -> Self {
        PortSpec {
            name,
            ty,
            doc,
            optional: false,
            persistent: false,
            iterate: false,
            in_place_of: None,
            refilled_from: None,
            started_from: None,
            final_of: None,
        }
    }

    pub const fn optional(mut self) -> Self {
        self.optional = true;
        self
    }

    pub const fn persistent(mut self) -> Self {
        self.persistent = true;
        self
    }

    pub const fn iterate(mut self) -> Self {
        self.iterate = true;
        self
    }

    /// An output the node may write into the buffer of its input `input` (see
    /// [`PortSpec::in_place_of`](PortSpec#structfield.in_place_of)).
    pub const fn in_place_of(mut self, input: &'static str) -> Self {
        self.in_place_of = Some(input);
        self
    }

    /// An iterate output the node refills from its iterate input `input` after every run
    /// of the body (see [`PortSpec::refilled_from`](PortSpec#structfield.refilled_from)).
    pub const fn refilled_from(mut self, input: &'static str) -> Self {
        self.refilled_from = Some(input);
        self
    }

    /// An iterate output the node sets from its plain input `input` at the loop's start
    /// (see [`PortSpec::started_from`](PortSpec#structfield.started_from)).
    pub const fn started_from(mut self, input: &'static str) -> Self {
        self.started_from = Some(input);
        self
    }

    /// An output the node sets from its iterate output `output` after the last
    /// iteration (see [`PortSpec::final_of`](PortSpec#structfield.final_of)).
    pub const fn final_of(mut self, output: &'static str) -> Self {
        self.final_of = Some(output);
        self
    }
}

/// The type and valid range of a param.
#[derive(Clone, Debug)]
pub enum ParamKind {
    /// A number in [min, max]; integer-valued when `integer`.
    Number {
        min: f64,
        max: f64,
        integer: bool,
    },
    /// An array of numbers, each in [min, max], of length `len` when given.
    Numbers {
        len: Option<usize>,
        min: f64,
        max: f64,
    },
    /// One of a fixed set of strings.
    Choice(&'static [&'static str]),
    Bool,
}

/// The largest magnitude of a param the kernels compute with in f32 (a factor, a
/// viscosity, a length): about the square root of f32's largest value (3.4e38), so that
/// its product with data of magnitude up to the same bound is still finite in f32.
pub const F32_PARAM_MAX: f64 = 1e18;
/// The smallest magnitude of a positive f32 param (one the kernels also divide by: a
/// viscosity, a radius, a width): the square root of f32's smallest normal value
/// (1.2e-38), so that its reciprocal stays within [`F32_PARAM_MAX`] and its product
/// with data down to the same bound is still a normal f32.
pub const F32_PARAM_MIN: f64 = 1e-18;

/// Why the f32 ranges are what they are, as `mesoflow nodes` prints it under the kinds.
pub const F32_RANGE_NOTE: &str = "Ranges up to 1e18 (and from 1e-18 for params that are also divided by) are where f32 arithmetic is meaningful: f32 holds magnitudes from 1.2e-38 to 3.4e38, so a param within the square root of that range, times or over data within it too, stays a finite, normal f32. A node also checks the coefficients it forms from several params (1/(4 pi^2 viscosity) times box^2, say) against the same range.";

/// Checks a coefficient a node forms from its params for its kernels' f32 arithmetic:
/// zero, or of magnitude in [`F32_PARAM_MIN`], [`F32_PARAM_MAX`]. `what` says how it is
/// formed, naming the params in backticks (the loader then names where each came from).
pub fn check_f32_coefficient(what: &str, x: f64) -> Result<(), String> {
    let m = x.abs();
    if x == 0.0 || (F32_PARAM_MIN..=F32_PARAM_MAX).contains(&m) {
        Ok(())
    } else {
        Err(format!(
            "{what} = {x:.3e} is outside [1e-18, 1e18] in magnitude, where the node's f32 arithmetic is meaningful (f32 holds 1.2e-38 to 3.4e38; see `mesoflow nodes`)"
        ))
    }
}

/// One param of a node kind.
#[derive(Clone, Debug)]
pub struct ParamSpec {
    pub name: &'static str,
    pub kind: ParamKind,
    /// `None`: the graph file must give it.
    pub default: Option<ParamValue>,
    pub doc: &'static str,
}

impl ParamSpec {
    pub fn number(
        name: &'static str,
        default: Option<f64>,
        min: f64,
        max: f64,
        doc: &'static str,
    ) -> Self {
        ParamSpec {
            name,
            kind: ParamKind::Number {
                min,
                max,
                integer: false,
            },
            default: default.map(ParamValue::Number),
            doc,
        }
    }

    /// A number the kernels compute with in f32, of either sign: within
    /// [`F32_PARAM_MAX`] in magnitude.
    pub fn f32_factor(name: &'static str, default: Option<f64>, doc: &'static str) -> Self {
        Self::number(name, default, -F32_PARAM_MAX, F32_PARAM_MAX, doc)
    }

    /// A positive number the kernels compute with in f32 and divide by: in
    /// [[`F32_PARAM_MIN`], [`F32_PARAM_MAX`]].
    pub fn f32_positive(name: &'static str, default: Option<f64>, doc: &'static str) -> Self {
        Self::number(name, default, F32_PARAM_MIN, F32_PARAM_MAX, doc)
    }

    /// A non-negative number the kernels compute with in f32 (0 meaning none): in
    /// [0, [`F32_PARAM_MAX`]].
    pub fn f32_nonnegative(name: &'static str, default: Option<f64>, doc: &'static str) -> Self {
        Self::number(name, default, 0.0, F32_PARAM_MAX, doc)
    }

    pub fn integer(
        name: &'static str,
        default: Option<f64>,
        min: f64,
        max: f64,
        doc: &'static str,
    ) -> Self {
        ParamSpec {
            name,
            kind: ParamKind::Number {
                min,
                max,
                integer: true,
            },
            default: default.map(ParamValue::Number),
            doc,
        }
    }

    pub fn choice(
        name: &'static str,
        default: &'static str,
        choices: &'static [&'static str],
        doc: &'static str,
    ) -> Self {
        ParamSpec {
            name,
            kind: ParamKind::Choice(choices),
            default: Some(ParamValue::Text(default.into())),
            doc,
        }
    }

    pub fn flag(name: &'static str, default: bool, doc: &'static str) -> Self {
        ParamSpec {
            name,
            kind: ParamKind::Bool,
            default: Some(ParamValue::Bool(default)),
            doc,
        }
    }

    /// Checks a value against the spec; the message says what was expected.
    pub fn check(&self, v: &ParamValue) -> Result<(), String> {
        match (&self.kind, v) {
            (ParamKind::Number { min, max, integer }, ParamValue::Number(x)) => {
                if !x.is_finite() {
                    return Err(format!("{x} is not finite"));
                }
                if *integer && x.fract() != 0.0 {
                    return Err(format!("{} is not an integer", fmt_number(*x)));
                }
                if x < min || x > max {
                    return Err(format!("{} {}", fmt_number(*x), out_of_range(*min, *max)));
                }
                Ok(())
            }
            (ParamKind::Numbers { len, min, max }, ParamValue::Numbers(xs)) => {
                if let Some(n) = len
                    && xs.len() != *n
                {
                    return Err(format!("expected {n} numbers, got {}", xs.len()));
                }
                for x in xs {
                    if !x.is_finite() || x < min || x > max {
                        return Err(format!(
                            "element {} {}",
                            fmt_number(*x),
                            out_of_range(*min, *max)
                        ));
                    }
                }
                Ok(())
            }
            (ParamKind::Choice(choices), ParamValue::Text(s)) => {
                if choices.contains(&s.as_str()) {
                    Ok(())
                } else {
                    let hint = nearest(s, choices.iter().copied())
                        .map(|c| format!(" (did you mean \"{c}\"?)"))
                        .unwrap_or_default();
                    Err(format!(
                        "\"{s}\" is not one of {}{hint}",
                        choices.join(", ")
                    ))
                }
            }
            (ParamKind::Bool, ParamValue::Bool(_)) => Ok(()),
            (kind, v) => Err(format!(
                "expected {}, got {}",
                kind_name(kind),
                v.type_name()
            )),
        }
    }

    /// The spec as `mesoflow nodes` prints it.
    pub fn describe(&self) -> String {
        let with_range = |what: String, min: f64, max: f64| match range(min, max) {
            Some(r) => format!("{what} {r}"),
            None => what,
        };
        let kind = match &self.kind {
            ParamKind::Number { min, max, integer } => with_range(
                if *integer { "integer" } else { "number" }.into(),
                *min,
                *max,
            ),
            ParamKind::Numbers { len, min, max } => with_range(
                match len {
                    Some(n) => format!("{n} numbers"),
                    None => "any count of numbers".into(),
                },
                *min,
                *max,
            ),
            ParamKind::Choice(c) => format!("one of {}", c.join(" | ")),
            ParamKind::Bool => "true | false".into(),
        };
        match &self.default {
            Some(ParamValue::Number(x)) => format!("{kind}, default {}", fmt_number(*x)),
            Some(d) => format!("{kind}, default {d}"),
            None => format!("{kind}, required"),
        }
    }
}

/// Whether a bound stands for "no bound": f64::MAX and beyond.
fn unbounded(x: f64) -> bool {
    x.abs() >= 1e300
}

/// Whether a lower bound stands for "positive": above 0 by less than any value a
/// param takes (f64::MIN_POSITIVE).
fn positive(x: f64) -> bool {
    x > 0.0 && x < 1e-300
}

/// A range as people write it: `> 0`, `>= 0`, `<= 1`, `in [1, 10]`; `None` for no bound.
fn range(min: f64, max: f64) -> Option<String> {
    match (unbounded(min), unbounded(max)) {
        (true, true) => None,
        (false, true) if positive(min) => Some("> 0".into()),
        (false, true) => Some(format!(">= {}", fmt_number(min))),
        (true, false) => Some(format!("<= {}", fmt_number(max))),
        (false, false) if positive(min) => Some(format!("in (0, {}]", fmt_number(max))),
        (false, false) => Some(format!("in [{}, {}]", fmt_number(min), fmt_number(max))),
    }
}

/// What is wrong with a value outside `[min, max]`, said with the range as `range` says it.
fn out_of_range(min: f64, max: f64) -> String {
    match (unbounded(min), unbounded(max)) {
        (false, true) if positive(min) => "is not > 0".into(),
        (false, true) => format!("is below the minimum {}", fmt_number(min)),
        (true, false) => format!("is above the maximum {}", fmt_number(max)),
        (false, false) if positive(min) => format!("is outside (0, {}]", fmt_number(max)),
        _ => format!("is outside [{}, {}]", fmt_number(min), fmt_number(max)),
    }
}

// Numbers in messages and ranges as people read them (exponent form beyond 1e15 or
// below 1e-6); defined with the expressions, whose values print the same way.
pub use crate::expr::fmt_number;

fn kind_name(k: &ParamKind) -> &'static str {
    match k {
        ParamKind::Number { integer: true, .. } => "an integer",
        ParamKind::Number { .. } => "a number",
        ParamKind::Numbers { .. } => "an array of numbers",
        ParamKind::Choice(_) => "a string",
        ParamKind::Bool => "a boolean",
    }
}

/// Checked param values of one node, with typed accessors. Every declared param is
/// present (defaults filled in), so accessors only fail on a kind's own coding error.
#[derive(Clone, Debug, Default)]
pub struct Params {
    values: BTreeMap<String, ParamValue>,
}

impl Params {
    pub fn new(values: BTreeMap<String, ParamValue>) -> Self {
        Params { values }
    }

    pub fn iter(&self) -> impl Iterator<Item = (&String, &ParamValue)> {
        self.values.iter()
    }

    pub fn get(&self, name: &str) -> Option<&ParamValue> {
        self.values.get(name)
    }

    pub fn number(&self, name: &str) -> f64 {
        match self.values.get(name) {
            Some(ParamValue::Number(x)) => *x,
            other => panic!("param `{name}` is not a checked number: {other:?}"),
        }
    }

    pub fn numbers(&self, name: &str) -> &[f64] {
        match self.values.get(name) {
            Some(ParamValue::Numbers(x)) => x,
            other => panic!("param `{name}` is not a checked number array: {other:?}"),
        }
    }

    pub fn text(&self, name: &str) -> &str {
        match self.values.get(name) {
            Some(ParamValue::Text(s)) => s,
            other => panic!("param `{name}` is not a checked string: {other:?}"),
        }
    }

    pub fn flag(&self, name: &str) -> bool {
        match self.values.get(name) {
            Some(ParamValue::Bool(b)) => *b,
            other => panic!("param `{name}` is not a checked boolean: {other:?}"),
        }
    }
}

/// Checks raw values against a kind's specs and fills defaults. Returns every problem
/// as (param name, message): those of [`check_param_names`] and the values' own.
pub fn check_params(
    specs: &[ParamSpec],
    raw: &BTreeMap<String, ParamValue>,
) -> Result<Params, Vec<(String, String)>> {
    let mut problems = check_param_names(specs, raw);
    let mut values = BTreeMap::new();
    for spec in specs {
        if let Some(v) = raw.get(spec.name).or(spec.default.as_ref()) {
            match spec.check(v) {
                Ok(()) => {
                    values.insert(spec.name.to_string(), v.clone());
                }
                Err(e) => problems.push((spec.name.to_string(), format!("bad value: {e}"))),
            }
        }
    }
    if problems.is_empty() {
        Ok(Params::new(values))
    } else {
        Err(problems)
    }
}

/// The problems of a node's params that do not depend on their values: names the kind
/// does not take, required params not given. (Whether a value suits its param is the
/// rest of [`check_params`].)
pub fn check_param_names(
    specs: &[ParamSpec],
    raw: &BTreeMap<String, ParamValue>,
) -> Vec<(String, String)> {
    let mut problems = Vec::new();
    for name in raw.keys() {
        if !specs.iter().any(|s| s.name == name) {
            let known: Vec<&str> = specs.iter().map(|s| s.name).collect();
            problems.push((
                name.clone(),
                format!(
                    "unknown param (this kind takes: {})",
                    if known.is_empty() {
                        "none".to_string()
                    } else {
                        known.join(", ")
                    }
                ),
            ));
        }
    }
    for spec in specs {
        if spec.default.is_none() && !raw.contains_key(spec.name) {
            problems.push((spec.name.to_string(), "missing required param".into()));
        }
    }
    problems
}

/// A type error at one port, found while inferring shapes.
#[derive(Clone, Debug, PartialEq)]
pub struct PortError {
    pub port: String,
    pub message: String,
}

impl PortError {
    pub fn new(port: impl Into<String>, message: impl Into<String>) -> Self {
        PortError {
            port: port.into(),
            message: message.into(),
        }
    }
}

/// Output types and scratch needs of a node for given input types, and the node's
/// decision for them.
#[derive(Clone, Debug)]
pub struct Signature {
    pub outputs: Vec<ValueType>,
    /// Scratch buffers in bytes, live only while the node runs; the planner pools them.
    pub scratch: Vec<u64>,
    /// What a node with several strategies chose for these inputs and this adapter (see
    /// [`NodePlan`]): the plan keeps it, `inspect` prints it, compilation reads it.
    pub plan: Option<NodePlan>,
}

impl Signature {
    pub fn outputs(outputs: Vec<ValueType>) -> Self {
        Signature {
            outputs,
            scratch: Vec::new(),
            plan: None,
        }
    }

    pub fn with_scratch(mut self, scratch: Vec<u64>) -> Self {
        self.scratch = scratch;
        self
    }

    pub fn with_plan(mut self, plan: impl NodeDecision) -> Self {
        self.plan = Some(NodePlan::new(plan));
        self
    }
}

/// An element-wise f32 operation the planner may fuse with its neighbours.
///
/// The body is a WGSL function body returning the output element. It sees its inputs as
/// f32 arguments named after the input ports (scalar-typed inputs are broadcast), `idx`
/// (flat element index, u32), `comp` (component: the column of a particle array, the
/// component of a grid), `step` (the time step, when `uses_step`), and its params as
/// `p0`, `p1`, ... (f32; integer params travel as raw bits, read with `bitcast<u32>`).
#[derive(Clone, Debug, PartialEq)]
pub struct PointwiseBody {
    pub body: String,
    pub params: Vec<f32>,
    /// Shader files whose functions the body calls (`common/philox.wgsl`).
    pub imports: Vec<String>,
    /// The body reads `step`, so the kernel binds the engine clock.
    pub uses_step: bool,
}

/// How a node turns into GPU work.
pub enum Lowering<'a> {
    /// An element-wise body the planner compiles, fused or alone.
    Pointwise(PointwiseBody),
    /// The node records its own dispatches.
    Kernels(&'a dyn GpuKernels),
    /// A spectral operation the planner folds into a transform or runs alone.
    Spectral(SpectralBody),
    /// A transform over grid lines whose passes may host a spectral node
    /// (see [`crate::transform`]).
    Transform(&'a dyn Transform),
    /// The node drives an iteration of its loop body, deciding on the host when to stop.
    Iterative(&'a dyn GpuIterative),
}

/// The GPU side of an iterative node, recorded once per program.
pub struct IterativeKernels {
    /// Before the first iteration (the first value of the node's `iterate` output).
    pub start: Vec<Dispatch>,
    /// After every run of the loop body (the next value of the `iterate` output).
    pub iterate: Vec<Dispatch>,
    /// After the last iteration, once the host has written its answer to `answer`.
    pub finish: Vec<Dispatch>,
    /// What the host reads to decide (`status_bytes` bytes from offset 0).
    pub status: wgpu::Buffer,
    pub status_bytes: u64,
    /// Where the host writes [`Decision::Finish`]'s bytes (from `answer_offset`).
    pub answer: wgpu::Buffer,
    pub answer_offset: u64,
    /// For a loop whose GPU side knows when it has stopped (`repeat`): where in `status`
    /// it says so. The executor then runs the loop in batches of iterations, reading the
    /// status once per batch, and gates the iterations a batch holds past the stop: the
    /// body's and `iterate`'s dispatches go out as indirect dispatches with zero
    /// workgroups (see `exec/run.rs`). `None` where only the host's `decide` knows
    /// (`lanczos`): one status read per iteration.
    pub gpu_stop: Option<GpuStop>,
}

/// The status words of a loop that stops on the GPU (`IterativeKernels::gpu_stop`).
#[derive(Clone, Copy, Debug)]
pub struct GpuStop {
    /// A u32 that `start` sets to 0 and `iterate` sets nonzero at the stop (at the latest
    /// when the iterations reach the node's limit), after which `iterate` changes nothing
    /// and the body's results are read by no one.
    pub stopped_word: u32,
    /// The iterations run before the stop, counted by `iterate`: what `decide` is given.
    pub iterations_word: u32,
    /// A u32 that `start` sets to 0 and `iterate` sets nonzero, with `stopped_word`, where
    /// the loop stopped as `decide` will accept, finishing with an empty answer (its
    /// `finish` needs nothing from the host). The executor chains the rest of a step on
    /// it: what follows the loop runs, in the same submission, only where it is set
    /// (exec/run.rs, `StepChain`).
    pub done_word: u32,
}

/// The host's verdict after reading an iterative node's status.
pub enum Decision {
    /// Run the loop body and `iterate` once more.
    Continue,
    /// Write these bytes to `answer`, run `finish` and leave the loop.
    Finish(Vec<u8>),
}

/// Why an iterative node stopped without an answer.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum LoopError {
    /// What the loop was given cannot be iterated on (a vector that is not finite).
    #[error("{0}")]
    Input(String),
    /// The loop body's operator is not what the node needs (not finite, not positive
    /// definite, singular).
    #[error("{0}")]
    Operator(String),
    /// The stopping rule was not met within the allowed iterations.
    #[error("{0}")]
    NoConvergence(String),
    /// The GPU and the host disagree about the loop: a bug.
    #[error("internal: {0}")]
    Internal(String),
}

/// A node that runs its loop body repeatedly (Lanczos: one operator product per
/// iteration) and decides on the host, from a small status buffer, when to stop. The
/// executor runs the node's `start`, then body + `iterate` until `decide` says finish:
/// one host round trip per decision.
pub trait GpuIterative {
    fn compile(
        &self,
        cx: &mut CompileCtx<'_>,
        io: &NodeIo<'_>,
    ) -> Result<IterativeKernels, CompileError>;

    /// After `iterations` runs of the body, from the status bytes: go on, finish, or stop
    /// with an error that says why (no convergence, an operator that is not positive).
    fn decide(&self, iterations: usize, status: &[u8]) -> Result<Decision, LoopError>;

    /// A loop whose number of iterations is known before it runs (`repeat`): the program
    /// records start, that many runs of the body and `iterate`, and finish, one after the
    /// other, with no status read and no host decision (`decide` is not asked).
    fn fixed_iterations(&self) -> Option<u32> {
        None
    }
}

/// A node that records its own dispatches.
///
/// `compile` may be called more than once for one node (once per state-buffer parity),
/// so it must not keep GPU state of its own that outlives a step: anything that persists
/// belongs in a `persistent` output, which the planner owns.
pub trait GpuKernels {
    fn compile(
        &self,
        cx: &mut CompileCtx<'_>,
        io: &NodeIo<'_>,
    ) -> Result<Vec<Dispatch>, CompileError>;
}

/// Context given to CPU references.
#[derive(Clone, Copy, Debug, Default)]
pub struct RefCtx {
    /// The time step (0 for the first step).
    pub step: u64,
}

/// A row of host data that a node refuses ([`Node::check_input`]): its index and what is
/// wrong with it, the value and the bound it breaks named.
#[derive(Clone, Debug, PartialEq)]
pub struct RowError {
    pub row: usize,
    pub message: String,
}

impl RowError {
    pub fn new(row: usize, message: impl Into<String>) -> Self {
        RowError {
            row,
            message: message.into(),
        }
    }
}

/// Rows of host data a node refuses together ([`Node::check_inputs_together`]): the port
/// and row it blames, and what is wrong (naming the other rows involved).
#[derive(Clone, Debug, PartialEq)]
pub struct PortRowError {
    pub port: usize,
    pub row: usize,
    pub message: String,
}

/// A node instance with checked params.
pub trait Node: Send + Sync {
    /// Output types for the given input types (`None`: an absent optional input) on an
    /// adapter with these capabilities. Inputs already match their ports' [`PortType`]s;
    /// this checks the relations between them. A node with several strategies decides
    /// here, once, and returns its decision in [`Signature::plan`].
    fn infer(
        &self,
        inputs: &[Option<ValueType>],
        caps: &DeviceCaps,
    ) -> Result<Signature, PortError>;

    fn lowering(&self) -> Lowering<'_>;

    /// Decisions the node takes for these input types (a transform's radix plan, a grid
    /// size chosen from a tolerance), one line each, shown by `mesoflow inspect`.
    fn notes(&self, inputs: &[Option<ValueType>]) -> Vec<String> {
        let _ = inputs;
        Vec::new()
    }

    /// `Some(i)` when, for these input types, the output is input `i` unchanged (an `add`
    /// whose optional term is absent): the planner then reads input `i` in its place and
    /// the node does no work.
    fn forwards(&self, inputs: &[Option<ValueType>]) -> Option<usize> {
        let _ = inputs;
        None
    }

    /// `Some(output)` when every row of that output is a row of input `port` unchanged or
    /// a row of zeros (a gather, enabled or not), or that row with the ids it holds
    /// renamed one to one (`relabel` through a table its graph declares a permutation: a
    /// mesh's vertices renumbered with its points): the checks of the nodes that read the
    /// output (or a state it initialises) then apply to the data given for the input
    /// (`Graph::check_input_data`), so that sorting particles does not hide one outside a
    /// wall from the node that refuses it. Default: none.
    fn passes_rows(&self, port: usize) -> Option<usize> {
        let _ = port;
        None
    }

    /// Checks data given from the host for input `port` before it is uploaded: a graph
    /// input wired to the port, or the initial value of a state the port reads
    /// (`Graph::check_input_data`). For what the node's kernels cannot take and no type
    /// says (a particle outside the walls, a NaN velocity): the first row refused. Values
    /// other nodes compute on the GPU are not checked here; those nodes' own contracts
    /// keep them in range. Default: any data.
    fn check_input(&self, port: usize, data: &HostArray) -> Result<(), RowError> {
        let _ = (port, data);
        Ok(())
    }

    /// Whether `check_input` looks at any data: false lets uploads skip holding the data
    /// on the host for it (nodes that check return true).
    fn checks_input(&self) -> bool {
        false
    }

    /// Checks the data given from the host for several input ports together, where one
    /// port's rows are only wrong beside another's (sphere centres with their radii: two
    /// spheres that overlap): `data[port]` is the data given for the port (as for
    /// `check_input`, this upload's or the last one's), `None` where the port reads no
    /// graph input. Runs after every `check_input` passed. The refusal names the port
    /// and row it blames. Default: any data.
    fn check_inputs_together(&self, data: &[Option<&HostArray>]) -> Result<(), PortRowError> {
        let _ = data;
        Ok(())
    }

    /// Whether `check_inputs_together` looks at any data (then the program keeps a host
    /// copy of the inputs it reads, for uploads that give only some of them).
    fn checks_inputs_together(&self) -> bool {
        false
    }

    /// The f64 CPU reference of one evaluation; `outputs` holds the previous contents of
    /// the node's persistent outputs (zeros at the first step).
    fn cpu_reference(&self, inputs: &[Option<RefArray>], outputs: &mut [RefArray], cx: RefCtx);
}

/// Builds a node from checked params; the error names what is wrong with them together.
pub type BuildFn = dyn Fn(&Params) -> Result<Box<dyn Node>, String> + Send + Sync;

/// A node kind: the factory behind a `kind` name in graph files, declared as data (see
/// [`NodeKind::declare`]).
pub struct NodeKind {
    name: &'static str,
    doc: &'static str,
    inputs: Vec<PortSpec>,
    outputs: Vec<PortSpec>,
    params: Vec<ParamSpec>,
    build: Box<BuildFn>,
}

impl NodeKind {
    /// Starts a declaration:
    /// `NodeKind::declare("gather", "doc").input(..).output(..).param(..).build(|p| ..)`.
    /// Ports and params keep the order they are declared in.
    pub fn declare(name: &'static str, doc: &'static str) -> KindDecl {
        KindDecl {
            name,
            doc,
            inputs: Vec::new(),
            outputs: Vec::new(),
            params: Vec::new(),
        }
    }

    pub fn name(&self) -> &'static str {
        self.name
    }

    /// One line, shown by `mesoflow nodes`.
    pub fn doc(&self) -> &'static str {
        self.doc
    }

    pub fn inputs(&self) -> &[PortSpec] {
        &self.inputs
    }

    pub fn outputs(&self) -> &[PortSpec] {
        &self.outputs
    }

    pub fn params(&self) -> &[ParamSpec] {
        &self.params
    }

    /// Builds a node from checked params; the error names what is wrong with them together.
    pub fn build(&self, params: &Params) -> Result<Box<dyn Node>, String> {
        (self.build)(params)
    }
}

/// A [`NodeKind`] being declared: its ports and params so far. [`KindDecl::build`] ends it.
#[must_use = "a declaration is a kind only once `build` gives it its factory"]
pub struct KindDecl {
    name: &'static str,
    doc: &'static str,
    inputs: Vec<PortSpec>,
    outputs: Vec<PortSpec>,
    params: Vec<ParamSpec>,
}

impl KindDecl {
    pub fn input(mut self, port: PortSpec) -> Self {
        self.inputs.push(port);
        self
    }

    pub fn inputs(mut self, ports: impl IntoIterator<Item = PortSpec>) -> Self {
        self.inputs.extend(ports);
        self
    }

    pub fn output(mut self, port: PortSpec) -> Self {
        self.outputs.push(port);
        self
    }

    pub fn outputs(mut self, ports: impl IntoIterator<Item = PortSpec>) -> Self {
        self.outputs.extend(ports);
        self
    }

    pub fn param(mut self, param: ParamSpec) -> Self {
        self.params.push(param);
        self
    }

    pub fn params(mut self, params: impl IntoIterator<Item = ParamSpec>) -> Self {
        self.params.extend(params);
        self
    }

    /// Ends the declaration with the factory that builds a node from checked params.
    pub fn build(
        self,
        build: impl Fn(&Params) -> Result<Box<dyn Node>, String> + Send + Sync + 'static,
    ) -> NodeKind {
        // A port naming an input the kind lacks is a declaration bug, found at start-up.
        for o in &self.outputs {
            let named = |input: &str, iterate: bool| {
                self.inputs
                    .iter()
                    .any(|i| i.name == input && i.iterate == iterate)
            };
            if let Some(i) = o.in_place_of {
                assert!(
                    named(i, false) && !o.iterate && !o.persistent,
                    "kind `{}`: output `{}` in place of `{i}`, not a plain input of it",
                    self.name,
                    o.name
                );
            }
            if let Some(i) = o.refilled_from {
                assert!(
                    named(i, true) && o.iterate,
                    "kind `{}`: output `{}` refilled from `{i}`, not an iterate input of it",
                    self.name,
                    o.name
                );
            }
            if let Some(i) = o.started_from {
                assert!(
                    named(i, false) && o.iterate,
                    "kind `{}`: output `{}` started from `{i}`, not a plain input of it",
                    self.name,
                    o.name
                );
            }
            if let Some(c) = o.final_of {
                assert!(
                    !o.iterate
                        && !o.persistent
                        && self.outputs.iter().any(|p| p.name == c && p.iterate),
                    "kind `{}`: output `{}` the final value of `{c}`, not an iterate output of it",
                    self.name,
                    o.name
                );
            }
        }
        NodeKind {
            name: self.name,
            doc: self.doc,
            inputs: self.inputs,
            outputs: self.outputs,
            params: self.params,
            build: Box::new(build),
        }
    }
}

/// What graph files may name: node kinds by name, and the host functions param
/// expressions may call. The node families fill it (`nodes::registry` for the shipped
/// ones); loading and planning are handed it and know no family.
#[derive(Clone, Default)]
pub struct Registry {
    /// Shared, so that a registry clones cheaply (a kind's factory is not `Clone`).
    kinds: BTreeMap<&'static str, Arc<NodeKind>>,
    functions: HostFunctions,
}

impl Registry {
    /// Adds a host function for param expressions.
    pub fn add_function(&mut self, f: HostFunction) {
        self.functions.add(f);
    }

    pub fn functions(&self) -> &HostFunctions {
        &self.functions
    }

    /// Adds a kind. Two kinds with one name are a programming error.
    pub fn add(&mut self, kind: NodeKind) {
        let name = kind.name();
        let previous = self.kinds.insert(name, Arc::new(kind));
        assert!(previous.is_none(), "node kind `{name}` registered twice");
    }

    pub fn get(&self, name: &str) -> Option<&NodeKind> {
        self.kinds.get(name).map(Arc::as_ref)
    }

    /// The kinds in name order.
    pub fn kinds(&self) -> impl Iterator<Item = &NodeKind> {
        self.kinds.values().map(Arc::as_ref)
    }

    /// Known names closest to `name`, for "did you mean" hints.
    pub fn suggest(&self, name: &str) -> Option<&'static str> {
        nearest(name, self.kinds.keys().copied())
    }
}

/// The candidate closest to a mistyped `name`, for a "did you mean" in an error: within
/// 3 edits (and fewer edits than `name` has letters, so that a short name does not
/// match everything), or one that starts with what was typed (`gauss` for `gaussian`).
pub fn nearest<'a>(name: &str, candidates: impl IntoIterator<Item = &'a str>) -> Option<&'a str> {
    let prefix_of = |c: &str| name.len() >= 3 && c.starts_with(name);
    candidates
        .into_iter()
        .map(|c| (edit_distance(c, name), c))
        .filter(|&(d, c)| (d <= 3 && d < name.chars().count()) || prefix_of(c))
        .min_by_key(|&(d, c)| (!prefix_of(c), d))
        .map(|(_, c)| c)
}

/// Levenshtein distance, for suggestions in error messages.
pub fn edit_distance(a: &str, b: &str) -> usize {
    let b: Vec<char> = b.chars().collect();
    let mut prev: Vec<usize> = (0..=b.len()).collect();
    for (i, ca) in a.chars().enumerate() {
        let mut cur = vec![i + 1; b.len() + 1];
        for (j, cb) in b.iter().enumerate() {
            cur[j + 1] = (prev[j] + usize::from(ca != *cb))
                .min(prev[j + 1] + 1)
                .min(cur[j] + 1);
        }
        prev = cur;
    }
    prev[b.len()]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ranges_read_as_people_write_them() {
        let cases = [
            (f64::MIN_POSITIVE, f64::MAX, "number > 0", "-1 is not > 0"),
            (0.0, f64::MAX, "number >= 0", "-1 is below the minimum 0"),
            (f64::MIN, 2.0, "number <= 2", "3 is above the maximum 2"),
            (1.0, 10.0, "number in [1, 10]", "11 is outside [1, 10]"),
            (
                f64::MIN_POSITIVE,
                0.5,
                "number in (0, 0.5]",
                "1 is outside (0, 0.5]",
            ),
        ];
        for (min, max, shown, refused) in cases {
            let s = ParamSpec::number("x", None, min, max, "");
            assert_eq!(s.describe(), format!("{shown}, required"));
            let bad: f64 = refused.split(' ').next().unwrap().parse().unwrap();
            assert_eq!(s.check(&ParamValue::Number(bad)).unwrap_err(), refused);
        }
        let free = ParamSpec::number("x", Some(f64::MAX), f64::MIN, f64::MAX, "");
        assert_eq!(free.describe(), "number, default 1.7976931348623157e308");
    }

    #[test]
    fn param_checks() {
        let s = ParamSpec::integer("count", Some(3.0), 1.0, 10.0, "");
        assert!(s.check(&ParamValue::Number(4.0)).is_ok());
        assert!(
            s.check(&ParamValue::Number(4.5))
                .unwrap_err()
                .contains("not an integer")
        );
        assert!(
            s.check(&ParamValue::Number(11.0))
                .unwrap_err()
                .contains("outside")
        );
        assert!(
            s.check(&ParamValue::Text("x".into()))
                .unwrap_err()
                .contains("expected an integer")
        );
        let c = ParamSpec::choice("kernel", "gaussian", &["gaussian", "es"], "");
        assert!(
            c.check(&ParamValue::Text("peskin".into()))
                .unwrap_err()
                .contains("not one of")
        );
    }

    #[test]
    fn check_params_reports_all() {
        let specs = vec![
            ParamSpec::number("a", None, 0.0, 1.0, ""),
            ParamSpec::number("b", Some(0.5), 0.0, 1.0, ""),
        ];
        let mut raw = BTreeMap::new();
        raw.insert("b".to_string(), ParamValue::Number(2.0));
        raw.insert("c".to_string(), ParamValue::Number(1.0));
        let errs = check_params(&specs, &raw).unwrap_err();
        let names: Vec<&str> = errs.iter().map(|(n, _)| n.as_str()).collect();
        assert_eq!(names, vec!["c", "a", "b"]);
    }

    /// A kind that refuses to build, naming its param: enough to see the factory run.
    fn test_kind(name: &'static str) -> NodeKind {
        NodeKind::declare(name, "a test kind")
            .input(PortSpec::new("a", PortType::Scalar, ""))
            .inputs([PortSpec::new("b", PortType::Scalar, "").optional()])
            .output(PortSpec::new("out", PortType::Scalar, ""))
            .param(ParamSpec::flag("f", false, ""))
            .params([ParamSpec::number("x", None, 0.0, 1.0, "")])
            .build(|p| Err(format!("x is {}", p.number("x"))))
    }

    #[test]
    fn declarations_keep_their_order() {
        let kind = test_kind("k");
        let names = |ports: &[PortSpec]| ports.iter().map(|p| p.name).collect::<Vec<_>>();
        assert_eq!(names(kind.inputs()), ["a", "b"]);
        assert!(kind.inputs()[1].optional);
        assert_eq!(names(kind.outputs()), ["out"]);
        let params: Vec<&str> = kind.params().iter().map(|p| p.name).collect();
        assert_eq!(params, ["f", "x"]);
        let raw = BTreeMap::from([("x".to_string(), ParamValue::Number(0.5))]);
        let checked = check_params(kind.params(), &raw).unwrap();
        assert_eq!(kind.build(&checked).err().as_deref(), Some("x is 0.5"));
    }

    #[test]
    fn registry_finds_kinds_by_name() {
        let mut r = Registry::default();
        r.add(test_kind("second"));
        r.add(test_kind("first"));
        assert_eq!(r.get("first").map(NodeKind::name), Some("first"));
        assert!(r.get("third").is_none());
        let names: Vec<&str> = r.kinds().map(NodeKind::name).collect();
        assert_eq!(names, ["first", "second"]);
    }

    #[test]
    #[should_panic(expected = "node kind `k` registered twice")]
    fn registering_a_name_twice_panics() {
        let mut r = Registry::default();
        r.add(test_kind("k"));
        r.add(test_kind("k"));
    }

    #[test]
    fn suggestions() {
        assert_eq!(edit_distance("kitten", "sitting"), 3);
        assert_eq!(edit_distance("", "abc"), 3);
        let kernels = ["gaussian", "es", "peskin3", "peskin4", "peskin6"];
        assert_eq!(nearest("gauss", kernels), Some("gaussian"));
        assert_eq!(nearest("peskin5", kernels), Some("peskin3"));
        assert_eq!(nearest("ex", kernels), Some("es"));
        assert_eq!(nearest("x", ["dt", "n"]), None);
        assert_eq!(
            nearest("viscosty", ["viscosity", "radius"]),
            Some("viscosity")
        );
    }
}
