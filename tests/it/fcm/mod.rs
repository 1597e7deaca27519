//! graphs/fcm.json and graphs/bd_fcm.json against physics, by topic: the mobility
//! (Hasimoto's periodic self-mobility, an f64 direct Fourier sum of the
//! Gaussian-regularised Stokes Green function, symmetry and positive definiteness),
//! fluctuations and diffusion, and what settings may and may not change. The f64
//! references (`crate::util::mobility`) are written independently of the engine.

mod mobility;
mod noise;
mod settings;
