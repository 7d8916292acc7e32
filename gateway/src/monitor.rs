//! Dead-process detection for clients: a thread that watches the iceoryx2 nodes of the clients
//! the arbiter knows and reports the ones that died, so that their control is released at once
//! instead of when their command ages out. It also removes what dead processes left behind.

use std::collections::HashSet;
use std::sync::mpsc::{Receiver, Sender, channel};
use std::time::Duration;

use iceoryx2::node::{Node, NodeState, NodeView};
use iceoryx2::prelude::CallbackProgression;
use scout_interface::Ipc;
use tracing::{debug, error, warn};

/// How often the node list is scanned.
pub const SCAN_PERIOD: Duration = Duration::from_millis(50);

/// The control thread's end of the monitor.
#[derive(Debug)]
pub struct NodeMonitor {
    watch: Sender<u128>,
    gone: Receiver<u128>,
}

impl NodeMonitor {
    /// Starts the monitor thread; it ends when this is dropped.
    pub fn start() -> std::io::Result<Self> {
        let (watch, watched) = channel();
        let (report, gone) = channel();
        std::thread::Builder::new()
            .name("node-monitor".into())
            .spawn(move || scan_loop(&watched, &report))?;
        Ok(Self { watch, gone })
    }

    /// Watches the process of node `node`.
    pub fn watch(&self, node: u128) {
        if self.watch.send(node).is_err() {
            error!(
                "the client monitor thread has stopped: a client that dies keeps its control until its command ages out"
            );
        }
    }

    /// A watched node that died since the last call, if any. Never blocks.
    pub fn try_gone(&self) -> Option<u128> {
        self.gone.try_recv().ok()
    }
}

fn scan_loop(watched: &Receiver<u128>, report: &Sender<u128>) {
    let mut watching = HashSet::new();
    loop {
        loop {
            match watched.try_recv() {
                Ok(node) => {
                    watching.insert(node);
                }
                Err(std::sync::mpsc::TryRecvError::Empty) => break,
                Err(std::sync::mpsc::TryRecvError::Disconnected) => return,
            }
        }
        if !watching.is_empty()
            && let Some(alive) = alive_nodes()
        {
            for node in watching
                .iter()
                .copied()
                .filter(|n| !alive.contains(n))
                .collect::<Vec<_>>()
            {
                debug!("client node {node:x} is gone");
                watching.remove(&node);
                if report.send(node).is_err() {
                    return;
                }
            }
        }
        std::thread::sleep(SCAN_PERIOD);
    }
}

/// The ids of the nodes whose processes live; dead ones are cleaned up on the way. `None` when
/// the nodes could not be listed: then nobody is declared dead.
fn alive_nodes() -> Option<HashSet<u128>> {
    let mut alive = HashSet::new();
    let config = match scout_interface::services::config() {
        Ok(config) => config,
        Err(error) => {
            warn!("{error}: no client is declared dead this scan");
            return None;
        }
    };
    let listed = Node::<Ipc>::list(&config, |state| {
        match state {
            NodeState::Alive(view) => {
                alive.insert(view.id().value());
            }
            NodeState::Dead(view) => {
                if let Err(error) = view.try_remove_stale_resources() {
                    debug!("removing a dead node's resources failed: {error:?}");
                }
            }
            NodeState::Inaccessible(id) | NodeState::Undefined(id) => {
                // Not provably dead: keep treating it as alive.
                alive.insert(id.value());
            }
        }
        CallbackProgression::Continue
    });
    match listed {
        Ok(()) => Some(alive),
        Err(failure) => {
            warn!(
                "listing iceoryx2 nodes failed ({failure:?}): no client is declared dead this scan"
            );
            None
        }
    }
}
