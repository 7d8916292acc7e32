//! The multi-process system tests, one module per area.
