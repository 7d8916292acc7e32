//! scout-gateway: the chassis simulator model and, later, the gateway that owns the port.
