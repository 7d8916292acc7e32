//! Helpers for the multi-process system tests: start the real binaries and talk to them.
