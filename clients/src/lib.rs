//! scout-clients: the client library of the scout-gateway.
