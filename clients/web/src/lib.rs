//! scout-web: the operator's page (`scout web`, the `scout-web` program). An HTTP server with a
//! WebSocket serves one page from the binary ([`page`]); each page is a client of the arbiter
//! like any other, as `web:USER`: its E-STOP a stop owned by its user, its drives teleop
//! commands under a lease, aged from the browser's clock. Sans-IO: the request heads
//! ([`http`]), who may connect and do what ([`access`]) and what a page's messages ask for
//! ([`session`]) and who may hold a connection ([`gate`]); [`server`] is the driver around them
//! (sockets and tasks on tokio, threads for the gateway, the clock), over TLS ([`tls`]) beyond
//! loopback. [`qr`] shows the link to a phone's camera.

pub mod access;
pub mod gate;
pub mod http;
pub mod page;
pub mod qr;
pub mod server;
pub mod session;
pub mod tls;
