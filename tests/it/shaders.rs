//! Every WGSL file validates with naga without a GPU, imports resolved, with the
//! capabilities mesoflow may request; so do the kernels the fusion pass generates.

use mesoflow::gpu::shaders;

use crate::util::validate_wgsl;

/// Every capability mesoflow may request of a device.
const EVERY_CAPABILITY: naga::valid::Capabilities = naga::valid::Capabilities::FLOAT64
    .union(naga::valid::Capabilities::SHADER_FLOAT32_ATOMIC)
    .union(naga::valid::Capabilities::SUBGROUP)
    .union(naga::valid::Capabilities::SHADER_INT64)
    .union(naga::valid::Capabilities::SHADER_INT64_ATOMIC_ALL_OPS);

#[test]
fn every_shader_file_validates() {
    let mut n = 0;
    for path in shaders::paths() {
        // Templates are validated composed, by the tests of the nodes that compose them.
        if shaders::raw(path).is_some_and(|s| s.starts_with("// template")) {
            continue;
        }
        let src = shaders::source(path).unwrap_or_else(|e| panic!("{path}: {e}"));
        validate_wgsl(path, &src, EVERY_CAPABILITY);
        n += 1;
    }
    assert!(n >= 3);
}

#[test]
fn mpcd_binning_validates_with_either_sum_atomics() {
    for sums in ["mpcd/sums_int64.wgsl", "mpcd/sums_int32.wgsl"] {
        for main in ["mpcd/bin.wgsl", "mpcd/stream_bin.wgsl"] {
            let src = shaders::resolve(&format!("#import {sums}\n#import {main}\n"))
                .unwrap_or_else(|e| panic!("{sums}: {e}"));
            validate_wgsl(&format!("{main} after {sums}"), &src, EVERY_CAPABILITY);
        }
    }
}

#[test]
fn generated_pointwise_kernels_validate() {
    use mesoflow::plan::{self, Launch, PlanOptions};
    // A graph that uses every element-wise kind, fused and unfused.
    let g = crate::util::load(&crate::util::root().join("graphs/fixtures/pointwise_all.json"));
    let inputs = g.declared_input_types();
    for fuse in [true, false] {
        let opts = PlanOptions {
            outputs: None,
            inputs: inputs.clone(),
            fuse,
            in_place: true,
        };
        let p = plan::plan(&g, &opts, &mesoflow::gpu::DeviceCaps::baseline()).unwrap();
        let mut generated = 0;
        for l in &p.step {
            if let Launch::Fused(k) = l {
                validate_wgsl("generated", &k.source, EVERY_CAPABILITY);
                generated += 1;
            }
        }
        if fuse {
            assert!(generated >= 1);
        } else {
            // One kernel per node, but for the sum without its optional term (read through).
            assert_eq!(generated + p.forwarded.len(), g.nodes.len());
            assert_eq!(p.forwarded.len(), 1);
        }
    }
}

#[test]
fn imports_resolve_once_and_report_missing_files() {
    let src = shaders::resolve("#import common/index.wgsl\n#import common/index.wgsl\n").unwrap();
    assert_eq!(src.matches("fn flat_index").count(), 1);
    let err = shaders::resolve("#import common/nope.wgsl\n")
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("no shader file `shaders/common/nope.wgsl`"),
        "{err}"
    );
}

/// The functions of `src` that index a struct passed to them by value with a non-constant
/// index (`m.box[a]` for an argument `m` and a loop counter `a`).
fn dynamic_indices_into_struct_arguments(path: &str, src: &str) -> Vec<String> {
    use naga::{Expression, TypeInner};
    let module = naga::front::wgsl::parse_str(src).unwrap_or_else(|e| panic!("{path}: {e}"));
    let mut found = Vec::new();
    let functions = module
        .functions
        .iter()
        .map(|(_, f)| f)
        .chain(module.entry_points.iter().map(|e| &e.function));
    for f in functions {
        for (_, e) in f.expressions.iter() {
            let Expression::Access { base, .. } = e else {
                continue;
            };
            let mut root = *base;
            while let Expression::Access { base, .. } | Expression::AccessIndex { base, .. } =
                f.expressions[root]
            {
                root = base;
            }
            if let Expression::FunctionArgument(i) = f.expressions[root] {
                let ty = f.arguments[i as usize].ty;
                if matches!(module.types[ty].inner, TypeInner::Struct { .. }) {
                    found.push(format!(
                        "{path}: fn {} indexes its struct argument {} by a non-constant index",
                        f.name.as_deref().unwrap_or("?"),
                        f.arguments[i as usize].name.as_deref().unwrap_or("?"),
                    ));
                }
            }
        }
    }
    found.sort();
    found.dedup();
    found
}

/// No kernel indexes a struct passed by value with a non-constant index. On lavapipe (Mesa
/// 22.3.6) that construct made the MPCD binning kernels recompile at every dispatch and keep
/// every compiled copy (host memory grew by about 270 KB a step, to 15 GB over the mpcd
/// tests; mpcd/common.wgsl, cell_of); on GPUs it costs a per-thread copy of the struct.
/// Index the uniform itself (`geo.box_len[a]`) or use vector arithmetic instead.
#[test]
fn no_kernel_indexes_a_struct_argument_dynamically() {
    let mut sources = Vec::new();
    for path in shaders::paths() {
        if shaders::raw(path).is_some_and(|s| s.starts_with("// template")) {
            continue;
        }
        let src = shaders::source(path).unwrap_or_else(|e| panic!("{path}: {e}"));
        sources.push((path.to_string(), src));
    }
    for sums in ["mpcd/sums_int64.wgsl", "mpcd/sums_int32.wgsl"] {
        for main in ["mpcd/bin.wgsl", "mpcd/stream_bin.wgsl"] {
            let src = shaders::resolve(&format!("#import {sums}\n#import {main}\n"))
                .unwrap_or_else(|e| panic!("{sums}: {e}"));
            sources.push((format!("{main} after {sums}"), src));
        }
    }
    // The check itself sees the construct.
    let probe = "struct S { v: vec4<f32> }\nfn f(s: S, a: u32) -> f32 { return s.v[a]; }";
    assert_eq!(
        dynamic_indices_into_struct_arguments("probe", probe).len(),
        1
    );
    let found: Vec<String> = sources
        .iter()
        .flat_map(|(path, src)| dynamic_indices_into_struct_arguments(path, src))
        .collect();
    assert!(found.is_empty(), "{}", found.join("\n"));
}
