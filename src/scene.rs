//! Scenes: a simulation described by what it contains (species, particles, box and walls,
//! interactions, hydrodynamics, integrator, what to record), built into the graph that
//! system needs from the library of subgraphs: an integrator of `graphs/lib/integrators/`
//! around a mobility graph and `graphs/lib/forces/interactions.json`, bound through
//! graph-valued params. Nothing here knows a node: a scene is turned into a graph file's
//! text and host arrays (the particles), which load and run like any graph.
//!
//! Schema version 1 (`"scene": 1`), unknown fields refused, every problem reported with
//! its place (`particles[1].species`).

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use indexmap::IndexMap;
use rand::rngs::StdRng;
use rand::{RngExt, SeedableRng};
use serde::Deserialize;
use serde_json::{Value, json};

use crate::graph::{Dim, InputShape};
use crate::value::{HostArray, ValueType};

/// The scene schema this mesoflow reads.
pub const SCENE_VERSION: u32 = 1;

/// Tries at placing one particle at random before a scene is called too dense.
const PLACEMENT_TRIES: usize = 10_000;

/// The most particles a generator places (a scene of more gives them as a file).
const MAX_GENERATED: u64 = 1 << 24;

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct SceneFile {
    scene: u32,
    #[serde(default)]
    doc: String,
    /// [Lx, Ly, Lz], centred at the origin in x and y (and z without walls).
    #[serde(rename = "box")]
    box_lengths: [f64; 3],
    #[serde(default)]
    walls: Option<Walls>,
    species: IndexMap<String, Species>,
    particles: Vec<ParticleSet>,
    #[serde(default)]
    interactions: Interactions,
    #[serde(default)]
    hydrodynamics: Hydrodynamics,
    temperature: f64,
    integrator: Integrator,
    #[serde(default)]
    run: RunSettings,
    #[serde(default)]
    output: Option<Output>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct Walls {
    /// `bottom` (a wall at zmin; zmax closes the domain) or `slit` (walls at both).
    #[serde(rename = "type")]
    kind: String,
    zmin: f64,
    zmax: f64,
    /// The walls' WCA repulsion (by default eps = kT, sigma = the largest radius).
    #[serde(default)]
    repulsion: Option<Lj>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct Species {
    radius: f64,
    #[serde(default = "one")]
    mass: f64,
    #[serde(default)]
    charge: f64,
}

fn one() -> f64 {
    1.0
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct ParticleSet {
    species: String,
    /// An NPY file of positions (N x 3), relative to the scene's folder.
    #[serde(default)]
    positions: Option<String>,
    /// Or this many, placed by `place`.
    #[serde(default)]
    count: Option<u64>,
    /// `random` (uniform, no two closer than the sum of their radii) or `lattice`
    /// (simple cubic, filling the region).
    #[serde(default)]
    place: Option<String>,
    /// Where in z they are placed (within the box or the walls).
    #[serde(default)]
    z: Option<[f64; 2]>,
}

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct Interactions {
    #[serde(default)]
    wca: Option<Lj>,
    /// Lennard-Jones with its attractive tail, truncated at `cutoff` sigma and shifted.
    #[serde(default)]
    lj: Option<LjCut>,
    /// Acceleration of gravity: each particle feels mass * gravity (for Brownian
    /// dynamics, give the buoyant mass).
    #[serde(default)]
    gravity: Option<[f64; 3]>,
    #[serde(default)]
    electrostatics: Option<Electrostatics>,
    #[serde(default)]
    bonds: Option<Bonds>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct Bonds {
    stiffness: f64,
    /// By default the diameter (the chain generator's step).
    #[serde(default)]
    rest_length: Option<f64>,
    /// Bonded pairs by particle index (in the order of `particles`), beside the bonds of
    /// sets placed as chains.
    #[serde(default)]
    pairs: Vec<[u64; 2]>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct Lj {
    #[serde(default)]
    epsilon: Option<f64>,
    #[serde(default)]
    sigma: Option<f64>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct LjCut {
    #[serde(default)]
    epsilon: Option<f64>,
    #[serde(default)]
    sigma: Option<f64>,
    /// In units of sigma (default 2.5).
    #[serde(default)]
    cutoff: Option<f64>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct Electrostatics {
    #[serde(default = "one")]
    permittivity: f64,
    /// The charges' Gaussian width (by default the smallest radius).
    #[serde(default)]
    width: Option<f64>,
    #[serde(default = "default_tolerance")]
    tolerance: f64,
}

fn default_tolerance() -> f64 {
    1e-3
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct Hydrodynamics {
    #[serde(default = "no_model")]
    model: String,
    /// The solvent's viscosity (default 1; not for `mpcd`, whose viscosity follows from
    /// its params).
    #[serde(default)]
    viscosity: Option<f64>,
    /// The mobility's accuracy (default 1e-3; not for `mpcd`).
    #[serde(default)]
    tolerance: Option<f64>,
    /// Further params of the mobility graph (of mpcd_md.json for `mpcd`: cell, density,
    /// angle, thermostat...), bound as they are (checked by it).
    #[serde(default)]
    params: IndexMap<String, Value>,
}

fn no_model() -> String {
    "none".into()
}

impl Default for Hydrodynamics {
    fn default() -> Self {
        Hydrodynamics {
            model: no_model(),
            viscosity: None,
            tolerance: None,
            params: IndexMap::new(),
        }
    }
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct Integrator {
    scheme: String,
    dt: f64,
    /// Langevin: the friction coefficient xi.
    #[serde(default)]
    friction: Option<f64>,
    /// Further params of the integrator graph, bound as they are (checked by it).
    #[serde(default)]
    params: IndexMap<String, Value>,
}

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct RunSettings {
    #[serde(default)]
    steps: Option<u64>,
    #[serde(default)]
    seed: Option<u64>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct Output {
    /// A `.gsd` or `.npy` file (relative to the working folder, as `--output` is).
    file: String,
    /// Steps between frames.
    every: u64,
    /// The outputs recorded (default: positions, and velocities where the integrator
    /// has them).
    #[serde(default)]
    values: Option<Vec<String>>,
}

/// Brownian integrators take a mobility; inertial ones velocities and masses.
const BROWNIAN: [&str; 4] = [
    "euler_maruyama",
    "midpoint",
    "adams_bashforth",
    "leimkuhler",
];
const INERTIAL: [&str; 2] = ["velocity_verlet", "langevin_gjf"];

/// What a scene's species are, per particle, for trajectory files.
#[derive(Clone, Debug, Default)]
pub struct SpeciesTable {
    pub names: Vec<String>,
    pub typeid: Vec<u32>,
    pub diameter: Vec<f32>,
    pub mass: Vec<f32>,
    pub charge: Vec<f32>,
}

/// A scene built: the graph's text, its inputs, and how the scene asks to run it.
#[derive(Debug)]
pub struct CompiledScene {
    /// A graph file's text (schema of `graph::load`).
    pub graph: String,
    pub inputs: BTreeMap<String, HostArray>,
    pub steps: Option<u64>,
    pub seed: Option<u64>,
    /// `(output, file)` pairs and the frame interval.
    pub outputs: Vec<(String, PathBuf)>,
    pub every: Option<u64>,
    pub species: SpeciesTable,
    /// The scene's box, for trajectory frames (its graph binds it inside).
    pub box_lengths: [f64; 3],
}

/// Problems of a scene, each with its place.
#[derive(Debug, thiserror::Error)]
#[error("{}: {}", .file.display(), .problems.join("; "))]
pub struct SceneError {
    pub file: PathBuf,
    pub problems: Vec<String>,
}

/// Whether the file at `path` is a scene (a JSON object with the key `scene`).
pub fn is_scene(path: &Path) -> bool {
    let Ok(text) = std::fs::read_to_string(path) else {
        return false;
    };
    matches!(serde_json::from_str::<Value>(&text), Ok(Value::Object(m)) if m.contains_key("scene"))
}

/// Reads a scene and builds it. `seed` (from the command line) takes the place of the
/// scene's for the placement of generated particles as for the run.
pub fn compile(path: &Path, seed: Option<u64>) -> Result<CompiledScene, SceneError> {
    let fail = |problems: Vec<String>| SceneError {
        file: path.to_path_buf(),
        problems,
    };
    let text =
        std::fs::read_to_string(path).map_err(|e| fail(vec![format!("cannot read: {e}")]))?;
    crate::graph::check_unique_keys(&text).map_err(|e| fail(vec![e.to_string()]))?;
    let scene: SceneFile = serde_json::from_str(&text).map_err(|e| fail(vec![e.to_string()]))?;
    if scene.scene != SCENE_VERSION {
        return Err(fail(vec![format!(
            "scene schema version {} is not supported (this mesoflow reads version {SCENE_VERSION})",
            scene.scene
        )]));
    }
    let folder = path.parent().unwrap_or(Path::new("."));
    let mut b = Builder {
        scene: &scene,
        problems: Vec::new(),
    };
    let built = b.build(folder, seed);
    match built {
        Some(c) if b.problems.is_empty() => Ok(c),
        _ => Err(fail(b.problems)),
    }
}

struct Builder<'s> {
    scene: &'s SceneFile,
    problems: Vec<String>,
}

/// Where particles may be placed: [lo, hi] per axis.
type Region = [[f64; 2]; 3];

impl Builder<'_> {
    fn problem(&mut self, msg: impl Into<String>) {
        self.problems.push(msg.into());
    }

    fn positive(&mut self, place: &str, x: f64) {
        if !(x.is_finite() && x > 0.0) {
            self.problem(format!("{place}: expected a positive number, got {x}"));
        }
    }

    fn build(&mut self, folder: &Path, seed: Option<u64>) -> Option<CompiledScene> {
        let s = self.scene;
        for (i, l) in s.box_lengths.iter().enumerate() {
            self.positive(&format!("box[{i}]"), *l);
        }
        if s.species.is_empty() {
            self.problem("species: none declared");
        }
        for (name, sp) in &s.species {
            self.positive(&format!("species.{name}.radius"), sp.radius);
            self.positive(&format!("species.{name}.mass"), sp.mass);
            if !sp.charge.is_finite() {
                self.problem(format!(
                    "species.{name}.charge: {} is not finite",
                    sp.charge
                ));
            }
        }
        if !(s.temperature.is_finite() && s.temperature >= 0.0) {
            self.problem(format!(
                "temperature: expected a non-negative number, got {}",
                s.temperature
            ));
        }
        self.positive("integrator.dt", s.integrator.dt);
        if let Some(eta) = s.hydrodynamics.viscosity {
            self.positive("hydrodynamics.viscosity", eta);
        }
        if let Some(tol) = s.hydrodynamics.tolerance {
            self.positive("hydrodynamics.tolerance", tol);
        }
        let scheme = s.integrator.scheme.as_str();
        let brownian = BROWNIAN.contains(&scheme);
        let inertial = INERTIAL.contains(&scheme);
        if !brownian && !inertial {
            self.problem(format!(
                "integrator.scheme: unknown `{scheme}` (one of {}, {})",
                BROWNIAN.join(", "),
                INERTIAL.join(", ")
            ));
        }
        let model = s.hydrodynamics.model.as_str();
        const MODELS: [&str; 7] = [
            "none", "fcm", "pse", "rpy_open", "rpy_wall", "dpstokes", "mpcd",
        ];
        if !MODELS.contains(&model) {
            self.problem(format!(
                "hydrodynamics.model: unknown `{model}` (one of {})",
                MODELS.join(", ")
            ));
        }
        let mpcd = model == "mpcd";
        if mpcd {
            // The solute's MD is mpcd_md.json's own velocity Verlet, one step per collision.
            if scheme != "velocity_verlet" {
                self.problem(format!(
                    "integrator.scheme: hydrodynamics.model `mpcd` moves the particles by velocity Verlet between collisions (the solvent is their thermostat): give `velocity_verlet`, not `{scheme}`"
                ));
            }
            for (field, given) in [
                ("viscosity", s.hydrodynamics.viscosity.is_some()),
                ("tolerance", s.hydrodynamics.tolerance.is_some()),
            ] {
                if given {
                    self.problem(format!(
                        "hydrodynamics.{field}: not a param of `mpcd` (its viscosity follows from cell, density, angle and dt; give those in hydrodynamics.params)"
                    ));
                }
            }
            for reserved in ["box", "dt", "temperature", "solute_mass", "walls", "forces"] {
                if s.hydrodynamics.params.contains_key(reserved) {
                    self.problem(format!(
                        "hydrodynamics.params.{reserved}: set by the scene (box, integrator.dt, temperature, the species' mass, walls, interactions)"
                    ));
                }
            }
            let masses: Vec<f64> = s.species.values().map(|sp| sp.mass).collect();
            if masses.iter().any(|&m| m != masses[0]) {
                self.problem(format!(
                    "species: masses {} differ, but the MPCD solute has one mass (mpcd_md.json's solute_mass)",
                    s.species
                        .iter()
                        .map(|(n, sp)| format!("{n} {}", sp.mass))
                        .collect::<Vec<_>>()
                        .join(", ")
                ));
            }
        } else if !brownian && !s.hydrodynamics.params.is_empty() {
            self.problem(format!(
                "hydrodynamics.params: `{scheme}` with hydrodynamics.model `{model}` takes no mobility to give them to"
            ));
        }
        if !mpcd && inertial && model != "none" {
            self.problem(format!(
                "integrator.scheme `{scheme}` is inertial and takes no mobility: hydrodynamics.model must be `none` (or `mpcd`, an explicit solvent), not `{model}`"
            ));
        }
        if scheme == "langevin_gjf" && s.integrator.friction.is_none() {
            self.problem("integrator.friction: `langevin_gjf` needs the friction coefficient xi");
        }
        if scheme != "langevin_gjf" && s.integrator.friction.is_some() {
            self.problem(format!(
                "integrator.friction: only `langevin_gjf` takes a friction, not `{scheme}`"
            ));
        }
        // One hydrodynamic radius: the mobility graphs take one.
        let radii: Vec<f64> = s.species.values().map(|sp| sp.radius).collect();
        let radius = radii.iter().cloned().fold(f64::NAN, f64::max);
        let smallest = radii.iter().cloned().fold(f64::NAN, f64::min);
        if brownian && radii.iter().any(|&r| r != radius) {
            self.problem(format!(
                "species: radii {} differ, but the mobilities take one hydrodynamic radius",
                s.species
                    .iter()
                    .map(|(n, sp)| format!("{n} {}", sp.radius))
                    .collect::<Vec<_>>()
                    .join(", ")
            ));
        }
        let walls = self.walls(model);
        if !self.problems.is_empty() {
            return None;
        }

        // Particles.
        let seed = seed.or(s.run.seed).unwrap_or(0);
        let mut rng = StdRng::seed_from_u64(seed ^ 0x5eed_5ce7e);
        let mut positions: Vec<[f64; 3]> = Vec::new();
        let mut typeid: Vec<u32> = Vec::new();
        let mut bonds: Vec<(u32, u32)> = Vec::new();
        let mut placer = Placer::new(s.box_lengths, walls.is_none(), radius.max(smallest));
        for (i, set) in s.particles.iter().enumerate() {
            let place = format!("particles[{i}]");
            let Some(t) = s.species.get_index_of(&set.species) else {
                self.problem(format!(
                    "{place}.species: no species `{}` (species: {})",
                    set.species,
                    s.species.keys().cloned().collect::<Vec<_>>().join(", ")
                ));
                continue;
            };
            let r = s.species[t].radius;
            let placed = match (&set.positions, set.count) {
                (Some(file), None) => {
                    if set.place.is_some() || set.z.is_some() {
                        self.problem(format!(
                            "{place}: `place` and `z` are for generated particles, not those read from `positions`"
                        ));
                    }
                    let read = self.read_positions(&place, &folder.join(file));
                    for p in read.iter().flatten() {
                        placer.add(*p, r);
                    }
                    read
                }
                (None, Some(count)) => {
                    if count == 0 || count > MAX_GENERATED {
                        self.problem(format!(
                            "{place}.count: {count} is not in 1..={MAX_GENERATED} (give more as a positions file)"
                        ));
                        continue;
                    }
                    let region = self.region(&place, set, r, &walls);
                    let kind = set.place.as_deref().unwrap_or("random");
                    match (region, kind) {
                        (None, _) => None,
                        (Some(region), "random") => {
                            self.place_random(&place, count, r, region, &mut placer, &mut rng)
                        }
                        (Some(region), "chain") => {
                            let Some(b) = &s.interactions.bonds else {
                                self.problem(format!(
                                    "{place}.place: a chain needs interactions.bonds (its stiffness)"
                                ));
                                continue;
                            };
                            let step = b.rest_length.unwrap_or(2.0 * r).max(2.0 * r);
                            let first = positions.len() as u32;
                            let chain = self.place_chain(
                                &place,
                                count,
                                r,
                                step,
                                region,
                                &mut placer,
                                &mut rng,
                            );
                            if chain.is_some() {
                                bonds.extend((1..count as u32).map(|k| (first + k - 1, first + k)));
                            }
                            chain
                        }
                        (Some(region), "lattice") => {
                            let sites = Self::place_lattice(count, region);
                            for p in &sites {
                                placer.add(*p, r);
                            }
                            Some(sites)
                        }
                        (_, other) => {
                            self.problem(format!(
                                "{place}.place: unknown `{other}` (random, lattice or chain)"
                            ));
                            None
                        }
                    }
                }
                _ => {
                    self.problem(format!(
                        "{place}: give either `positions` (an NPY file) or `count` (placed by `place`)"
                    ));
                    None
                }
            };
            if let Some(p) = placed {
                typeid.extend(std::iter::repeat_n(t as u32, p.len()));
                positions.extend(p);
            }
        }
        if positions.is_empty() && self.problems.is_empty() {
            self.problem("particles: the scene holds none");
        }
        if !self.problems.is_empty() {
            return None;
        }
        let n = positions.len() as u32;
        let species_of = |i: usize| &s.species[typeid[i] as usize];
        let mut inputs = BTreeMap::new();
        let particles = |k: u32, v: Vec<f32>| HostArray::f32(ValueType::Particles { n, k }, v);
        inputs.insert(
            "positions".to_string(),
            particles(3, positions.iter().flatten().map(|&x| x as f32).collect()),
        );
        let masses: Vec<f64> = (0..n as usize).map(|i| species_of(i).mass).collect();
        let charged = s.species.values().any(|sp| sp.charge != 0.0);
        if let Some(g) = s.interactions.gravity {
            inputs.insert(
                "external".into(),
                particles(
                    3,
                    masses
                        .iter()
                        .flat_map(|m| g.map(|gi| (m * gi) as f32))
                        .collect(),
                ),
            );
        }
        if s.interactions.electrostatics.is_some() {
            if !charged {
                self.problem(
                    "interactions.electrostatics: no species carries a charge (leave electrostatics out)",
                );
            }
            inputs.insert(
                "charges".into(),
                particles(
                    1,
                    (0..n as usize)
                        .map(|i| species_of(i).charge as f32)
                        .collect(),
                ),
            );
        } else if charged {
            self.problem(
                "species carry charges but interactions.electrostatics is not given (give it, or set the charges to 0)",
            );
        }
        if let Some(b) = &s.interactions.bonds {
            self.positive("interactions.bonds.stiffness", b.stiffness);
            for (i, &[p, q]) in b.pairs.iter().enumerate() {
                if p >= n as u64 || q >= n as u64 || p == q {
                    self.problem(format!(
                        "interactions.bonds.pairs[{i}]: [{p}, {q}] is not a pair of two of the {n} particles"
                    ));
                } else {
                    bonds.push((p as u32, q as u32));
                }
            }
            if bonds.is_empty() {
                self.problem(
                    "interactions.bonds: no bonds (give pairs, or a particle set placed as a chain)",
                );
            }
            let mut lists = vec![Vec::new(); n as usize];
            for &(p, q) in &bonds {
                lists[p as usize].push(q);
                lists[q as usize].push(p);
            }
            let mut start = vec![0u32];
            let mut partner = Vec::new();
            for l in &lists {
                partner.extend(l);
                start.push(partner.len() as u32);
            }
            inputs.insert(
                "bond_start".into(),
                HostArray::u32(ValueType::Indices { n: n + 1 }, start),
            );
            inputs.insert(
                "bond_partner".into(),
                HostArray::u32(
                    ValueType::Indices {
                        n: partner.len() as u32,
                    },
                    partner,
                ),
            );
        }
        if inertial {
            // mpcd_md.json takes the (one) mass as a param.
            if !mpcd {
                inputs.insert(
                    "masses".into(),
                    particles(1, masses.iter().map(|&m| m as f32).collect()),
                );
            }
            // Maxwell-Boltzmann at the temperature, zero total momentum.
            let mut v: Vec<[f64; 3]> = masses
                .iter()
                .map(|m| {
                    let sd = (s.temperature / m).sqrt();
                    [0; 3].map(|_| sd * normal(&mut rng))
                })
                .collect();
            let total: f64 = masses.iter().sum();
            for d in 0..3 {
                let p: f64 = v.iter().zip(&masses).map(|(v, m)| v[d] * m).sum();
                for vi in &mut v {
                    vi[d] -= p / total;
                }
            }
            inputs.insert(
                "velocities".into(),
                particles(3, v.iter().flatten().map(|&x| x as f32).collect()),
            );
        }
        let species = SpeciesTable {
            names: s.species.keys().cloned().collect(),
            diameter: (0..n as usize)
                .map(|i| 2.0 * species_of(i).radius as f32)
                .collect(),
            mass: masses.iter().map(|&m| m as f32).collect(),
            charge: (0..n as usize)
                .map(|i| species_of(i).charge as f32)
                .collect(),
            typeid,
        };
        let graph = self.graph(n, radius, smallest, &walls, &inputs);
        let (outputs, every) = match &s.output {
            None => (Vec::new(), None),
            Some(o) => {
                if o.every == 0 {
                    self.problem("output.every: must be at least 1");
                }
                let values = o.values.clone().unwrap_or_else(|| {
                    if inertial {
                        vec!["positions".into(), "velocities".into()]
                    } else {
                        vec!["positions".into()]
                    }
                });
                let file = PathBuf::from(&o.file);
                let is_gsd = file.extension().is_some_and(|e| e == "gsd");
                if !is_gsd && values.len() > 1 {
                    self.problem(format!(
                        "output.values: an NPY file holds one output, not {}: record them to a .gsd file",
                        values.join(", ")
                    ));
                }
                let mut out = Vec::new();
                for v in values {
                    if v != "positions" && v != "velocities" && v != "energy" && v != "forces" {
                        self.problem(format!(
                            "output.values: unknown `{v}` (positions, velocities, forces, energy)"
                        ));
                    } else if v == "velocities" && !inertial {
                        self.problem(format!(
                            "output.values: `{scheme}` has no velocities (Brownian dynamics)"
                        ));
                    } else {
                        out.push((v, file.clone()));
                    }
                }
                (out, Some(o.every))
            }
        };
        if !self.problems.is_empty() {
            return None;
        }
        Some(CompiledScene {
            graph,
            inputs,
            steps: s.run.steps,
            seed: Some(seed),
            outputs,
            every,
            species,
            box_lengths: s.box_lengths,
        })
    }

    /// The walls' z range, checked against the model; None without walls.
    fn walls(&mut self, model: &str) -> Option<(String, f64, f64)> {
        let s = self.scene;
        let Some(w) = &s.walls else {
            if model == "rpy_wall" {
                self.problem(
                    "hydrodynamics.model `rpy_wall` needs walls: {\"type\": \"bottom\", ...}",
                );
            }
            return None;
        };
        if w.kind != "bottom" && w.kind != "slit" {
            self.problem(format!("walls.type: unknown `{}` (bottom or slit)", w.kind));
        }
        if !(w.zmin.is_finite() && w.zmax.is_finite() && w.zmax > w.zmin) {
            self.problem(format!(
                "walls: expected zmin < zmax, got {} and {}",
                w.zmin, w.zmax
            ));
        }
        if (s.box_lengths[2] - (w.zmax - w.zmin)).abs() > 1e-9 * s.box_lengths[2] {
            self.problem(format!(
                "box[2] = {} but the walls span zmax - zmin = {}: with walls the box's z length is the domain's height",
                s.box_lengths[2],
                w.zmax - w.zmin
            ));
        }
        match model {
            "fcm" | "pse" => self.problem(format!(
                "walls with hydrodynamics.model `{model}`: its mobility is triply periodic and knows no wall (use dpstokes, or rpy_wall for a bottom wall)"
            )),
            "rpy_wall" if w.kind != "bottom" => {
                self.problem("hydrodynamics.model `rpy_wall` has one wall: walls.type must be `bottom`")
            }
            "rpy_open" => self.problem(
                "walls with hydrodynamics.model `rpy_open`: its mobility knows no wall (use rpy_wall or dpstokes)",
            ),
            "mpcd" => {
                if w.kind != "slit" {
                    self.problem(format!(
                        "walls.type `{}` with hydrodynamics.model `mpcd`: its solvent is held by two plates (`slit`) or none",
                        w.kind
                    ));
                }
                let half = s.box_lengths[2] / 2.0;
                if (w.zmin + half).abs() > 1e-9 * half || (w.zmax - half).abs() > 1e-9 * half {
                    self.problem(format!(
                        "walls: with hydrodynamics.model `mpcd` the plates are at z = -box[2]/2 and box[2]/2 = {half}, not {} and {}",
                        w.zmin, w.zmax
                    ));
                }
            }
            _ => {}
        }
        if s.interactions.electrostatics.is_some() {
            self.problem(
                "interactions.electrostatics with walls: mesoflow's Poisson solver is triply periodic (the doubly periodic one is not built yet)",
            );
        }
        Some((w.kind.clone(), w.zmin, w.zmax))
    }

    /// Where a generated set goes: the box in x and y, the box or the walls (a radius
    /// away) in z, narrowed by the set's `z`.
    fn region(
        &mut self,
        place: &str,
        set: &ParticleSet,
        r: f64,
        walls: &Option<(String, f64, f64)>,
    ) -> Option<Region> {
        let l = self.scene.box_lengths;
        let mut z = match walls {
            Some((_, lo, hi)) => [lo + r, hi - r],
            None => [-l[2] / 2.0, l[2] / 2.0],
        };
        if let Some([lo, hi]) = set.z {
            if !(lo < hi && lo >= z[0] && hi <= z[1]) {
                self.problem(format!(
                    "{place}.z: [{lo}, {hi}] must be an interval inside [{}, {}]",
                    z[0], z[1]
                ));
                return None;
            }
            z = [lo, hi];
        }
        if z[0] >= z[1] {
            self.problem(format!("{place}: no room in z for particles of radius {r}"));
            return None;
        }
        Some([[-l[0] / 2.0, l[0] / 2.0], [-l[1] / 2.0, l[1] / 2.0], z])
    }

    fn read_positions(&mut self, place: &str, file: &Path) -> Option<Vec<[f64; 3]>> {
        let shape = InputShape::Particles {
            rows: Dim::Free,
            cols: 3,
        };
        match crate::npy::read_input(file, &shape) {
            Ok(a) => {
                let crate::value::HostData::F32(v) = &a.data else {
                    self.problem(format!(
                        "{place}.positions: {} holds integers",
                        file.display()
                    ));
                    return None;
                };
                if let Some(i) = v.iter().position(|x| !x.is_finite()) {
                    self.problem(format!(
                        "{place}.positions: {} row {} is not finite",
                        file.display(),
                        i / 3
                    ));
                    return None;
                }
                Some(
                    v.chunks_exact(3)
                        .map(|r| [r[0] as f64, r[1] as f64, r[2] as f64])
                        .collect(),
                )
            }
            Err(e) => {
                self.problem(format!("{place}.positions: {e}"));
                None
            }
        }
    }

    /// Uniform positions, none closer to another (earlier sets included) than the sum
    /// of their radii.
    fn place_random(
        &mut self,
        place: &str,
        count: u64,
        r: f64,
        region: Region,
        placer: &mut Placer,
        rng: &mut StdRng,
    ) -> Option<Vec<[f64; 3]>> {
        let mut out = Vec::with_capacity(count as usize);
        for _ in 0..count {
            let found = (0..PLACEMENT_TRIES)
                .map(|_| uniform_in(&region, rng))
                .find(|p| placer.fits(p, r));
            let Some(p) = found else {
                let volume: f64 = region.iter().map(|[a, b]| b - a).product();
                let fraction =
                    out.len() as f64 * 4.0 / 3.0 * std::f64::consts::PI * r.powi(3) / volume;
                self.problem(format!(
                    "{place}: placed {} of {count} particles without overlap before {PLACEMENT_TRIES} tries failed (packing fraction {fraction:.3} reached): use a larger region, fewer particles or place: lattice",
                    out.len()
                ));
                return None;
            };
            placer.add(p, r);
            out.push(p);
        }
        Some(out)
    }

    /// A chain: a random walk of steps `bond` from a random start, each bead inside the
    /// region and overlapping no other particle (its predecessor touches it where the
    /// step is the sum of radii); bonds between consecutive beads.
    #[allow(clippy::too_many_arguments)]
    fn place_chain(
        &mut self,
        place: &str,
        count: u64,
        r: f64,
        bond: f64,
        region: Region,
        placer: &mut Placer,
        rng: &mut StdRng,
    ) -> Option<Vec<[f64; 3]>> {
        let inside = |p: &[f64; 3]| (0..3).all(|d| p[d] >= region[d][0] && p[d] <= region[d][1]);
        let mut out: Vec<[f64; 3]> = Vec::with_capacity(count as usize);
        for k in 0..count {
            let found = (0..PLACEMENT_TRIES)
                .map(|_| match out.last() {
                    None => uniform_in(&region, rng),
                    Some(prev) => {
                        let u = [normal(rng), normal(rng), normal(rng)];
                        let norm = (u[0] * u[0] + u[1] * u[1] + u[2] * u[2]).sqrt().max(1e-300);
                        [0, 1, 2].map(|d| prev[d] + bond * u[d] / norm)
                    }
                })
                .find(|p| inside(p) && placer.fits(p, r));
            let Some(p) = found else {
                self.problem(format!(
                    "{place}: a chain of {count} beads found no room for bead {k} in {PLACEMENT_TRIES} tries (a larger region, or a shorter chain)"
                ));
                return None;
            };
            placer.add(p, r);
            out.push(p);
        }
        Some(out)
    }

    /// The first `count` sites of a simple cubic lattice of spacing (V / count)^(1/3)
    /// over the region, each site at the centre of its lattice cell.
    fn place_lattice(count: u64, region: Region) -> Vec<[f64; 3]> {
        let sides = region.map(|[a, b]| b - a);
        let spacing = (sides.iter().product::<f64>() / count as f64).cbrt();
        let mut per = sides.map(|s| ((s / spacing).floor() as u64).max(1));
        // Round down can leave too few sites: grow the axis with the most room.
        while per.iter().product::<u64>() < count {
            let d = (0..3)
                .max_by(|&a, &b| (sides[a] / per[a] as f64).total_cmp(&(sides[b] / per[b] as f64)))
                .expect("three axes");
            per[d] += 1;
        }
        let mut out = Vec::with_capacity(count as usize);
        'fill: for k in 0..per[2] {
            for j in 0..per[1] {
                for i in 0..per[0] {
                    if out.len() as u64 == count {
                        break 'fill;
                    }
                    let idx = [i, j, k];
                    out.push(
                        [0, 1, 2].map(|d| {
                            region[d][0] + sides[d] * (idx[d] as f64 + 0.5) / per[d] as f64
                        }),
                    );
                }
            }
        }
        out
    }

    /// The graph: one integrator node around the mobility and the interactions.
    fn graph(
        &mut self,
        n: u32,
        radius: f64,
        smallest: f64,
        walls: &Option<(String, f64, f64)>,
        inputs: &BTreeMap<String, HostArray>,
    ) -> String {
        let s = self.scene;
        let h = &s.hydrodynamics;
        let l = s.box_lengths;
        let scheme = s.integrator.scheme.as_str();
        let mpcd = h.model == "mpcd";
        let mut params = serde_json::Map::new();
        params.insert("dt".into(), json!("$dt"));
        params.insert("temperature".into(), json!("$temperature"));
        if mpcd {
            // The solvent and the solute's MD are one graph: its params are the scene's.
            params.insert("box".into(), json!(l));
            params.insert(
                "walls".into(),
                json!(if walls.is_some() { "plates" } else { "none" }),
            );
            let mass = s.species.values().next().map_or(1.0, |sp| sp.mass);
            params.insert("solute_mass".into(), json!(mass));
            for (k, v) in &h.params {
                params.insert(k.clone(), v.clone());
            }
        }
        if let Some(xi) = s.integrator.friction {
            params.insert("friction".into(), json!(xi));
        }
        for (k, v) in &s.integrator.params {
            params.insert(k.clone(), v.clone());
        }
        if BROWNIAN.contains(&scheme) {
            let tolerance = h.tolerance.unwrap_or(default_tolerance());
            let (file, mut bound): (&str, Vec<(&str, Value)>) = match h.model.as_str() {
                "none" => ("lib/mobility/free.json", vec![]),
                "fcm" => (
                    "fcm.json",
                    vec![("box", json!(l)), ("tolerance", json!(tolerance))],
                ),
                "pse" => (
                    "pse.json",
                    vec![("box", json!(l)), ("tolerance", json!(tolerance))],
                ),
                "rpy_open" => ("rpy_open.json", vec![]),
                "rpy_wall" => (
                    "rpy_wall.json",
                    vec![("wall_height", json!(walls.as_ref().map_or(0.0, |w| w.1)))],
                ),
                _ => {
                    let (kind, zmin, zmax) =
                        walls
                            .clone()
                            .unwrap_or(("none".into(), -l[2] / 2.0, l[2] / 2.0));
                    (
                        "dpstokes.json",
                        vec![
                            ("box", json!([l[0], l[1]])),
                            ("zmin", json!(zmin)),
                            ("zmax", json!(zmax)),
                            ("walls", json!(kind)),
                            ("tolerance", json!(tolerance)),
                        ],
                    )
                }
            };
            bound.push(("viscosity", json!(h.viscosity.unwrap_or(1.0))));
            bound.push(("radius", json!(radius)));
            params.insert("mobility".into(), json!(library_file(file)));
            for (k, v) in bound {
                params.insert(format!("mobility.{k}"), v);
            }
            for (k, v) in &h.params {
                params.insert(format!("mobility.{k}"), v.clone());
            }
        }
        // The interactions, each bound only where the scene has it.
        params.insert(
            "forces".into(),
            json!(library_file("lib/forces/interactions.json")),
        );
        let it = &s.interactions;
        let mut cutoff: f64 = 0.0;
        // WCA, or Lennard-Jones with its tail: one pair kernel, cut at 2^(1/6) sigma or
        // at `cutoff` sigma (the energy shifted to 0 there either way).
        let pair = match (&it.wca, &it.lj) {
            (Some(_), Some(_)) => {
                self.problem(
                    "interactions: give `wca` or `lj`, not both (WCA is LJ cut at 2^(1/6) sigma)",
                );
                None
            }
            (Some(w), None) => Some(("wca", w.epsilon, w.sigma, 2f64.powf(1.0 / 6.0))),
            (None, Some(l)) => Some(("lj", l.epsilon, l.sigma, l.cutoff.unwrap_or(2.5))),
            (None, None) => None,
        };
        if let Some((name, epsilon, sigma, reach)) = pair {
            let sigma = sigma.unwrap_or(2.0 * radius);
            let eps = epsilon.unwrap_or(s.temperature.max(f64::MIN_POSITIVE));
            self.positive(&format!("interactions.{name}.sigma"), sigma);
            self.positive(&format!("interactions.{name}.epsilon"), eps);
            if !(reach.is_finite() && reach >= 1.0) {
                self.problem(format!(
                    "interactions.{name}.cutoff: expected at least 1 (in sigma), got {reach}"
                ));
            }
            cutoff = reach * sigma;
            params.insert("forces.wca".into(), json!(true));
            params.insert("forces.wca_epsilon".into(), json!(eps));
            params.insert("forces.wca_sigma".into(), json!(sigma));
            params.insert("forces.wca_cutoff".into(), json!(cutoff));
        }
        if let Some(e) = &it.electrostatics {
            let width = e.width.unwrap_or(smallest);
            self.positive("interactions.electrostatics.width", width);
            self.positive("interactions.electrostatics.permittivity", e.permittivity);
            params.insert("forces.electrostatics".into(), json!(true));
            params.insert("forces.permittivity".into(), json!(e.permittivity));
            params.insert("forces.charge_width".into(), json!(width));
            params.insert("forces.tolerance".into(), json!(e.tolerance));
        }
        if let Some(b) = &it.bonds {
            params.insert("forces.bonds".into(), json!(true));
            params.insert("forces.bond_stiffness".into(), json!(b.stiffness));
            params.insert(
                "forces.bond_rest_length".into(),
                json!(b.rest_length.unwrap_or(2.0 * radius)),
            );
        }
        // With walls, the periodic box of the pair list spans the domain and a cutoff
        // more each side, so no pair meets across the walls.
        let force_box = match walls {
            Some(_) => [l[0], l[1], l[2] + 2.0 * cutoff.max(radius)],
            None => l,
        };
        params.insert("forces.box".into(), json!(force_box));
        if let (Some((kind, zmin, zmax)), Some(w)) = (walls, &s.walls) {
            let rep = w.repulsion.as_ref();
            let sigma = rep.and_then(|r| r.sigma).unwrap_or(radius);
            let eps = rep
                .and_then(|r| r.epsilon)
                .unwrap_or(s.temperature.max(f64::MIN_POSITIVE));
            self.positive("walls.repulsion.sigma", sigma);
            self.positive("walls.repulsion.epsilon", eps);
            params.insert("forces.walls".into(), json!(true));
            params.insert("forces.wall_bottom".into(), json!(zmin));
            if kind == "slit" {
                params.insert("forces.wall_top".into(), json!(zmax));
            }
            params.insert("forces.wall_epsilon".into(), json!(eps));
            params.insert("forces.wall_sigma".into(), json!(sigma));
        }
        let mut node_inputs = serde_json::Map::new();
        let mut decl = serde_json::Map::new();
        for (name, a) in inputs {
            let d = match a.ty {
                ValueType::Particles { k, .. } => {
                    json!({"type": "particles", "rows": "n", "cols": k})
                }
                _ => json!({"type": "indices"}),
            };
            decl.insert(name.clone(), d);
            let port = match name.as_str() {
                "charges" | "external" | "bond_start" | "bond_partner" => {
                    format!("forces.{name}")
                }
                other => other.to_string(),
            };
            node_inputs.insert(port, json!(format!("inputs.{name}")));
        }
        let mut outputs = serde_json::Map::new();
        outputs.insert("positions".into(), json!("system.positions"));
        if INERTIAL.contains(&scheme) {
            outputs.insert("velocities".into(), json!("system.velocities"));
        }
        outputs.insert("forces".into(), json!("system.forces"));
        outputs.insert("energy".into(), json!("system.energy"));
        if mpcd {
            for name in ["solvent_positions", "solvent_velocities", "temperature"] {
                outputs.insert(name.into(), json!(format!("system.{name}")));
            }
        }
        let mut doc = String::new();
        let _ = write!(
            doc,
            "Built from a scene ({scheme}, hydrodynamics {}): {}",
            h.model, s.doc
        );
        let g = json!({
            "mesoflow": 1,
            "doc": doc,
            "params": {
                "dt": {"default": s.integrator.dt, "min": 0, "doc": "time step"},
                "temperature": {"default": s.temperature, "min": 0, "doc": "kT"},
                "integrator": {
                    "default": if mpcd {
                        library_file("mpcd_md.json")
                    } else {
                        library_file(&format!("lib/integrators/{scheme}.json"))
                    },
                    "graph": true,
                    "doc": "the integrator's graph",
                },
            },
            "sizes": {"n": {"default": n, "doc": "particles"}},
            "inputs": decl,
            "nodes": [{
                "id": "system",
                "graph": "$integrator",
                "params": params,
                "inputs": node_inputs,
            }],
            "outputs": outputs,
        });
        serde_json::to_string_pretty(&g).expect("a JSON value")
    }
}

/// A graph of the library by its path there, as the absolute path of the file found in
/// the first library folder that holds it: a scene's folder may hold files of the same
/// name (a scene called fcm.json), which a relative path would find first.
fn library_file(relative: &str) -> String {
    crate::graph::library::library_folders()
        .iter()
        .map(|folder| folder.join(relative))
        .find(|p| p.is_file())
        .and_then(|p| p.canonicalize().ok())
        .map_or_else(|| relative.to_string(), |p| p.display().to_string())
}

/// Placed particles in a grid of cells of the largest diameter, so an overlap check looks
/// at 27 cells: periodic in x and y and, without walls, z (a contact within 1e-9 of the
/// sum of radii counts as touching, not overlapping).
struct Placer {
    lengths: [f64; 3],
    periodic_z: bool,
    dims: [usize; 3],
    largest: f64,
    cells: std::collections::HashMap<[usize; 3], Vec<usize>>,
    placed: Vec<([f64; 3], f64)>,
}

impl Placer {
    fn new(lengths: [f64; 3], periodic_z: bool, largest_radius: f64) -> Placer {
        let cell = 2.0 * largest_radius;
        Placer {
            lengths,
            periodic_z,
            dims: [0, 1, 2].map(|d| ((lengths[d] / cell).floor() as usize).clamp(1, 256)),
            largest: largest_radius,
            cells: std::collections::HashMap::new(),
            placed: Vec::new(),
        }
    }

    fn cell_of(&self, p: &[f64; 3]) -> [usize; 3] {
        [0, 1, 2].map(|d| {
            let u = (p[d] / self.lengths[d] + 0.5).rem_euclid(1.0);
            ((u * self.dims[d] as f64) as usize).min(self.dims[d] - 1)
        })
    }

    fn fits(&self, p: &[f64; 3], r: f64) -> bool {
        debug_assert!(r <= self.largest);
        let c = self.cell_of(p);
        for dx in -1i64..=1 {
            for dy in -1i64..=1 {
                for dz in -1i64..=1 {
                    let offset = [dx, dy, dz];
                    let key: [usize; 3] = std::array::from_fn(|d| {
                        (c[d] as i64 + offset[d]).rem_euclid(self.dims[d] as i64) as usize
                    });
                    let Some(list) = self.cells.get(&key) else {
                        continue;
                    };
                    for &j in list {
                        let (q, rj) = self.placed[j];
                        let mut d2 = 0.0;
                        for d in 0..3 {
                            let mut x = p[d] - q[d];
                            if d < 2 || self.periodic_z {
                                x -= self.lengths[d] * (x / self.lengths[d]).round();
                            }
                            d2 += x * x;
                        }
                        let contact = (r + rj) * (1.0 - 1e-9);
                        if d2 < contact * contact {
                            return false;
                        }
                    }
                }
            }
        }
        true
    }

    fn add(&mut self, p: [f64; 3], r: f64) {
        let c = self.cell_of(&p);
        self.cells.entry(c).or_default().push(self.placed.len());
        self.placed.push((p, r));
    }
}

/// A point uniform in the region.
fn uniform_in(region: &Region, rng: &mut StdRng) -> [f64; 3] {
    [0, 1, 2].map(|d| region[d][0] + (region[d][1] - region[d][0]) * rng.random::<f64>())
}

/// A standard normal draw (Box-Muller; the scene's own stream, apart from the graph's).
fn normal(rng: &mut StdRng) -> f64 {
    let u: f64 = 1.0 - rng.random::<f64>();
    let v: f64 = rng.random::<f64>();
    (-2.0 * u.ln()).sqrt() * (2.0 * std::f64::consts::PI * v).cos()
}
