//! What the Vulkan driver makes of a kernel: its registers, spills, code size and the like,
//! as the driver reports them (VK_KHR_pipeline_executable_properties). wgpu does not ask
//! the driver for them, so this opens the device a second time through ash, compiles each
//! kernel from a `MESOFLOW_KERNEL_DUMP` file to SPIR-V the way wgpu does (naga, the
//! default `trusted` runtime checks: no bounds checks, no loop bounding), builds its
//! pipeline with statistics captured, and reads them back. A tool for kernel work (the
//! occupancy a kernel's registers allow), not part of any run: `mesoflow kernel-stats`.

use std::ffi::{CStr, c_char};
use std::path::{Path, PathBuf};

use ash::vk;
use thiserror::Error;

use super::kernel::{Binding, KernelSpec};

#[derive(Debug, Error)]
#[non_exhaustive]
pub enum DriverStatsError {
    #[error("cannot load the Vulkan loader: {0}")]
    Loader(String),
    #[error("Vulkan: {call}: {result}")]
    Vulkan {
        call: &'static str,
        result: vk::Result,
    },
    #[error("no Vulkan device{}", match .0 { Some(w) => format!(" matches MESOFLOW_ADAPTER=\"{w}\""), None => String::new() })]
    NoDevice(Option<String>),
    #[error(
        "the driver of {0} does not report kernel statistics \
         (no VK_KHR_pipeline_executable_properties)"
    )]
    Unsupported(String),
    #[error("{file}: {message}")]
    Kernel { file: PathBuf, message: String },
}

fn vulkan(call: &'static str) -> impl Fn(vk::Result) -> DriverStatsError {
    move |result| DriverStatsError::Vulkan { call, result }
}

/// The kernel of a `MESOFLOW_KERNEL_DUMP` file (`KernelSpec::from_dump`).
pub fn read_dump(file: &Path) -> Result<KernelSpec, DriverStatsError> {
    let fail = |message: String| DriverStatsError::Kernel {
        file: file.into(),
        message,
    };
    let text = std::fs::read_to_string(file).map_err(|e| fail(e.to_string()))?;
    KernelSpec::from_dump(&text).map_err(fail)
}

/// SPIR-V as wgpu's Vulkan backend writes it for this kernel under the default `trusted`
/// runtime checks (`kernel.rs`'s `runtime_checks`).
pub fn spirv(spec: &KernelSpec, lang_version: (u8, u8)) -> Result<Vec<u32>, String> {
    use naga::back::spv;
    let module =
        naga::front::wgsl::parse_str(&spec.source).map_err(|e| e.emit_to_string(&spec.source))?;
    let info = naga::valid::Validator::new(
        naga::valid::ValidationFlags::all(),
        naga::valid::Capabilities::all(),
    )
    .validate(&module)
    .map_err(|e| e.emit_to_string(&spec.source))?;
    let constants = spec
        .constants
        .iter()
        .map(|(n, bits)| (n.clone(), f64::from_bits(*bits)))
        .collect();
    let stage = naga::ShaderStage::Compute;
    let (module, info) = naga::back::pipeline_constants::process_overrides(
        &module,
        &info,
        Some((stage, &spec.entry)),
        &constants,
    )
    .map_err(|e| e.to_string())?;
    let options = spv::Options {
        lang_version,
        bounds_check_policies: naga::proc::BoundsCheckPolicies {
            index: naga::proc::BoundsCheckPolicy::Unchecked,
            buffer: naga::proc::BoundsCheckPolicy::Unchecked,
            image_load: naga::proc::BoundsCheckPolicy::Unchecked,
            binding_array: naga::proc::BoundsCheckPolicy::Unchecked,
        },
        force_loop_bounding: false,
        zero_initialize_workgroup_memory: spv::ZeroInitializeWorkgroupMemoryMode::None,
        ..spv::Options::default()
    };
    let pipeline = spv::PipelineOptions {
        shader_stage: stage,
        entry_point: spec.entry.clone(),
    };
    spv::write_vec(&module, &info, &options, Some(&pipeline)).map_err(|e| e.to_string())
}

/// One statistic as the driver names and describes it.
#[derive(Debug, Clone)]
pub struct Statistic {
    pub name: String,
    pub description: String,
    pub value: String,
}

/// A pipeline executable (a compute pipeline has one on most drivers) and its statistics.
#[derive(Debug, Clone)]
pub struct Executable {
    pub name: String,
    pub subgroup_size: u32,
    pub statistics: Vec<Statistic>,
    /// The driver's internal representations (its IR or machine code, where it gives
    /// them): (name, text).
    pub representations: Vec<(String, String)>,
}

/// The device opened for statistics.
pub struct DriverStats {
    _entry: ash::Entry,
    instance: ash::Instance,
    device: ash::Device,
    executables: ash::khr::pipeline_executable_properties::Device,
    pub adapter: String,
    varying_subgroups: bool,
    lang_version: (u8, u8),
}

fn text(chars: &[c_char]) -> String {
    // SAFETY: Vulkan's fixed-size strings are nul-terminated within their arrays.
    unsafe { CStr::from_ptr(chars.as_ptr()) }
        .to_string_lossy()
        .into_owned()
}

impl DriverStats {
    /// Opens the discrete GPU when there is one, else the first device; `wanted` picks by a
    /// substring of its name (as `MESOFLOW_ADAPTER` does for runs).
    pub fn open(wanted: Option<&str>) -> Result<DriverStats, DriverStatsError> {
        // SAFETY: loading the system's Vulkan loader; every call below follows the spec's
        // valid usage for the handles created here, destroyed in `Drop`.
        unsafe {
            let entry = ash::Entry::load().map_err(|e| DriverStatsError::Loader(e.to_string()))?;
            let app = vk::ApplicationInfo::default().api_version(vk::API_VERSION_1_3);
            let instance = entry
                .create_instance(
                    &vk::InstanceCreateInfo::default().application_info(&app),
                    None,
                )
                .map_err(vulkan("vkCreateInstance"))?;
            match Self::open_device(&instance, wanted) {
                Ok(opened) => {
                    let (device, adapter, varying_subgroups, lang_version) = opened;
                    let executables =
                        ash::khr::pipeline_executable_properties::Device::new(&instance, &device);
                    Ok(DriverStats {
                        _entry: entry,
                        instance,
                        device,
                        executables,
                        adapter,
                        varying_subgroups,
                        lang_version,
                    })
                }
                Err(e) => {
                    // Before `entry` goes, which unloads the loader.
                    instance.destroy_instance(None);
                    Err(e)
                }
            }
        }
    }

    /// The device, its name, whether it takes subgroups of varying size and its SPIR-V
    /// version.
    unsafe fn open_device(
        instance: &ash::Instance,
        wanted: Option<&str>,
    ) -> Result<(ash::Device, String, bool, (u8, u8)), DriverStatsError> {
        unsafe {
            let devices = instance
                .enumerate_physical_devices()
                .map_err(vulkan("vkEnumeratePhysicalDevices"))?;
            let named: Vec<(vk::PhysicalDevice, vk::PhysicalDeviceProperties)> = devices
                .iter()
                .map(|&d| (d, instance.get_physical_device_properties(d)))
                .filter(|(_, p)| wanted.is_none_or(|w| text(&p.device_name).contains(w)))
                .collect();
            let (physical, props) = named
                .iter()
                .find(|(_, p)| p.device_type == vk::PhysicalDeviceType::DISCRETE_GPU)
                .or(named.first())
                .copied()
                .ok_or_else(|| DriverStatsError::NoDevice(wanted.map(String::from)))?;
            let adapter = text(&props.device_name);
            let extensions = instance
                .enumerate_device_extension_properties(physical)
                .map_err(vulkan("vkEnumerateDeviceExtensionProperties"))?;
            let has = |name: &CStr| {
                extensions
                    .iter()
                    .any(|e| text(&e.extension_name).as_bytes() == name.to_bytes())
            };
            if !has(ash::khr::pipeline_executable_properties::NAME) {
                return Err(DriverStatsError::Unsupported(adapter));
            }
            let mut wanted_extensions =
                vec![ash::khr::pipeline_executable_properties::NAME.as_ptr()];
            let atomic_float = has(ash::ext::shader_atomic_float::NAME);
            if atomic_float {
                wanted_extensions.push(ash::ext::shader_atomic_float::NAME.as_ptr());
            }
            let robustness2 = has(ash::ext::robustness2::NAME);
            if robustness2 {
                wanted_extensions.push(ash::ext::robustness2::NAME.as_ptr());
            }
            // Every feature the device has: those mesoflow's kernels use (f64, i64,
            // subgroups of any size, float atomics) and, as wgpu enables them, robust buffer
            // access (1 and 2), which the driver may compile into each load and store.
            let varying_subgroups = {
                let mut v13 = vk::PhysicalDeviceVulkan13Features::default();
                let mut query = vk::PhysicalDeviceFeatures2::default().push_next(&mut v13);
                instance.get_physical_device_features2(physical, &mut query);
                v13.subgroup_size_control == vk::TRUE
            };
            let mut v11 = vk::PhysicalDeviceVulkan11Features::default();
            let mut v12 = vk::PhysicalDeviceVulkan12Features::default();
            let mut v13 = vk::PhysicalDeviceVulkan13Features::default();
            let mut floats = vk::PhysicalDeviceShaderAtomicFloatFeaturesEXT::default();
            let mut robust = vk::PhysicalDeviceRobustness2FeaturesEXT::default();
            let mut features = vk::PhysicalDeviceFeatures2::default()
                .push_next(&mut v11)
                .push_next(&mut v12)
                .push_next(&mut v13);
            if atomic_float {
                features = features.push_next(&mut floats);
            }
            if robustness2 {
                features = features.push_next(&mut robust);
            }
            instance.get_physical_device_features2(physical, &mut features);
            let mut capture = vk::PhysicalDevicePipelineExecutablePropertiesFeaturesKHR::default()
                .pipeline_executable_info(true);
            let mut features = features.push_next(&mut capture);
            let family = instance
                .get_physical_device_queue_family_properties(physical)
                .iter()
                .position(|f| f.queue_flags.contains(vk::QueueFlags::COMPUTE))
                .ok_or_else(|| DriverStatsError::NoDevice(wanted.map(String::from)))?
                as u32;
            let priorities = [1.0];
            let queues = [vk::DeviceQueueCreateInfo::default()
                .queue_family_index(family)
                .queue_priorities(&priorities)];
            let mut create = vk::DeviceCreateInfo::default()
                .queue_create_infos(&queues)
                .enabled_extension_names(&wanted_extensions);
            create = create.push_next(&mut features);
            let device = instance
                .create_device(physical, &create, None)
                .map_err(vulkan("vkCreateDevice"))?;
            let lang_version = match props.api_version {
                v if v >= vk::API_VERSION_1_3 => (1, 6),
                v if v >= vk::API_VERSION_1_2 => (1, 5),
                _ => (1, 3),
            };
            Ok((device, adapter, varying_subgroups, lang_version))
        }
    }

    /// Builds the kernel's pipeline with statistics captured and reads them (and, with
    /// `representations`, the driver's internal representations).
    pub fn kernel(
        &self,
        kernel: &KernelSpec,
        representations: bool,
    ) -> Result<Vec<Executable>, String> {
        let words = spirv(kernel, self.lang_version)?;
        let fail = |call: &str, r: vk::Result| format!("{call}: {r}");
        // SAFETY: handles created here from this device and destroyed before returning.
        unsafe {
            let bindings: Vec<vk::DescriptorSetLayoutBinding> = kernel
                .bindings
                .iter()
                .enumerate()
                .map(|(i, b)| {
                    vk::DescriptorSetLayoutBinding::default()
                        .binding(i as u32)
                        .descriptor_count(1)
                        .stage_flags(vk::ShaderStageFlags::COMPUTE)
                        .descriptor_type(match b {
                            Binding::Uniform => vk::DescriptorType::UNIFORM_BUFFER,
                            _ => vk::DescriptorType::STORAGE_BUFFER,
                        })
                })
                .collect();
            let set_layout = self
                .device
                .create_descriptor_set_layout(
                    &vk::DescriptorSetLayoutCreateInfo::default().bindings(&bindings),
                    None,
                )
                .map_err(|r| fail("vkCreateDescriptorSetLayout", r))?;
            let layouts = [set_layout];
            let layout = self.device.create_pipeline_layout(
                &vk::PipelineLayoutCreateInfo::default().set_layouts(&layouts),
                None,
            );
            let module = self
                .device
                .create_shader_module(&vk::ShaderModuleCreateInfo::default().code(&words), None);
            let result = match (layout, module) {
                (Ok(layout), Ok(module)) => self.capture(kernel, layout, module, representations),
                (Err(r), _) => Err(fail("vkCreatePipelineLayout", r)),
                (_, Err(r)) => Err(fail("vkCreateShaderModule", r)),
            };
            if let Ok(module) = module {
                self.device.destroy_shader_module(module, None);
            }
            if let Ok(layout) = layout {
                self.device.destroy_pipeline_layout(layout, None);
            }
            self.device.destroy_descriptor_set_layout(set_layout, None);
            result
        }
    }

    unsafe fn capture(
        &self,
        kernel: &KernelSpec,
        layout: vk::PipelineLayout,
        module: vk::ShaderModule,
        representations: bool,
    ) -> Result<Vec<Executable>, String> {
        let entry = std::ffi::CString::new(kernel.entry.as_str()).map_err(|e| e.to_string())?;
        let mut stage_flags = vk::PipelineShaderStageCreateFlags::empty();
        if self.varying_subgroups {
            stage_flags |= vk::PipelineShaderStageCreateFlags::ALLOW_VARYING_SUBGROUP_SIZE;
        }
        let stage = vk::PipelineShaderStageCreateInfo::default()
            .flags(stage_flags)
            .stage(vk::ShaderStageFlags::COMPUTE)
            .module(module)
            .name(&entry);
        let mut flags = vk::PipelineCreateFlags::CAPTURE_STATISTICS_KHR;
        if representations {
            flags |= vk::PipelineCreateFlags::CAPTURE_INTERNAL_REPRESENTATIONS_KHR;
        }
        let info = [vk::ComputePipelineCreateInfo::default()
            .flags(flags)
            .stage(stage)
            .layout(layout)];
        // SAFETY: as in `kernel`.
        unsafe {
            let pipeline = self
                .device
                .create_compute_pipelines(vk::PipelineCache::null(), &info, None)
                .map_err(|(_, r)| format!("vkCreateComputePipelines: {r}"))?[0];
            let result = self.read(pipeline, representations);
            self.device.destroy_pipeline(pipeline, None);
            result
        }
    }

    unsafe fn read(
        &self,
        pipeline: vk::Pipeline,
        representations: bool,
    ) -> Result<Vec<Executable>, String> {
        // SAFETY: as in `kernel`.
        unsafe {
            let properties = self
                .executables
                .get_pipeline_executable_properties(
                    &vk::PipelineInfoKHR::default().pipeline(pipeline),
                )
                .map_err(|r| format!("vkGetPipelineExecutablePropertiesKHR: {r}"))?;
            let mut out = Vec::new();
            for (i, p) in properties.iter().enumerate() {
                let info = vk::PipelineExecutableInfoKHR::default()
                    .pipeline(pipeline)
                    .executable_index(i as u32);
                let statistics = self
                    .executables
                    .get_pipeline_executable_statistics(&info)
                    .map_err(|r| format!("vkGetPipelineExecutableStatisticsKHR: {r}"))?
                    .iter()
                    .map(|s| Statistic {
                        name: text(&s.name),
                        description: text(&s.description),
                        value: match s.format {
                            vk::PipelineExecutableStatisticFormatKHR::BOOL32 => {
                                (s.value.b32 != 0).to_string()
                            }
                            vk::PipelineExecutableStatisticFormatKHR::INT64 => {
                                s.value.i64.to_string()
                            }
                            vk::PipelineExecutableStatisticFormatKHR::UINT64 => {
                                s.value.u64.to_string()
                            }
                            vk::PipelineExecutableStatisticFormatKHR::FLOAT64 => {
                                s.value.f64.to_string()
                            }
                            other => format!("(format {other:?})"),
                        },
                    })
                    .collect();
                let representations = if representations {
                    self.representations(&info)?
                } else {
                    Vec::new()
                };
                out.push(Executable {
                    name: text(&p.name),
                    subgroup_size: p.subgroup_size,
                    statistics,
                    representations,
                });
            }
            Ok(out)
        }
    }

    /// The internal representations: the count and sizes first, then the text.
    unsafe fn representations(
        &self,
        info: &vk::PipelineExecutableInfoKHR,
    ) -> Result<Vec<(String, String)>, String> {
        let fp = self.executables.fp();
        let handle = self.executables.device();
        let call = "vkGetPipelineExecutableInternalRepresentationsKHR";
        // SAFETY: the two-call idiom: count, then the sizes, then the data into buffers of
        // those sizes.
        unsafe {
            let mut count = 0u32;
            let query =
                |count: &mut u32, data: *mut vk::PipelineExecutableInternalRepresentationKHR| {
                    (fp.get_pipeline_executable_internal_representations_khr)(
                        handle, info, count, data,
                    )
                    .result()
                    .map_err(|r| format!("{call}: {r}"))
                };
            query(&mut count, std::ptr::null_mut())?;
            let mut reps =
                vec![vk::PipelineExecutableInternalRepresentationKHR::default(); count as usize];
            query(&mut count, reps.as_mut_ptr())?;
            let mut buffers: Vec<Vec<u8>> = reps.iter().map(|r| vec![0u8; r.data_size]).collect();
            for (r, b) in reps.iter_mut().zip(buffers.iter_mut()) {
                r.p_data = b.as_mut_ptr().cast();
            }
            query(&mut count, reps.as_mut_ptr())?;
            Ok(reps
                .iter()
                .zip(buffers)
                .map(|(r, b)| {
                    let body = if r.is_text == vk::TRUE {
                        String::from_utf8_lossy(b.split(|&c| c == 0).next().unwrap_or(&[]))
                            .into_owned()
                    } else {
                        format!("({} bytes of binary)", b.len())
                    };
                    (text(&r.name), body)
                })
                .collect())
        }
    }
}

impl Drop for DriverStats {
    fn drop(&mut self) {
        // SAFETY: every pipeline and module made from the device is gone by now.
        unsafe {
            self.device.destroy_device(None);
            self.instance.destroy_instance(None);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const SOURCE: &str = "override SCALE: f32;\n\
        struct U { n: u32 }\n\
        @group(0) @binding(0) var<storage, read> x: array<f32>;\n\
        @group(0) @binding(1) var<storage, read_write> y: array<f32>;\n\
        @group(0) @binding(2) var<uniform> u: U;\n\
        @compute @workgroup_size(64)\n\
        fn main(@builtin(global_invocation_id) g: vec3<u32>) {\n\
            if (g.x < u.n) { y[g.x] = SCALE * subgroupAdd(x[g.x]); }\n\
        }\n";

    /// A dumped kernel builds to SPIR-V with its override constants, and fails without
    /// them or with a source that does not parse.
    #[test]
    fn a_dumped_kernel_builds_to_spirv_with_its_constants() {
        let bindings = [
            Binding::StorageRead,
            Binding::StorageReadWrite,
            Binding::Uniform,
        ];
        let spec = KernelSpec::new("a kernel", SOURCE, &bindings).constant("SCALE", 2.5);
        let k = KernelSpec::from_dump(&spec.dump_text(SOURCE)).unwrap();
        let words = spirv(&k, (1, 3)).unwrap();
        assert_eq!(words[0], 0x0723_0203);
        let unset = KernelSpec::new("a kernel", SOURCE, &bindings);
        let e = spirv(&unset, (1, 3)).unwrap_err();
        assert!(e.contains("SCALE") || e.contains("override"), "{e}");
        let broken = KernelSpec::new("k", "fn broken(\n", &[]);
        assert!(spirv(&broken, (1, 3)).is_err());
    }
}
