//! FOIS ray tracer.
