//! scout-clients: the client library of scout-gateway and the pieces of the `scout` tool.
//!
//! - [`decode`]: candump text and serial hex to decoded frames (`scout decode`).

pub mod decode;
