import os

# lavapipe (the CPU Vulkan driver CI runs on) wants a runtime dir; wgpu Vulkan only.
os.environ.setdefault("XDG_RUNTIME_DIR", "/tmp")
os.environ.setdefault("WGPU_BACKEND", "vulkan")
