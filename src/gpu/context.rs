//! The GPU context: one Vulkan adapter, its device and queue, and [`DeviceCaps`], the one
//! struct through which nodes learn what the device can do.

use std::sync::{Arc, Mutex};
use std::time::Duration;

use thiserror::Error;

/// Errors from the GPU layer.
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum GpuError {
    #[error(
        "no Vulkan adapter found. mesoflow runs on Vulkan only. On a machine without a GPU install \
         the CPU Vulkan driver: `apt-get install mesa-vulkan-drivers libvulkan1`; on a GPU machine \
         install the vendor's Vulkan driver and the Vulkan loader (libvulkan1)"
    )]
    NoAdapter,
    #[error("no Vulkan adapter matches MESOFLOW_ADAPTER=\"{wanted}\"; adapters found: {found}")]
    AdapterNotFound { wanted: String, found: String },
    #[error("could not open a device on adapter {adapter}: {message}")]
    RequestDevice { adapter: String, message: String },
    #[error("GPU error: {0}")]
    Device(String),
    #[error("the GPU did not finish within {0:?} (is the device hung or the job too large?)")]
    Timeout(Duration),
}

/// What the device can do, read once from the adapter. Nodes read capabilities here,
/// never from the adapter.
#[derive(Clone, Debug, PartialEq, Eq, Hash)]
pub struct DeviceCaps {
    pub adapter: String,
    pub device_type: String,
    pub driver: String,
    /// `atomic<f32>` add on storage buffers (not workgroup memory).
    pub f32_atomics: bool,
    /// `atomic<u64>` / `atomic<i64>` add on storage buffers (exact fixed-point sums in one
    /// return-less atomic instead of a 32-bit add and a carry).
    pub int64_atomics: bool,
    /// `i64` / `u64` in shaders (SHADER_INT64).
    pub int64: bool,
    /// Subgroup operations, with the (min, max) subgroup size the kernel must cope with.
    pub subgroups: Option<(u32, u32)>,
    pub timestamps: bool,
    pub f64: bool,
    /// Largest storage-buffer binding in bytes.
    pub max_binding: u64,
    pub max_buffer: u64,
    pub max_workgroup_storage: u32,
    pub max_invocations: u32,
    pub max_workgroups_per_dim: u32,
    /// Not a capability but a request of the run, carried with the caps so that every
    /// node's `infer` sees it (`--deterministic`): plans whose results are bitwise the
    /// same from run to run on this adapter with this binary and these inputs (integer
    /// sums where float atomics would add in any order, counting sorts stable inside a
    /// bin). Off by default: adapters' own caps never set it.
    pub deterministic: bool,
}

impl DeviceCaps {
    /// The WebGPU baseline with no optional feature: what planning assumes without a device.
    pub fn baseline() -> Self {
        let l = wgpu::Limits::default();
        DeviceCaps {
            adapter: "(no device: WebGPU baseline limits)".into(),
            device_type: "none".into(),
            driver: String::new(),
            f32_atomics: false,
            int64_atomics: false,
            int64: false,
            subgroups: None,
            timestamps: false,
            f64: false,
            max_binding: l.max_storage_buffer_binding_size,
            max_buffer: l.max_buffer_size,
            max_workgroup_storage: l.max_compute_workgroup_storage_size,
            max_invocations: l.max_compute_invocations_per_workgroup,
            max_workgroups_per_dim: l.max_compute_workgroups_per_dimension,
            deterministic: false,
        }
    }

    /// One line for logs and benchmark tables.
    pub fn summary(&self) -> String {
        let mut feats = Vec::new();
        if self.f32_atomics {
            feats.push("f32-atomics".to_string());
        }
        if self.int64 {
            feats.push("i64".to_string());
        }
        if self.int64_atomics {
            feats.push("i64-atomics".to_string());
        }
        if let Some((a, b)) = self.subgroups {
            feats.push(format!("subgroups {a}..{b}"));
        }
        if self.timestamps {
            feats.push("timestamps".into());
        }
        if self.f64 {
            feats.push("f64".into());
        }
        format!(
            "{} ({}, {}); {}; max binding {} MiB, workgroup memory {} KiB",
            self.adapter,
            self.device_type,
            self.driver,
            if feats.is_empty() {
                "no optional features".to_string()
            } else {
                feats.join(", ")
            },
            self.max_binding >> 20,
            self.max_workgroup_storage >> 10
        )
    }
}

fn vulkan_adapters() -> Vec<wgpu::Adapter> {
    let mut desc = wgpu::InstanceDescriptor::new_without_display_handle();
    desc.backends = wgpu::Backends::VULKAN;
    // No validation layers unless asked for through WGPU_VALIDATION / WGPU_DEBUG.
    desc.flags = wgpu::InstanceFlags::empty().with_env();
    let instance = wgpu::Instance::new(desc);
    pollster::block_on(instance.enumerate_adapters(wgpu::Backends::VULKAN))
}

/// The device mesoflow runs on.
pub struct GpuContext {
    pub adapter: wgpu::Adapter,
    pub device: wgpu::Device,
    pub queue: wgpu::Queue,
    pub caps: DeviceCaps,
    errors: Arc<Mutex<Vec<String>>>,
}

/// How long a wait for the GPU may take before it counts as hung.
pub const GPU_TIMEOUT: Duration = Duration::from_secs(600);

impl GpuContext {
    /// Opens the discrete GPU when there is one, otherwise any Vulkan adapter;
    /// `MESOFLOW_ADAPTER=<substring>` picks one by name.
    pub fn new() -> Result<GpuContext, GpuError> {
        let wanted = std::env::var("MESOFLOW_ADAPTER")
            .ok()
            .filter(|s| !s.is_empty());
        Self::open_named(wanted.as_deref())
    }

    /// Opens the adapter whose name contains `wanted`, or (None) the one `new` would
    /// choose without `MESOFLOW_ADAPTER`.
    pub fn open_named(wanted: Option<&str>) -> Result<GpuContext, GpuError> {
        let adapter = choose_adapter(vulkan_adapters(), wanted)?;
        Self::open(adapter)
    }

    /// Every Vulkan adapter: its name and device type.
    pub fn adapters() -> Vec<(String, String)> {
        vulkan_adapters()
            .iter()
            .map(|a| {
                let info = a.get_info();
                (info.name, format!("{:?}", info.device_type))
            })
            .collect()
    }

    fn open(adapter: wgpu::Adapter) -> Result<GpuContext, GpuError> {
        let info = adapter.get_info();
        let want = wgpu::Features::SHADER_FLOAT32_ATOMIC
            | wgpu::Features::SUBGROUP
            | wgpu::Features::SUBGROUP_BARRIER
            | wgpu::Features::TIMESTAMP_QUERY
            | wgpu::Features::TIMESTAMP_QUERY_INSIDE_ENCODERS
            | wgpu::Features::SHADER_F64
            | wgpu::Features::SHADER_INT64
            | wgpu::Features::SHADER_INT64_ATOMIC_ALL_OPS;
        let features = adapter.features() & want;
        let lim = adapter.limits();
        let required_limits = wgpu::Limits {
            max_storage_buffer_binding_size: lim.max_storage_buffer_binding_size,
            max_buffer_size: lim.max_buffer_size,
            max_compute_workgroup_storage_size: lim.max_compute_workgroup_storage_size,
            max_compute_invocations_per_workgroup: lim.max_compute_invocations_per_workgroup,
            max_compute_workgroup_size_x: lim.max_compute_workgroup_size_x,
            max_compute_workgroup_size_y: lim.max_compute_workgroup_size_y,
            max_compute_workgroup_size_z: lim.max_compute_workgroup_size_z,
            max_storage_buffers_per_shader_stage: lim.max_storage_buffers_per_shader_stage.min(16),
            max_bind_groups: lim.max_bind_groups,
            ..wgpu::Limits::default()
        };
        let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
            label: Some("mesoflow"),
            required_features: features,
            required_limits: required_limits.clone(),
            ..Default::default()
        }))
        .map_err(|e| GpuError::RequestDevice {
            adapter: info.name.clone(),
            message: e.to_string(),
        })?;

        let errors = Arc::new(Mutex::new(Vec::new()));
        let sink = errors.clone();
        device.on_uncaptured_error(Arc::new(move |e: wgpu::Error| {
            if let Ok(mut v) = sink.lock() {
                v.push(e.to_string());
            }
        }));

        let caps = DeviceCaps {
            adapter: info.name.clone(),
            device_type: format!("{:?}", info.device_type),
            driver: format!("{} {}", info.driver, info.driver_info)
                .trim()
                .to_string(),
            f32_atomics: features.contains(wgpu::Features::SHADER_FLOAT32_ATOMIC),
            int64_atomics: features.contains(
                wgpu::Features::SHADER_INT64 | wgpu::Features::SHADER_INT64_ATOMIC_ALL_OPS,
            ),
            int64: features.contains(wgpu::Features::SHADER_INT64),
            subgroups: features
                .contains(wgpu::Features::SUBGROUP)
                .then_some((info.subgroup_min_size, info.subgroup_max_size)),
            timestamps: features.contains(wgpu::Features::TIMESTAMP_QUERY),
            f64: features.contains(wgpu::Features::SHADER_F64),
            max_binding: required_limits.max_storage_buffer_binding_size,
            max_buffer: required_limits.max_buffer_size,
            max_workgroup_storage: required_limits.max_compute_workgroup_storage_size,
            max_invocations: required_limits.max_compute_invocations_per_workgroup,
            max_workgroups_per_dim: required_limits.max_compute_workgroups_per_dimension,
            deterministic: false,
        };
        Ok(GpuContext {
            adapter,
            device,
            queue,
            caps,
            errors,
        })
    }

    /// Errors the device reported outside error scopes since the last call.
    pub fn take_errors(&self) -> Result<(), GpuError> {
        let mut v = self
            .errors
            .lock()
            .map_err(|_| GpuError::Device("error log poisoned".into()))?;
        if v.is_empty() {
            Ok(())
        } else {
            let msg = v.join("; ");
            v.clear();
            Err(GpuError::Device(msg))
        }
    }

    /// Blocks until the given submission has finished, with a finite timeout.
    pub fn wait(&self, index: wgpu::SubmissionIndex) -> Result<(), GpuError> {
        self.device
            .poll(wgpu::PollType::Wait {
                submission_index: Some(index),
                timeout: Some(GPU_TIMEOUT),
            })
            .map_err(|e| match e {
                wgpu::PollError::Timeout => GpuError::Timeout(GPU_TIMEOUT),
                other => GpuError::Device(other.to_string()),
            })?;
        self.take_errors()
    }

    /// Copies a buffer back to the host (blocking).
    pub fn read_buffer(&self, buffer: &wgpu::Buffer, bytes: u64) -> Result<Vec<u8>, GpuError> {
        let size = bytes.max(4).next_multiple_of(4);
        let staging = self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("readback"),
            size,
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let mut enc = self.device.create_command_encoder(&Default::default());
        enc.copy_buffer_to_buffer(buffer, 0, &staging, 0, size);
        let idx = self.queue.submit([enc.finish()]);
        let (tx, rx) = std::sync::mpsc::channel();
        staging.slice(..).map_async(wgpu::MapMode::Read, move |r| {
            let _ = tx.send(r);
        });
        self.wait(idx)?;
        rx.recv()
            .map_err(|_| GpuError::Device("buffer map callback never ran".into()))?
            .map_err(|e| GpuError::Device(format!("mapping a readback buffer failed: {e}")))?;
        let data = staging
            .slice(..)
            .get_mapped_range()
            .map_err(|e| GpuError::Device(format!("reading a mapped buffer failed: {e}")))?
            .to_vec();
        staging.unmap();
        Ok(data[..bytes as usize].to_vec())
    }
}

fn rank(t: wgpu::DeviceType) -> u8 {
    match t {
        wgpu::DeviceType::DiscreteGpu => 0,
        wgpu::DeviceType::IntegratedGpu => 1,
        wgpu::DeviceType::VirtualGpu => 2,
        wgpu::DeviceType::Other => 3,
        wgpu::DeviceType::Cpu => 4,
    }
}

fn choose_adapter(
    adapters: Vec<wgpu::Adapter>,
    wanted: Option<&str>,
) -> Result<wgpu::Adapter, GpuError> {
    if adapters.is_empty() {
        return Err(GpuError::NoAdapter);
    }
    match wanted {
        Some(w) => {
            let lw = w.to_lowercase();
            let names: Vec<String> = adapters.iter().map(|a| a.get_info().name).collect();
            adapters
                .into_iter()
                .find(|a| a.get_info().name.to_lowercase().contains(&lw))
                .ok_or_else(|| GpuError::AdapterNotFound {
                    wanted: w.to_string(),
                    found: names.join(", "),
                })
        }
        None => adapters
            .into_iter()
            .min_by_key(|a| rank(a.get_info().device_type))
            .ok_or(GpuError::NoAdapter),
    }
}
