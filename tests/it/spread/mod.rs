//! Spreading and interpolation against f64 references, by topic: every window on every
//! kernel path, the properties they must keep (conservation, adjointness, periodic wrap,
//! empty input), and tiled spreading. Shared helpers: `crate::util::spread`.

mod properties;
mod tiles;
mod windows;
